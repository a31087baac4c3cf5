"""Server settings read from the environment: JSON-valued ones decoded, and a wrong one named."""

from __future__ import annotations

import json
import logging
import os
from typing import get_origin

import pytest

from app.core.config import Settings, SettingsError, load_settings, unknown_variables
from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS


def json_valued_fields() -> list[str]:
    """The settings an operator writes as JSON: tuples, and the planner's parameters."""
    return [
        name
        for name, info in Settings.model_fields.items()
        if get_origin(info.annotation) in (tuple, dict, list)
    ]


def test_every_json_valued_setting_reads_its_json(monkeypatch: pytest.MonkeyPatch) -> None:
    fields = json_valued_fields()
    assert "planner_params" in fields
    assert "readiness_gps_satellites" in fields
    defaults = Settings()
    for name in fields:
        value = getattr(defaults, name)
        monkeypatch.setenv(f"SMOOTHFLEET_{name.upper()}", json.dumps(value))
    read = load_settings()
    for name in fields:
        assert getattr(read, name) == getattr(defaults, name), name


def test_the_server_plans_as_the_simulator_recommends(monkeypatch: pytest.MonkeyPatch) -> None:
    defaults = load_settings()
    assert defaults.planner_algorithm == RECOMMENDED_PLANNER
    assert defaults.planner_param_values() == {
        **RECOMMENDED_PLANNER_PARAMS,
        "cycle_period_s": defaults.planner_period_s,
    }
    # An override replaces its own parameter and keeps the others recommended.
    monkeypatch.setenv("SMOOTHFLEET_PLANNER_PARAMS", '{"window_m": 2000}')
    monkeypatch.setenv("SMOOTHFLEET_PLANNER_ALGORITHM", "kernel_smooth_buffer")
    overridden = load_settings()
    assert overridden.planner_algorithm == "kernel_smooth_buffer"
    assert overridden.planner_param_values() == {
        **RECOMMENDED_PLANNER_PARAMS,
        "window_m": 2000,
        "cycle_period_s": overridden.planner_period_s,
    }


@pytest.mark.parametrize(
    ("variable", "text", "error"),
    [
        ("PLANNER_PARAMS", '{"window_m": 4000', "SMOOTHFLEET_PLANNER_PARAMS: not valid JSON"),
        ("READINESS_PING_AGE_S", "5, 60", "SMOOTHFLEET_READINESS_PING_AGE_S: not valid JSON"),
        ("READINESS_PING_AGE_S", "[60, 5]", "READINESS_PING_AGE_S: give .* amber below red"),
        ("PLANNER_PARAMS", '{"nosuch": 1}', "SMOOTHFLEET_PLANNER_PARAMS: planner parameter"),
        # a stage nobody registered: accepted, it failed every planner cycle from the first
        (
            "PLANNER_PARAMS",
            '{"kernel": "cosine"}',
            "planner parameter kernel: unknown kernel 'cosine' \\(known: gaussian, quartic",
        ),
        ("PLANNER_PARAMS", '{"predictor": "x"}', "planner parameter predictor: unknown predictor"),
    ],
)
def test_a_wrong_json_setting_is_named(
    monkeypatch: pytest.MonkeyPatch, variable: str, text: str, error: str
) -> None:
    monkeypatch.setenv(f"SMOOTHFLEET_{variable}", text)
    with pytest.raises(SettingsError, match=error):
        load_settings()


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("notanip", "'notanip' is no IP address or network"),
        ("10.0.0.0/33, 10.9.8.7", "'10.0.0.0/33' is no IP address or network"),
        ("10.1.2.3/16", "'10.1.2.3/16' is no IP .* has host bits set\\): did you mean 10.1.0.0/16"),
    ],
)
def test_a_mistyped_trusted_proxy_is_named(
    monkeypatch: pytest.MonkeyPatch, text: str, error: str
) -> None:
    """Accepted, it trusted no proxy: behind one, every operator's login counted against the
    proxy's address (ops audit)."""
    monkeypatch.setenv("SMOOTHFLEET_TRUSTED_PROXIES", text)
    with pytest.raises(SettingsError, match=f"SMOOTHFLEET_TRUSTED_PROXIES: {error}"):
        load_settings()


