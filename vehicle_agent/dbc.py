"""The makes' DBC files: shipped with the agent, or generated from the opendbc package into a
cache directory; then parsed.

A car opendbc does not cover (the 2023 Nissan Rogue, whose CAN-FD frames no opendbc DBC
describes) has its DBC in `vehicle_agent/cars/dbc/`, installed with the package and read as is.

opendbc ships most car DBCs as templates that `opendbc.dbc.generator.generator.generate_all()`
assembles in memory (`<name>_generated`). We write the ones we use to a cache directory named
after the opendbc version, so a car parses files from disk at start-up and never regenerates them
(and an upgrade of opendbc regenerates once). Parsed databases are shared per process: the demo
runs a hundred agents in one process.

Two repairs for cantools, both deliberate: the DBCs are parsed non-strictly (opendbc overlaps
a few placeholder signals in messages we never use, e.g. Toyota's PCS_HUD), and value tables
naming a signal their message does not have are dropped (GM's powertrain DBC names
`GasRegenCmdActiveInv` on a message that lacks it, which cantools refuses even non-strictly).
"""

from __future__ import annotations

import os
import re
import threading
from importlib import metadata
from pathlib import Path

import cantools
import platformdirs
from cantools.database.can import Database as CanDatabase
from cantools.database.errors import UnsupportedDatabaseFormatError

# DBCs shipped with the agent, by name (`<name>.dbc`); every other name comes from opendbc.
BUNDLED_DBC_DIR = Path(__file__).with_name("cars") / "dbc"

_MESSAGE = re.compile(r"^BO_ (\d+) ")
_SIGNAL = re.compile(r"^\s+SG_ (\w+)")
_VALUE_TABLE = re.compile(r"^VAL_ (\d+) (\w+) ")

_lock = threading.Lock()
_databases: dict[tuple[str, Path], CanDatabase] = {}


class DbcError(RuntimeError):
    """A DBC cannot be found or parsed; the message names it."""


def default_cache_dir() -> Path:
    """Where generated DBCs are kept between runs (per opendbc version)."""
    return Path(platformdirs.user_cache_dir("smoothfleet")) / "dbc"


def _opendbc_version() -> str:
    try:
        return metadata.version("opendbc")
    except metadata.PackageNotFoundError:
        return "unknown"


def without_orphan_value_tables(text: str) -> str:
    """Drop `VAL_` lines naming a signal their message does not define."""
    signals: dict[str, set[str]] = {}
    current: set[str] | None = None
    for line in text.splitlines():
        message = _MESSAGE.match(line)
        if message:
            current = signals.setdefault(message.group(1), set())
            continue
        signal = _SIGNAL.match(line)
        if signal and current is not None:
            current.add(signal.group(1))
        elif not line.strip():
            current = None
    kept = []
    for line in text.splitlines(keepends=True):
        table = _VALUE_TABLE.match(line)
        if table and table.group(2) not in signals.get(table.group(1), set()):
            continue
        kept.append(line)
    return "".join(kept)


def generated_dbc_path(name: str, cache_dir: Path | None = None) -> Path:
    """The generated DBC file for `name` (e.g. toyota_nodsu_pt), generating the cache if needed."""
    directory = (cache_dir or default_cache_dir()) / f"opendbc-{_opendbc_version()}"
    path = directory / f"{name}.dbc"
    if path.exists():
        return path
    from opendbc.dbc.generator.generator import generate_all

    generated = generate_all()
    content = generated.get(f"{name}_generated") or generated.get(name)
    if content is None:
        raise DbcError(f"opendbc has no generated DBC named {name!r}")
    # Write-then-rename: agents starting together never read a half-written file.
    temporary = directory / f".{name}.{os.getpid()}.{threading.get_ident()}.tmp"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        temporary.write_text(without_orphan_value_tables(content), encoding="utf-8")
        temporary.replace(path)
    except OSError as error:
        raise DbcError(
            f"cannot write the generated DBC {name} into {directory} "
            f"({error.strerror or error}): set SMOOTHFLEET_AGENT_DBC_CACHE_DIR to a folder "
            "the agent may write"
        ) from None
    return path


def dbc_path(name: str, cache_dir: Path | None = None) -> Path:
    """The file of DBC `name`: the shipped one if there is one, else opendbc's, generated."""
    bundled = BUNDLED_DBC_DIR / f"{name}.dbc"
    return bundled if bundled.is_file() else generated_dbc_path(name, cache_dir)


def load_dbc(name: str, cache_dir: Path | None = None) -> CanDatabase:
    """The parsed DBC `name`, shared by every agent of the process."""
    key = (name, (cache_dir or default_cache_dir()).resolve())
    with _lock:
        cached = _databases.get(key)
        if cached is not None:
            return cached
        path = dbc_path(name, cache_dir)
        try:
            database = cantools.database.load_file(str(path), strict=False)
        except (OSError, ValueError, UnsupportedDatabaseFormatError) as error:
            raise DbcError(f"cannot parse {path}: {error}") from None
        if not isinstance(database, CanDatabase):
            raise DbcError(f"{path} is not a CAN database")
        _databases[key] = database
        return database
