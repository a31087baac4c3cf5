"""Parsing pings: the one-pass path and the item-by-item path agree on every input.

Well-formed uploads are validated straight from the bytes; anything else is parsed and checked
item by item. Whichever path a body takes, a ping must be accepted or refused the same way.
"""

from __future__ import annotations

from typing import Any

import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from app.auth import Principal
from app.core.json_keys import RepeatedKey, refuse_repeated_keys
from app.ingest.pings import BodyError, ForeignVehicle, read_pings
from contract.vehicles import Ping

ADMIN = Principal(token_id=1, role="admin", vehicle_id=None)
CAR = Principal(token_id=2, role="vehicle", vehicle_id="SF-001")

json_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**40), max_value=2**40),
    st.floats(allow_nan=False, allow_infinity=False, width=64),
    st.text(max_size=12),
    st.sampled_from(["2026-11-23T09:00:00Z", "2026-11-23T09:00:00", "25", "true", "SF-001"]),
)
field_names = st.sampled_from(
    [
        "vehicle_id",
        "ts",
        "lat",
        "lon",
        "speed_mps",
        "lane",
        "acc_engaged",
        "acc_gap_setting",
        "controller",
        "plan_id",
        "lead_distance_m",
    ]
)
base_ping = {
    "vehicle_id": "SF-001",
    "ts": "2026-11-23T09:00:00Z",
    "lat": 36.0,
    "lon": -86.6,
    "speed_mps": 25.0,
}


def outcome(parse: Any) -> Ping | str:
    try:
        ping: Ping = parse()
        return ping
    except ValidationError as error:
        return str(error.errors(include_url=False)[0]["loc"])


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(field_names, json_scalars, max_size=6))
def test_from_bytes_and_from_parsed_json_agree(changes: dict[str, Any]) -> None:
    raw = orjson.dumps({**base_ping, **changes})
    from_bytes = outcome(lambda: Ping.model_validate_json(raw))
    from_objects = outcome(lambda: Ping.model_validate(orjson.loads(raw)))
    assert from_bytes == from_objects


def test_a_batch_with_one_bad_item_is_read_item_by_item() -> None:
    good = dict(base_ping)
    bad = {**base_ping, "speed_mps": 91}
    pings, rejected = read_pings(orjson.dumps({"pings": [good, bad, good]}), ADMIN)
    assert [index for index, _ in pings] == [0, 2]
    assert [(r.index, r.error.split(":")[0]) for r in rejected] == [(1, "speed_mps")]


def test_a_foreign_ping_refuses_the_request_on_either_path() -> None:
    foreign = {**base_ping, "vehicle_id": "SF-002"}
    for body in ({"pings": [base_ping, foreign]}, {"pings": [base_ping, {**foreign, "lat": 99}]}):
        with pytest.raises(ForeignVehicle) as refusal:
            read_pings(orjson.dumps(body), CAR)
        assert refusal.value.pings == 2


@pytest.mark.parametrize("vehicle_id", [1, "", None, ["SF-001"], "SF 001"])
def test_a_malformed_vehicle_id_is_that_items_error_not_another_cars_ping(
    vehicle_id: object,
) -> None:
    """A number or an empty string in vehicle_id refused a car's whole batch as 403 ("may
    not post pings of 1"), where an admin's same batch kept the good ping."""
    body = orjson.dumps({"pings": [base_ping, {**base_ping, "vehicle_id": vehicle_id}]})
    for principal in (CAR, ADMIN):
        pings, rejected = read_pings(body, principal)
        assert [index for index, _ in pings] == [0]
        assert [(r.index, r.error.split(":")[0]) for r in rejected] == [(1, "vehicle_id")]


def test_a_body_naming_pings_that_is_a_single_ping_still_parses() -> None:
    # The one-pass path guesses the shape from the bytes; a wrong guess falls back safely.
    pings, rejected = read_pings(orjson.dumps({**base_ping, "controller": '"pings"'}), ADMIN)
    assert len(pings) == 1
    assert rejected == []
    with pytest.raises(BodyError):
        read_pings(b'{"note": "\\"pings\\""}', ADMIN)


def test_text_too_long_is_counted_in_characters() -> None:
    """An optional text field's bound was applied after validation and said "Value should have
    at most 64 items" of a ping's controller, a status's agent version or engage reason."""
    with pytest.raises(ValidationError) as error:
        Ping.model_validate({**base_ping, "controller": "x" * 65})
    assert error.value.errors()[0]["msg"] == "String should have at most 64 characters"


def test_a_token_is_named_with_its_article() -> None:
    assert Principal(token_id=3, role="operator", vehicle_id=None).token_words == (
        "an operator token"
    )
    assert CAR.token_words == "a vehicle token"


def test_a_ping_naming_a_key_twice_is_refused_naming_it() -> None:
    """orjson and pydantic keep the last value of a repeated key: a ping with speed_mps twice
    was stored with the second speed and its sender never told which was dropped."""
    text = orjson.dumps(base_ping).decode()
    twice = text[:-1] + ', "speed_mps": 7.5}'
    with pytest.raises(BodyError, match=r'duplicate key "speed_mps".*ambiguous'):
        read_pings(twice.encode(), ADMIN)
    in_a_batch = f'{{"pings": [{text}, {twice}]}}'.encode()
    with pytest.raises(BodyError, match=r'duplicate key "speed_mps"'):
        read_pings(in_a_batch, ADMIN)
    with pytest.raises(BodyError, match=r'duplicate key "pings"'):
        read_pings(f'{{"pings": [{text}], "pings": []}}'.encode(), ADMIN)
    # the same key in two objects is no repetition
    pings, rejected = read_pings(f'{{"pings": [{text}, {text}]}}'.encode(), ADMIN)
    assert (len(pings), rejected) == (2, [])
    # a body that is not JSON is still told so by the ping parser, not as a repeated key
    with pytest.raises(BodyError) as error:
        read_pings(b'{"vehicle_id": ', ADMIN)
    assert "duplicate" not in str(error.value)


def test_a_repeated_key_is_refused_in_bodies_jiter_cannot_read() -> None:
    """jiter reads no byte-order mark, no lone surrogate and nesting only so deep, where orjson
    or Python's json read them: such a body with a repeated key passed the check and its last
    value was stored (a review)."""
    text = orjson.dumps(base_ping).decode()
    twice = text[:-1] + ', "speed_mps": 7.5'
    deep = twice + ', "note": ' + "[" * 300 + "]" * 300 + "}"
    surrogate = twice + ', "note": "\\ud800"}'
    for body in (deep.encode(), surrogate.encode(), b"\xef\xbb\xbf" + (twice + "}").encode()):
        with pytest.raises(RepeatedKey, match=r'duplicate key "speed_mps"'):
            refuse_repeated_keys(body)
    with pytest.raises(BodyError, match=r'duplicate key "speed_mps"'):
        read_pings(deep.encode(), ADMIN)
    refuse_repeated_keys(b"\xef\xbb\xbf" + text.encode())  # no repetition: passes
    refuse_repeated_keys(b"not json")  # the endpoint's own parser says what is wrong
