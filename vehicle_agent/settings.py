"""The agent's settings: environment variables prefixed SMOOTHFLEET_AGENT_ (or an env file), the
command line overriding them. A missing or wrong setting stops the agent with one line naming it.
"""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

import platformdirs
from dotenv.parser import parse_stream
from pydantic import Field, SecretStr, ValidationError, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from contract.environment import AGENT_ENV_PREFIX
from contract.values import first_problem, http_url
from vehicle_agent.cars import CARS, CruiseButton
from vehicle_agent.plan import DEFAULT_WAVE_SPEED_MPS

ENV_PREFIX = AGENT_ENV_PREFIX
PLACEHOLDER_TOKENS = frozenset({"", "change-me", "changeme", "token", "secret"})
# gpsd's own address, for a `gpsd:` setting that leaves host or port out.
GPSD_HOST = "127.0.0.1"
GPSD_PORT = 2947
# What --log-level may say (any case): the logging module's named levels.
LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")


class AgentSettingsError(Exception):
    """A setting is missing or wrong; the message names it in one line."""


def agent_data_dir() -> Path:
    """Where the agent keeps its state by default (the spool, the policies)."""
    return Path(platformdirs.user_data_dir("smoothfleet-agent"))


class AgentSettings(BaseSettings):
    """Everything the agent can be told."""

    # NaN and infinity are no setting (they pass a bound's comparison or make a timeout endless)
    # A variable set empty is unset: an empty spool path was "cannot open the ping spool ." (no
    # setting named), an empty DBC cache dir wrote the cache into the working directory.
    model_config = SettingsConfigDict(
        env_prefix=ENV_PREFIX, extra="ignore", allow_inf_nan=False, env_ignore_empty=True
    )

    server_url: str
    token: SecretStr
    vehicle_id: str = Field(pattern=r"^[A-Za-z0-9_-]{1,32}$")
    # python-can channel: socketcan:can0 in a car, virtual:<name> in simulation.
    can: str = "socketcan:can0"
    # Car interface key (nissan_rogue, cadillac_xt5, toyota_rav4, nissan_rogue_2018); unset: from
    # the server config.
    make: str | None = None
    # gpsd:<host>:<port>, or none (no GPS: the agent reports but never takes over).
    gps: str = f"gpsd:{GPSD_HOST}:{GPSD_PORT}"
    # Unset: one file per vehicle (`spool_file`), so a computer moved to another car never
    # sends the first car's pings with the second's token (refused whole, they would block
    # every later upload).
    spool_path: Path | None = None
    spool_max_rows: int = Field(100_000, ge=100)
    # Where downloaded policies are kept, by sha256 (vehicle_agent/policies.py).
    policy_dir: Path = Field(default_factory=lambda: agent_data_dir() / "policies")
    dbc_cache_dir: Path | None = None
    http_timeout_s: float = Field(3.0, gt=0, le=60)
    wave_speed_mps: float = Field(DEFAULT_WAVE_SPEED_MPS, le=0, ge=-20)
    # GPIO button board instead of CAN button frames, e.g. "plus=17,minus=27,gap=22".
    button_board: str | None = None
    # Where the board's lines are exported (sysfs); another root where sysfs is mounted elsewhere.
    gpio_root: Path = Path("/sys/class/gpio")
    log_level: str = "INFO"

    @property
    def spool_file(self) -> Path:
        """The ping spool: `spool_path`, or this vehicle's file in the agent's data folder."""
        if self.spool_path is not None:
            return self.spool_path
        return agent_data_dir() / f"spool-{self.vehicle_id}.sqlite"

    @field_validator("server_url")
    @classmethod
    def _http_url(cls, value: str) -> str:
        return http_url(value).rstrip("/")

    @field_validator("token")
    @classmethod
    def _real_token(cls, value: SecretStr) -> SecretStr:
        if value.get_secret_value().strip().lower() in PLACEHOLDER_TOKENS:
            raise ValueError("must be the vehicle's token (smoothfleet tokens create)")
        return value

    @field_validator("can")
    @classmethod
    def _channel(cls, value: str) -> str:
        interface, sep, channel = value.partition(":")
        if not sep or not interface or not channel:
            raise ValueError("must be interface:channel, e.g. socketcan:can0")
        return value

    @field_validator("make")
    @classmethod
    def _known_make(cls, value: str | None) -> str | None:
        if value is not None and value not in CARS:
            raise ValueError(f"must be one of {', '.join(sorted(CARS))}")
        return value

    @field_validator("gps")
    @classmethod
    def _gps(cls, value: str) -> str:
        gpsd_address(value)
        return value

    @field_validator("log_level")
    @classmethod
    def _known_level(cls, value: str) -> str:
        if value.upper() not in LOG_LEVELS:
            raise ValueError(f"must be one of {', '.join(LOG_LEVELS)}")
        return value

    @field_validator("button_board")
    @classmethod
    def _board(cls, value: str | None) -> str | None:
        if value:
            board_lines(value)
        return value or None


