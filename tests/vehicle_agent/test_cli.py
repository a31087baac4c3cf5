"""`smoothfleet-agent` settings and command line: wrong input stops it with one clear line."""

from __future__ import annotations

import configparser
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from contract.environment import AGENT_VARIABLES
from vehicle_agent.actuators import ButtonSequencer
from vehicle_agent.cars import CruiseButton
from vehicle_agent.loop import RateKeeper
from vehicle_agent.settings import (
    AgentSettingsError,
    board_lines,
    load_agent_settings,
    setting_names,
)

AGENT_SCRIPT = Path(sys.executable).parent / "smoothfleet-agent"


def agent_env(env: dict[str, str] | None = None) -> dict[str, str]:
    """A bare environment for the agent, keeping PYTHONPATH, where set, so that it runs the
    code under test rather than the checkout the environment was installed from."""
    inherited = {name: os.environ[name] for name in ("PYTHONPATH",) if name in os.environ}
    return {"PATH": "/usr/bin:/bin", **inherited, **(env or {})}


def run_agent_cli(
    *args: str, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(AGENT_SCRIPT), *args],
        capture_output=True,
        text=True,
        timeout=60,
        env=agent_env(env),
    )


def test_missing_and_wrong_settings_name_the_variable() -> None:
    missing = run_agent_cli("--token", "abc", "--vehicle-id", "SF-001")
    assert missing.returncode == 2
    assert missing.stderr.strip() == (
        "smoothfleet-agent: SMOOTHFLEET_AGENT_SERVER_URL: Field required"
    )
    wrong = run_agent_cli(
        "--vehicle-id",
        "SF-001",
        "--server",
        "http://x",
        env={"SMOOTHFLEET_AGENT_TOKEN": "change-me"},
    )
    assert wrong.returncode == 2
    assert wrong.stderr.startswith("smoothfleet-agent: SMOOTHFLEET_AGENT_TOKEN: must be the ")
    assert "Traceback" not in wrong.stderr
    no_port = run_agent_cli(
        "--vehicle-id", "SF-001", "--server", "http://x", "--token", "abc", "--gps", "gpsd:h:gps"
    )
    assert no_port.returncode == 2
    assert no_port.stderr.strip() == (
        "smoothfleet-agent: SMOOTHFLEET_AGENT_GPS: must be gpsd:<host>:<port> (a port 1-65535) "
        "or none"
    )


# Settings of an agent with no GPS and no server to reach.
AGENT_WITHOUT_SERVER = (
    "--server",
    "http://127.0.0.1:9",
    "--token",
    "abc",
    "--vehicle-id",
    "SF-001",
    "--gps",
    "none",
)


def run_agent_without_server(
    can: str, spool: Path, env: dict[str, str] | None = None, make: str = "toyota_rav4"
) -> subprocess.CompletedProcess[str]:
    """An agent for `make` (a RAV4) on `can` and `spool`, with no GPS and no server to reach."""
    return run_agent_cli(
        *AGENT_WITHOUT_SERVER,
        "--make",
        make,
        "--can",
        can,
        "--spool",
        str(spool),
        env=env,
    )


def test_an_agent_whose_spool_cannot_be_created_runs_and_says_so(tmp_path: Path) -> None:
    """It refused to start ("cannot open the ping spool", exit 1): a car with a missing or
    read-only card ran no agent at all. It now runs, its pings held in memory, says so, and
    stops cleanly on SIGTERM."""
    (tmp_path / "a-file").write_text("")
    spool = tmp_path / "a-file" / "pings.sqlite"
    command = [str(AGENT_SCRIPT), *AGENT_WITHOUT_SERVER, "--make", "toyota_rav4"]
    command += ["--can", "virtual:spool-test", "--spool", str(spool)]
    with subprocess.Popen(command, stderr=subprocess.PIPE, text=True, env=agent_env()) as agent:
        assert agent.stderr is not None
        lines: list[str] = []
        deadline = time.monotonic() + 60
        while not any(" agent 0." in line for line in lines) and time.monotonic() < deadline:
            lines.append(agent.stderr.readline())  # up to "agent VERSION for SF-001 ..."
        agent.send_signal(signal.SIGTERM)
        lines += agent.stderr.readlines()
        assert agent.wait(timeout=30) == 0
    said = "".join(lines)
    assert f"WARNING vehicle_agent.spool: ping spool {spool} cannot be opened (" in said
    assert "pings held in memory (at most 3600, then the oldest are dropped and counted)" in said
    assert "Traceback" not in said


