"""What the fuzzer must be told that an OpenAPI document cannot say: timestamps are recent,
and an uploaded policy is a real one.

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

The plan history's window [since, until) is refused (422) with `until` before `since`, a
relation between two parameters that no schema states: a positive case that drew them so gets
them in order, all else as drawn (the refusal is tested in tests/app/test_plans_api.py).

And a policy upload is kept only when the file hashes to its manifest's `sha256` and loads as a
trained network of the manifest's actuation (app/policies/service.py): conditions on a file's
bytes that no schema can state, so every drawn file would be refused (422) and the 201/200 path
never judged. A positive upload therefore gets a policy the repository ships
(vehicle_agent/controllers/policies/) and the manifest written beside it: the one of the
controller the case drew, or rl_acc when it drew none (the seed stores rl_accel before the
run, so such an upload stores a new policy and test_fuzz_openapi.py can see uploads were
accepted). The drawn controller and any extra form fields stay as drawn; the refusals of bad
files and manifests are tested in tests/app/test_policies.py. Negative uploads stay as drawn, so
`negative_data_rejection` still judges them. Schemathesis re-judges a body a hook edits, and it
cannot validate bytes, so it would call the upload negative (its `contains_binary`) and judge a
201 as a schema-violating request accepted. The edit only put bytes in the two `format: binary`
fields of a form it had judged valid, which any bytes are, so the case is marked positive again.

Loaded by test_fuzz_openapi.py through SCHEMATHESIS_HOOKS.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any

import schemathesis
from hypothesis import strategies as st
from pydantic import TypeAdapter, ValidationError
from schemathesis import GenerationMode
from schemathesis.core.parameters import ParameterLocation
from schemathesis.generation.meta import ComponentInfo

from app.core.config import Settings
from contract.controllers import RL_CONTROLLERS
from contract.values import Timestamp
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

STATUS = ("POST", "/api/v1/vehicles/{vehicle_id}/status")
PLAN_HISTORY = ("GET", "/api/v1/plans")
POLICY_UPLOAD = ("POST", "/api/v1/policies")
# What a positive upload that names no controller sends (see above).
UNNAMED_CONTROLLER = "rl_acc"
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


def _ts_in_the_window(body: object) -> object:
    """A status report with a `ts` outside the window moved to now, all else as drawn."""
    if isinstance(body, dict) and isinstance(body.get("ts"), str):
        if _outside_the_window(body["ts"]):
            return {**body, "ts": datetime.now(UTC).isoformat()}
    return body


def _a_shipped_policy(body: object) -> object:
    """An upload form with a shipped policy file and its own manifest in place of the drawn
    ones: the policy of the drawn controller, or UNNAMED_CONTROLLER's (see above)."""
    if not isinstance(body, dict):
        return body
    drawn = body.get("controller")
    controller = drawn if drawn in RL_CONTROLLERS else UNNAMED_CONTROLLER
    policy = BUNDLED_POLICIES / f"{controller}.npz"
    return {
        **body,
        "policy": policy.read_bytes(),
        "manifest": policy.with_suffix(".json").read_bytes(),
    }


def _window_in_order(query: object) -> object:
    """A plan-history query whose `until` reads before its `since` with the two swapped."""
    if not isinstance(query, dict):
        return query
    since, until = query.get("since"), query.get("until")
    if not (isinstance(since, str) and isinstance(until, str)):
        return query
    try:
        reversed_window = TIMESTAMP.validate_python(until) < TIMESTAMP.validate_python(since)
    except ValidationError:
        return query
    return {**query, "since": until, "until": since} if reversed_window else query


@schemathesis.hook
def map_case(context: Any, case: Any) -> Any:
    """A positive status report, plan-history query or policy upload gets the help described
    above; every other case is sent as drawn."""
    if case.meta is None or not case.meta.generation.mode.is_positive:
        return case
    operation = (case.method.upper(), case.operation.path)
    if operation == STATUS:
        case.body = _ts_in_the_window(case.body)
    elif operation == PLAN_HISTORY:
        case.query = _window_in_order(case.query)
    elif operation == POLICY_UPLOAD:
        case.body = _a_shipped_policy(case.body)
        meta = case.meta  # re-judged here: negative, for the bytes it cannot validate (see above)
        meta.components[ParameterLocation.BODY] = ComponentInfo(mode=GenerationMode.POSITIVE)
        meta.generation.mode = GenerationMode.POSITIVE
    return case