def test_trusted_proxies_take_addresses_networks_and_every_peer(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("SMOOTHFLEET_TRUSTED_PROXIES", "10.0.0.0/8, 192.168.1.1 ,::1,*")
    assert load_settings().trusted_proxies == "10.0.0.0/8, 192.168.1.1 ,::1,*"


@pytest.mark.parametrize("variable", ["INRIX_URL", "PUBLIC_URL"])
def test_a_url_setting_needs_a_scheme_and_a_host(
    monkeypatch: pytest.MonkeyPatch, variable: str
) -> None:
    # docker-compose hands an unset variable on as empty: unset
    monkeypatch.setenv(f"SMOOTHFLEET_{variable}", "")
    assert getattr(load_settings(), variable.lower()) is None
    monkeypatch.setenv(f"SMOOTHFLEET_{variable}", "https://fleet.example/api")
    assert getattr(load_settings(), variable.lower()) == "https://fleet.example/api"
    for wrong in ("api.inrix.com/v1", "ftp://fleet.example", "https://"):
        monkeypatch.setenv(f"SMOOTHFLEET_{variable}", wrong)
        with pytest.raises(SettingsError, match=f"SMOOTHFLEET_{variable}: must be an http"):
            load_settings()


def test_production_needs_a_secret_key_that_cannot_be_guessed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """'abc' was accepted: only the listed placeholders were refused (ops audit)."""
    monkeypatch.setenv("SMOOTHFLEET_ENVIRONMENT", "production")
    monkeypatch.setenv("SMOOTHFLEET_DATABASE_URL", "postgresql://u:p@db:5432/smoothfleet")
    monkeypatch.setenv("SMOOTHFLEET_SECRET_KEY", "abc")
    with pytest.raises(
        SettingsError, match="SMOOTHFLEET_SECRET_KEY is 3 characters: production needs at least 32"
    ):
        load_settings()
    monkeypatch.setenv("SMOOTHFLEET_SECRET_KEY", "x" * 32)
    assert load_settings().secret_key.get_secret_value() == "x" * 32


def test_production_needs_a_database_url(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SMOOTHFLEET_ENVIRONMENT", "production")
    monkeypatch.setenv("SMOOTHFLEET_SECRET_KEY", "a-real-secret-of-32-characters-xx")
    # a misspelt name is no database: production must not fall back to the embedded server
    monkeypatch.setenv("SMOOTHFLEET_DATABSE_URL", "postgresql://u:p@db:5432/smoothfleet")
    with pytest.raises(SettingsError, match="SMOOTHFLEET_DATABASE_URL must be set in production"):
        load_settings()
    monkeypatch.setenv("SMOOTHFLEET_DATABASE_URL", "postgresql://u:p@db:5432/smoothfleet")
    # the misspelt name itself is refused, named, once the setting it meant is there
    with pytest.raises(SettingsError, match="SMOOTHFLEET_DATABSE_URL: no server setting"):
        load_settings()
    monkeypatch.delenv("SMOOTHFLEET_DATABSE_URL")
    assert load_settings().database_url == "postgresql://u:p@db:5432/smoothfleet"


def test_a_misspelt_setting_is_refused_in_production_and_logged_in_development(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    for name in [name for name in os.environ if name.upper().startswith("SMOOTHFLEET_")]:
        monkeypatch.delenv(name)
    # the agent's settings and the tools' variables share the prefix: they are no typo
    monkeypatch.setenv("SMOOTHFLEET_AGENT_VEHICLE_ID", "SF-010")
    monkeypatch.setenv("SMOOTHFLEET_SHARED_DATA", "/data")
    monkeypatch.setenv("smoothfleet_planner_period_s", "30")  # matched without regard to case
    assert unknown_variables(os.environ) == []
    assert load_settings().planner_period_s == 30.0
    monkeypatch.setenv("SMOOTHFLEET_PLANER_PERIOD_S", "30")
    assert unknown_variables(os.environ) == ["SMOOTHFLEET_PLANER_PERIOD_S"]
    with caplog.at_level(logging.WARNING, logger="app.core.config"):
        assert load_settings().environment == "development"
    assert "SMOOTHFLEET_PLANER_PERIOD_S: no server setting of that name, ignored" in caplog.text
    monkeypatch.setenv("SMOOTHFLEET_ENVIRONMENT", "production")
    monkeypatch.setenv("SMOOTHFLEET_SECRET_KEY", "a-real-secret-of-32-characters-xx")
    monkeypatch.setenv("SMOOTHFLEET_DATABASE_URL", "postgresql://u:p@db:5432/smoothfleet")
    with pytest.raises(
        SettingsError, match=r"^SMOOTHFLEET_PLANER_PERIOD_S: no server setting of that name"
    ):
        load_settings()


def test_a_misspelt_server_setting_under_the_agents_prefix_is_refused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Four server settings share the agent's prefix (the periods handed to the cars), and the
    server passed over every name under it: SMOOTHFLEET_AGENT_PING_PERIOD (no _S) left the
    ping period at its default without a word."""
    for name in [name for name in os.environ if name.upper().startswith("SMOOTHFLEET_")]:
        monkeypatch.delenv(name)
    monkeypatch.setenv("SMOOTHFLEET_AGENT_PING_PERIOD_S", "0.5")  # the server's own
    monkeypatch.setenv("SMOOTHFLEET_AGENT_SERVER_URL", "https://fleet.test")  # the agent's
    assert unknown_variables(os.environ) == []
    assert load_settings().agent_ping_period_s == 0.5
    monkeypatch.setenv("SMOOTHFLEET_AGENT_PING_PERIOD", "0.5")
    assert unknown_variables(os.environ) == ["SMOOTHFLEET_AGENT_PING_PERIOD"]


def test_a_setting_left_empty_is_unset(monkeypatch: pytest.MonkeyPatch) -> None:
    """`SMOOTHFLEET_DATA_DIR=` put the embedded cluster in the working directory, and
    `SMOOTHFLEET_READINESS_AGENT_VERSION=` graded every car amber for running no version ""."""
    monkeypatch.setenv("SMOOTHFLEET_DATA_DIR", "")
    monkeypatch.setenv("SMOOTHFLEET_READINESS_AGENT_VERSION", "")
    settings = load_settings()
    assert settings.data_dir == Settings.model_fields["data_dir"].get_default(
        call_default_factory=True
    )
    assert settings.readiness_agent_version is None