def test_a_dbc_cache_that_cannot_be_written_is_one_line(tmp_path: Path) -> None:
    """It was a three-level FileNotFoundError traceback."""
    (tmp_path / "a-file").write_text("")
    result = run_agent_without_server(
        "virtual:dbc-test",
        tmp_path / "s.sqlite",
        env={"SMOOTHFLEET_AGENT_DBC_CACHE_DIR": str(tmp_path / "a-file")},
    )
    assert result.returncode == 1
    assert result.stderr.startswith(
        "smoothfleet-agent: cannot write the generated DBC toyota_nodsu_pt"
    )
    assert "SMOOTHFLEET_AGENT_DBC_CACHE_DIR" in result.stderr
    assert "Traceback" not in result.stderr


def test_a_2023_rogue_without_a_button_board_is_one_line(tmp_path: Path) -> None:
    """The car takes no button frames: with no board the agent would follow no plan."""
    result = run_agent_without_server(
        "virtual:rogue-test", tmp_path / "s.sqlite", make="nissan_rogue"
    )
    assert result.returncode == 1
    assert result.stderr == (
        "smoothfleet-agent: the Nissan Rogue (nissan_rogue) takes no button frames on CAN: its "
        "buttons are pressed through a GPIO button board, so set SMOOTHFLEET_AGENT_BUTTON_BOARD "
        "(e.g. plus=17,minus=27,gap=22)\n"
    )


def test_a_2023_rogue_without_a_button_board_is_refused_before_the_bus_opens(
    tmp_path: Path,
) -> None:
    """Nothing is opened for a car the agent could not press: not the bus (here one that
    cannot open, whose error came first), not the ping spool."""
    spool = tmp_path / "s.sqlite"
    result = run_agent_without_server("nosuch:can0", spool, make="nissan_rogue")
    assert result.returncode == 1
    assert "GPIO button board" in result.stderr
    assert "cannot open CAN bus" not in result.stderr
    assert not spool.exists()


def test_an_unusable_bus_is_one_line(tmp_path: Path) -> None:
    result = run_agent_without_server("nosuch:can0", tmp_path / "s.sqlite")
    assert result.returncode == 1
    assert result.stderr.startswith("smoothfleet-agent: cannot open CAN bus nosuch:can0")


def test_settings_from_an_env_file_with_the_command_line_winning(tmp_path: Path) -> None:
    env_file = tmp_path / "agent.env"
    env_file.write_text(
        "SMOOTHFLEET_AGENT_SERVER_URL=https://fleet.example/\n"
        "SMOOTHFLEET_AGENT_TOKEN=secret-token-1\n"
        "SMOOTHFLEET_AGENT_VEHICLE_ID=SF-010\n"
        "SMOOTHFLEET_AGENT_CAN=socketcan:can1\n"
    )
    settings = load_agent_settings(env_file, can="virtual:test")
    assert settings.server_url == "https://fleet.example"
    assert settings.vehicle_id == "SF-010"
    assert settings.can == "virtual:test"
    with pytest.raises(AgentSettingsError, match="SMOOTHFLEET_AGENT_MAKE: must be one of"):
        load_agent_settings(env_file, make="tesla")
    with pytest.raises(AgentSettingsError, match="SMOOTHFLEET_AGENT_BUTTON_BOARD: .*no line"):
        load_agent_settings(env_file, button_board="plus=17")


@pytest.mark.parametrize(
    ("text", "error"),
    [
        # a line without '=' would be skipped by the env-file reader: named, its text not shown
        ("SMOOTHFLEET_AGENT_TOKEN secret-token-1\n", r"agent.env, line 3: not NAME=value$"),
        # a misspelt name would be ignored, and the vehicle left on no id
        (
            "SMOOTHFLEET_AGENT_VEHICEL_ID=SF-010\n",
            "line 3: SMOOTHFLEET_AGENT_VEHICEL_ID is no agent",
        ),
        ("SMOOTHFLEET_AGENT_VEHICLE_ID\n", "line 3: SMOOTHFLEET_AGENT_VEHICLE_ID has no '='"),
        # set twice, the last won without a word: the car ran as SF-002
        (
            "SMOOTHFLEET_AGENT_VEHICLE_ID=SF-001\nSMOOTHFLEET_AGENT_VEHICLE_ID=SF-002\n",
            r"line 4: SMOOTHFLEET_AGENT_VEHICLE_ID is set again \(first on line 3\)$",
        ),
    ],
)
def test_an_env_file_line_that_would_be_lost_is_refused(
    tmp_path: Path, text: str, error: str
) -> None:
    env_file = tmp_path / "agent.env"
    # a comment, a blank line and another program's name are fine
    env_file.write_text(
        "# SF-010's agent\n\n" + text + "OTHER_TOOL=1\nSMOOTHFLEET_AGENT_SERVER_URL=http://x\n"
    )
    with pytest.raises(AgentSettingsError, match=error) as refused:
        load_agent_settings(env_file, token="abc", vehicle_id="SF-010")
    assert "secret-token-1" not in str(refused.value)
    env_file.write_bytes(b"SMOOTHFLEET_AGENT_CAN=\xff\n")
    with pytest.raises(AgentSettingsError, match="cannot read .*agent.env: it is not UTF-8"):
        load_agent_settings(env_file)


