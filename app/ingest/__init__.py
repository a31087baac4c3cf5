"""The ping fast path: validate per item, map-match, group-commit, answer after the commit."""

from app.ingest.asgi import PingFastPath
from app.ingest.pings import BodyError, ForeignVehicle
from app.ingest.service import Ingest, IngestResult, RowsRefused, ingest_running

__all__ = [
    "BodyError",
    "ForeignVehicle",
    "Ingest",
    "IngestResult",
    "PingFastPath",
    "RowsRefused",
    "ingest_running",
]
