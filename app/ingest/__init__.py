"""The ping fast path: validate per item, map-match, group-commit, answer after the commit."""

from app.ingest.pings import BodyError, ForeignVehicle
from app.ingest.service import Ingest, IngestResult, ingest_of, ingest_running

__all__ = ["BodyError", "ForeignVehicle", "Ingest", "IngestResult", "ingest_of", "ingest_running"]