def test_the_server_url_needs_a_scheme_and_a_host() -> None:
    for wrong in ("fleet.example", "https://"):
        with pytest.raises(
            AgentSettingsError, match="SMOOTHFLEET_AGENT_SERVER_URL: must be an http:// or https"
        ):
            load_agent_settings(server_url=wrong, token="abc", vehicle_id="SF-001")


def test_a_misspelt_setting_in_the_environment_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SMOOTHFLEET_AGENT_VEHICEL_ID", "SF-010")
    with pytest.raises(
        AgentSettingsError, match=r"SMOOTHFLEET_AGENT_VEHICEL_ID \(in the environment\) is no"
    ):
        load_agent_settings(server_url="http://x", token="abc", vehicle_id="SF-001")
    monkeypatch.delenv("SMOOTHFLEET_AGENT_VEHICEL_ID")
    monkeypatch.setenv("SMOOTHFLEET_AGENT_VEHICLE_ID", "SF-010")
    assert load_agent_settings(server_url="http://x", token="abc").vehicle_id == "SF-010"


def test_button_board_lines() -> None:
    assert board_lines("plus=17, minus=27,gap=22") == {
        CruiseButton.PLUS: 17,
        CruiseButton.MINUS: 27,
        CruiseButton.GAP: 22,
    }
    # one GPIO line wired to two buttons would press both: refused, as is a negative line
    with pytest.raises(ValueError, match="plus and minus share line 17: each needs its own"):
        board_lines("plus=17,minus=17,gap=22")
    with pytest.raises(ValueError, match="numbered from 0"):
        board_lines("plus=-1,minus=2,gap=3")


def test_an_unknown_log_level_is_a_setting_error() -> None:
    with pytest.raises(AgentSettingsError, match="SMOOTHFLEET_AGENT_LOG_LEVEL: must be one of"):
        load_agent_settings(
            server_url="http://x", token="abc", vehicle_id="SF-001", log_level="LOUD"
        )
    assert (
        load_agent_settings(
            server_url="http://x", token="abc", vehicle_id="SF-001", log_level="debug"
        ).log_level
        == "debug"
    )


def test_rate_keeper_sleeps_to_each_deadline_and_measures_lag() -> None:
    now = [0.0]
    sleeps: list[float] = []

    def sleep(seconds: float) -> None:
        sleeps.append(seconds)
        now[0] += seconds

    keeper = RateKeeper(0.1, clock=lambda: now[0], sleep=sleep)
    now[0] += 0.03  # the step took 30 ms
    assert keeper.wait() == 0.0
    assert sleeps == [pytest.approx(0.07)]
    now[0] += 0.15  # a 150 ms step: late by 50 ms
    assert keeper.wait() == pytest.approx(0.05)
    now[0] += 0.5  # a stall: missed deadlines are skipped, not replayed
    keeper.wait()
    assert keeper.missed >= 3
    assert keeper.next_deadline > now[0]


def test_sequencer_gives_up_after_unconfirmed_presses() -> None:
    sequencer = ButtonSequencer()
    sequencer.request(60, 3)
    time_s, presses = 0.0, []
    while time_s < 10.0:  # the car never reports a change
        presses.append(sequencer.step(time_s, 55.0, 3))
        time_s += 0.05
    assert sequencer.stalled
    assert sequencer.presses == 3
    assert presses[-1] is None
    sequencer.request(61, 3)  # a new request tries again
    assert sequencer.step(time_s, 55.0, 3) is CruiseButton.PLUS


def test_each_car_has_its_own_ping_spool_unless_one_is_named(tmp_path: Path) -> None:
    """One file for every car: a computer moved from SF-001 to SF-002 sent SF-001's pings with
    SF-002's token, which the server refuses whole (403), so no ping of SF-002 ever left."""
    first = load_agent_settings(server_url="http://x", token="abc", vehicle_id="SF-001")
    second = load_agent_settings(server_url="http://x", token="abc", vehicle_id="SF-002")
    assert first.spool_file.name == "spool-SF-001.sqlite"
    assert second.spool_file.name == "spool-SF-002.sqlite"
    assert first.spool_file.parent == second.spool_file.parent
    named = load_agent_settings(
        server_url="http://x", token="abc", vehicle_id="SF-001", spool_path=tmp_path / "p.sqlite"
    )
    assert named.spool_file == tmp_path / "p.sqlite"