def gpsd_address(spec: str) -> tuple[str, int] | None:
    """`gpsd:<host>:<port>` -> (host, port), host and port defaulting to gpsd's own; `none` ->
    None (no GPS); anything else a ValueError."""
    if spec == "none":
        return None
    host, _, port = spec.removeprefix("gpsd:").partition(":")
    if not spec.startswith("gpsd:") or not (
        port == "" or (port.isdigit() and 1 <= int(port) <= 65535)
    ):
        raise ValueError("must be gpsd:<host>:<port> (a port 1-65535) or none")
    return host or GPSD_HOST, int(port or GPSD_PORT)


def board_lines(spec: str) -> dict[CruiseButton, int]:
    """`plus=17,minus=27,gap=22` -> GPIO line per button."""
    lines: dict[CruiseButton, int] = {}
    for part in spec.split(","):
        name, sep, line = part.strip().partition("=")
        try:
            button = CruiseButton(name.strip().lower())
            lines[button] = int(line)
        except ValueError:
            raise ValueError(f"{part.strip()!r} is not button=line (plus, minus, gap)") from None
        if not sep:
            raise ValueError(f"{part.strip()!r} is not button=line")
    missing = {CruiseButton.PLUS, CruiseButton.MINUS, CruiseButton.GAP} - set(lines)
    if missing:
        raise ValueError(f"no line for {', '.join(sorted(b.value for b in missing))}")
    if any(line < 0 for line in lines.values()):
        raise ValueError("GPIO lines are numbered from 0")
    # one line wired to two buttons would press both whenever the agent presses either
    shared, uses = Counter(lines.values()).most_common(1)[0]
    if uses > 1:
        buttons = [button.value for button, used in lines.items() if used == shared]
        raise ValueError(f"{' and '.join(buttons)} share line {shared}: each needs its own")
    return lines


def load_agent_settings(env_file: Path | None = None, **overrides: object) -> AgentSettings:
    """Read the settings (command-line overrides win), or AgentSettingsError in one line."""
    given = {key: value for key, value in overrides.items() if value is not None}
    # a systemd unit's EnvironmentFile= or Environment= hands the settings over as variables:
    # a misspelt one is lost as silently as in --env-file
    known = setting_names()
    unknown = sorted(
        name
        for name in os.environ
        if name.upper().startswith(ENV_PREFIX) and name.upper() not in known
    )
    if unknown:
        raise AgentSettingsError(f"{unknown[0]} (in the environment) is no agent setting")
    if env_file is not None:
        check_env_file(env_file)
    try:
        return AgentSettings(_env_file=env_file, **given)  # type: ignore[arg-type]
    except ValidationError as error:
        problem = first_problem(error)
        name = ENV_PREFIX + problem.location[0].upper() if problem.location else "settings"
        raise AgentSettingsError(f"{name}: {problem.message}") from None


def setting_names() -> set[str]:
    """Every variable the agent reads, upper-case (the settings ignore case)."""
    return {ENV_PREFIX + name.upper() for name in AgentSettings.model_fields}


def check_env_file(env_file: Path) -> None:
    """Refuse a settings file that would lose a setting without a word: python-dotenv skips a
    line it cannot parse, and the settings ignore a name they do not know, so a car's
    `SMOOTHFLEET_AGENT_VEHICLE_ID SF-010` or `SMOOTHFLEET_AGENT_VEHICEL_ID=SF-010` would leave it
    on the default or stop it over a "missing" setting it was given. Names without the prefix
    are left alone (one file may serve other programs). The error names the line, never its
    text: the line may hold the token."""
    known = setting_names()
    try:
        with env_file.open(encoding="utf-8") as stream:
            bindings = list(parse_stream(stream))
    except FileNotFoundError:
        raise AgentSettingsError(f"--env-file: {env_file} does not exist") from None
    except (OSError, UnicodeDecodeError) as error:
        reason = error.strerror if isinstance(error, OSError) else "it is not UTF-8 text"
        raise AgentSettingsError(f"--env-file: cannot read {env_file}: {reason}") from None
    seen: dict[str, int] = {}
    for binding in bindings:
        original = binding.original
        # a binding's text begins with the blank lines before it; its own line comes after them
        line = original.line + len(original.string) - len(original.string.lstrip("\n"))
        where = f"--env-file {env_file}, line {line}"
        if binding.error:
            raise AgentSettingsError(f"{where}: not NAME=value")
        name = (binding.key or "").upper()
        if not name.startswith(ENV_PREFIX):
            continue
        if name not in known:
            raise AgentSettingsError(f"{where}: {name} is no agent setting")
        if binding.value is None:
            raise AgentSettingsError(f"{where}: {name} has no '=' and no value")
        if name in seen:
            # the last would win without a word: which one the car runs on is no guess to make
            raise AgentSettingsError(f"{where}: {name} is set again (first on line {seen[name]})")
        seen[name] = line
