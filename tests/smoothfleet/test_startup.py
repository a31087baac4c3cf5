"""A command imports what it uses: `sim` never touches the warehouse, so it must not pay
SQLAlchemy's and pandas' imports (4 s of every `smoothfleet sim` before they were lazy;
bench/cli_startup.py). Checked on the modules loaded, not on a clock."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys

import click
import pytest

from smoothfleet.cli.main import COMMANDS

HEAVY = ("sqlalchemy", "pandas", "matplotlib", "torch", "duckdb")


def modules_loaded_by(*words: str) -> set[str]:
    """Which HEAVY packages `smoothfleet WORDS --help` has imported when it exits."""
    code = (
        "import json, sys\n"
        "from smoothfleet.cli.main import cli\n"
        f"cli([*{list(words)!r}, '--help'], standalone_mode=False)\n"
        f"print(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    return set(json.loads(done.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize(
    ("words", "allowed"),
    [
        (("sim", "evaluate"), set()),
        (("sim", "train"), set()),
        (("policy", "upload"), set()),
        # the group's store (DuckDB) and the Edie window's defaults (with pandas) load with it
        (("motion", "generate"), {"pandas", "duckdb"}),
        (("db", "upgrade"), {"sqlalchemy"}),
    ],
)
def test_a_command_starts_with_only_what_it_uses(words: tuple[str, ...], allowed: set[str]) -> None:
    assert modules_loaded_by(*words) <= allowed


def test_the_listing_names_every_command() -> None:
    listing = subprocess.run(
        [sys.executable, "-m", "smoothfleet.cli", "--help"],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    ).stdout
    for command in (
        "analytics",
        "db",
        "demo",
        "inrix",
        "motion",
        "planner",
        "policy",
        "seed",
        "serve",
        "sim",
        "tokens",
        "users",
        "vehicles",
    ):
        assert f"  {command} " in listing, command


def test_the_listing_imports_no_command_and_says_what_each_says_itself() -> None:
    """`smoothfleet --help` names every command from the summaries beside the lazy table; each
    must read as the command's own help does when click shortens it, at any width."""
    code = (
        "import json, sys\n"
        "from click.testing import CliRunner\n"
        "from smoothfleet.cli.main import cli\n"
        "listing = CliRunner().invoke(cli, ['--help'], terminal_width=100).output\n"
        "loaded = [m for m in sys.modules if m.startswith('smoothfleet.cli.') and m not in (\n"
        "    'smoothfleet.cli.main', 'smoothfleet.cli.common')]\n"
        "print(json.dumps(loaded))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
    for name, lazy in COMMANDS.items():
        module, attribute = lazy.where.split(":")
        command = getattr(importlib.import_module(module), attribute)
        for limit in (20, 45, 80, 400):
            summary = click.Command(name, help=lazy.summary).get_short_help_str(limit)
            assert summary == command.get_short_help_str(limit), (name, limit)
