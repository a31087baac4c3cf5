"""What the fuzzer must be told that an OpenAPI document cannot say: timestamps are recent.

The API refuses times outside a window around now (pings and status reports: the retention
window back, SMOOTHFLEET_PING_MAX_FUTURE_S ahead; INRIX: SMOOTHFLEET_INRIX_MAX_AGE_DAYS back),
as the descriptions say; JSON Schema has no way to bound a date-time relative to now. Valid
cases therefore draw their date-times from the last hour (loaded by test_fuzz_openapi.py
through SCHEMATHESIS_HOOKS).
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import schemathesis
from hypothesis import strategies as st

schemathesis.openapi.format(
    "date-time",
    st.integers(min_value=0, max_value=3600).map(
        lambda seconds_ago: (datetime.now(UTC) - timedelta(seconds=seconds_ago)).isoformat()
    ),
)
