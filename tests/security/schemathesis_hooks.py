"""What the fuzzer must be told that an OpenAPI document cannot say: timestamps are recent.

The API refuses times outside a window around now (pings and status reports: the retention
window back, SMOOTHFLEET_PING_MAX_FUTURE_S ahead; INRIX: SMOOTHFLEET_INRIX_MAX_AGE_DAYS back),
as the descriptions say; JSON Schema has no way to bound a date-time relative to now. So:

- generated date-times (examples and fuzzing phases) are drawn from the last hour;
- the coverage phase builds its own values (fixed dates such as 2000-01-01), which would make
  every schema-valid status report a 422 and leave the other fields' boundaries untested. A
  positive status report whose `ts` is a real time outside the server's window gets `ts` moved
  to now, and nothing else: a `ts` the server should read but does not (a format disagreement)
  is left as drawn, so `positive_data_acceptance` still catches it; the window itself is tested
  in tests/app/test_vehicle_reports.py. Pings need no such help: a ping outside the window is
  refused item by item inside a 200, as a batch's bad items are.

Loaded by test_fuzz_openapi.py through SCHEMATHESIS_HOOKS.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any

import schemathesis
from hypothesis import strategies as st
from pydantic import TypeAdapter, ValidationError

from app.core.config import Settings
from contract.values import Timestamp

STATUS = ("POST", "/api/v1/vehicles/{vehicle_id}/status")
# The window of the server under test (test_fuzz_openapi.py runs it with the defaults).
RETENTION = timedelta(days=Settings.model_fields["ping_retention_days"].default)
AHEAD = timedelta(seconds=Settings.model_fields["ping_max_future_s"].default)
# Clocks move while a case travels: keep clear of the window's edges by this much.
MARGIN = timedelta(minutes=1)
TIMESTAMP: TypeAdapter[datetime] = TypeAdapter(Timestamp)

schemathesis.openapi.format(
    "date-time",
    st.integers(min_value=0, max_value=3600).map(
        lambda seconds_ago: (datetime.now(UTC) - timedelta(seconds=seconds_ago)).isoformat()
    ),
)


def _outside_the_window(text: str) -> bool:
    """Whether `text` is a time the server reads (the contract's Timestamp) but its window
    refuses."""
    try:
        moment = TIMESTAMP.validate_python(text)
    except ValidationError:
        return False
    now = datetime.now(UTC)
    return not now - RETENTION + MARGIN <= moment <= now + AHEAD - MARGIN


@schemathesis.hook
def map_case(context: Any, case: Any) -> Any:
    """A positive status report keeps everything but a `ts` outside the window (see above)."""
    if (case.method.upper(), case.operation.path) != STATUS:
        return case
    if case.meta is None or not case.meta.generation.mode.is_positive:
        return case
    body = case.body
    if isinstance(body, dict) and isinstance(body.get("ts"), str):
        if _outside_the_window(body["ts"]):
            case.body = {**body, "ts": datetime.now(UTC).isoformat()}
    return case
