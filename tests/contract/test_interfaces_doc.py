"""docs/interfaces.md and the code agree: the fields, endpoints and settings it names exist.

The document is what cars in the field rely on; a field renamed in a model, or an endpoint gone,
fails here before it reaches a car.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from app.core.config import Settings, load_settings
from contract.plans import BufferOut, LanePlanOut, PlanInputsOut, PlanOut
from contract.vehicles import Ping, VehicleConfig, VehicleStatusReport
from smoothfleet.server import create_app

DOC = (Path(__file__).resolve().parents[2] / "docs" / "interfaces.md").read_text()


def backticked(text: str) -> set[str]:
    """The identifiers written in backticks (field names)."""
    return set(re.findall(r"`([a-z_0-9]+)`", text))


def between(start: str, end: str) -> str:
    """The document's text from `start` up to the next `end`."""
    begin = DOC.index(start)
    return DOC[begin : DOC.index(end, begin)]


EXTENSIONS = DOC[DOC.index("## Compatible extensions") :]


def test_ping_fields_are_the_models() -> None:
    named = backticked(between("Ping fields:", "Answer 200"))
    fields = set(Ping.model_fields)
    assert named <= fields
    # a field the agreement does not name is one of our listed extensions
    assert fields - named <= backticked(EXTENSIONS)


def test_status_fields_are_the_models() -> None:
    named = backticked(between("the piStatus report, every ~10 s:", "(all but"))
    fields = set(VehicleStatusReport.model_fields)
    assert named <= fields
    # a field the agreement does not name is one of our listed extensions
    assert fields - named <= backticked(EXTENSIONS)


def test_config_fields_exist() -> None:
    named = backticked(between("`GET /api/v1/vehicles/{vehicle_id}/config`", "\n- "))
    assert named - {"acc", "accel"} <= set(VehicleConfig.model_fields)
    assert "config_version" in backticked(EXTENSIONS)


def test_plan_document_keys_exist() -> None:
    sketch = between("`GET /api/v1/plans/latest", "with an `ETag`")
    keys = set(re.findall(r'"([a-z_]+)"', sketch))
    fields = {
        *PlanOut.model_fields,
        *PlanInputsOut.model_fields,
        *LanePlanOut.model_fields,
        *BufferOut.model_fields,
    }
    assert keys <= fields
    assert keys >= {"plan_id", "valid_until", "lanes", "target_speed_mps", "buffers"}


def path_shape(path: str) -> str:
    """A path with its parameters' names left out (`{id}` and `{corridor_id}` are one path)."""
    return re.sub(r"\{[^}]*\}", "{}", path)


@pytest.fixture(scope="module")
def routes() -> set[tuple[str, str]]:
    """(method, path shape) of every operation in the served OpenAPI schema."""
    app = create_app(load_settings(database_url="postgresql://unused@localhost/unused"))
    return {
        (method.upper(), path_shape(path))
        for path, operations in app.openapi()["paths"].items()
        for method in operations
    }


def test_every_endpoint_named_is_served(routes: set[tuple[str, str]]) -> None:
    named = {
        (method, path_shape(path))
        for method, path in re.findall(r"`(GET|POST|PUT|DELETE) +(/[^`?\s\[]*)", DOC)
    }
    assert len(named) >= 12
    assert named - routes == set()


def test_every_setting_named_exists() -> None:
    named = set(re.findall(r"`SMOOTHFLEET_([A-Z_]+?)`", DOC)) - {"AGENT_"}
    prefixes = {name[:-1] for name in named if name.endswith("_")}
    fields = {field.upper() for field in Settings.model_fields}
    assert {name for name in named if not name.endswith("_")} <= fields
    for prefix in prefixes:
        assert any(field.startswith(prefix) for field in fields), prefix


def test_every_setting_is_named() -> None:
    """Settings the server reads and no document named (an audit found eight) are named in the
    agreed settings or the added ones, one by one or by a prefix written `NAME_*`."""
    named = set(re.findall(r"`(?:SMOOTHFLEET_)?([A-Z_]+?)`", DOC))
    prefixes = {name.removesuffix("_") for name in re.findall(r"`([A-Z_]+_)\*`", DOC)}
    unnamed = {
        field.upper()
        for field in Settings.model_fields
        if field.upper() not in named
        and not any(field.upper().startswith(prefix) for prefix in prefixes)
    }
    assert unnamed == set()