def _board_env(tmp_path: Path, board: str | None) -> Path:
    env_file = tmp_path / "agent.env"
    env_file.write_text(
        "SMOOTHFLEET_AGENT_SERVER_URL=https://fleet.example/\n"
        "SMOOTHFLEET_AGENT_TOKEN=secret-token-1\n"
        "SMOOTHFLEET_AGENT_VEHICLE_ID=SF-010\n"
        f"SMOOTHFLEET_AGENT_GPIO_ROOT={tmp_path / 'gpio'}\n"
        + (f"SMOOTHFLEET_AGENT_BUTTON_BOARD={board}\n" if board else "")
    )
    return env_file


def test_release_buttons_lowers_a_line_a_killed_agent_left_high(tmp_path: Path) -> None:
    # an agent killed (SIGKILL) while it held minus: sysfs keeps the line high
    for line, level in ((17, "0"), (27, "1"), (22, "0")):
        (tmp_path / "gpio" / f"gpio{line}").mkdir(parents=True)
        (tmp_path / "gpio" / f"gpio{line}" / "value").write_text(level)
    env_file = _board_env(tmp_path, "plus=17,minus=27,gap=22")
    result = run_agent_cli("--env-file", str(env_file), "--release-buttons")
    assert result.returncode == 0, result.stderr
    levels = {
        line: (tmp_path / "gpio" / f"gpio{line}" / "value").read_text() for line in (17, 27, 22)
    }
    assert levels == {17: "0", 27: "0", 22: "0"}
    # a line that cannot be written is named, and the others are still written low
    (tmp_path / "gpio" / "gpio27" / "value").write_text("1")
    (tmp_path / "gpio" / "gpio17" / "value").unlink()
    (tmp_path / "gpio" / "gpio17").rmdir()
    failed = run_agent_cli("--env-file", str(env_file), "--release-buttons")
    assert failed.returncode == 1
    assert failed.stderr.startswith(
        "smoothfleet-agent: the plus line (GPIO 17) was not written low"
    )
    assert (tmp_path / "gpio" / "gpio27" / "value").read_text() == "0"
    # the agent itself refuses to start on a board it cannot lower
    refused = run_agent_cli("--env-file", str(env_file), "--can", "virtual:release-test")
    assert refused.returncode == 1
    assert "the plus line (GPIO 17) was not written low" in refused.stderr
    # a car without a board has nothing to release
    plain = run_agent_cli("--env-file", str(_board_env(tmp_path, None)), "--release-buttons")
    assert (plain.returncode, plain.stderr) == (0, "")


def test_the_service_releases_the_buttons_after_every_exit_of_the_agent() -> None:
    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.read(Path(__file__).parents[2] / "deploy" / "smoothfleet-agent.service")
    service = unit["Service"]
    # systemd runs ExecStopPost after any exit, a SIGKILL included, with the agent's settings
    assert service["ExecStopPost"] == service["ExecStart"] + " --release-buttons"
    assert service["Restart"] == "always"


def test_the_server_knows_every_agent_setting_by_name() -> None:
    """The server refuses a name under the shared prefix that no program reads; it knows the
    agent's one by one (contract.environment), so the two lists must not drift apart."""
    assert setting_names() == AGENT_VARIABLES


def test_a_setting_left_empty_is_unset(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`SMOOTHFLEET_AGENT_SPOOL_PATH=` was the path "": "cannot open the ping spool .", naming
    no setting, and an empty DBC cache dir wrote opendbc's cache into the working directory.
    Empty is unset: the default, or, for a setting the agent needs, the setting named."""
    env_file = tmp_path / "agent.env"
    env_file.write_text(
        "SMOOTHFLEET_AGENT_SERVER_URL=https://fleet.example/\n"
        "SMOOTHFLEET_AGENT_TOKEN=secret-token-1\n"
        "SMOOTHFLEET_AGENT_VEHICLE_ID=SF-010\n"
        "SMOOTHFLEET_AGENT_SPOOL_PATH=\n"
    )
    monkeypatch.setenv("SMOOTHFLEET_AGENT_DBC_CACHE_DIR", "")
    settings = load_agent_settings(env_file)
    assert settings.spool_path is None
    assert settings.dbc_cache_dir is None
    monkeypatch.setenv("SMOOTHFLEET_AGENT_SERVER_URL", "")
    env_file.write_text(
        "SMOOTHFLEET_AGENT_TOKEN=secret-token-1\nSMOOTHFLEET_AGENT_VEHICLE_ID=SF-010\n"
    )
    with pytest.raises(AgentSettingsError, match="SMOOTHFLEET_AGENT_SERVER_URL: Field required"):
        load_agent_settings(env_file)
