"""What every `smoothfleet` command group shares: the database it works on, its settings, its
console, and the one-line failure it may end with."""

from __future__ import annotations

import importlib
import math
import os
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
from rich.console import Console

from app.core.config import Settings, get_settings

console = Console()


class CliError(Exception):
    """An expected failure: its message is printed as one line and the exit code is 1."""


class FiniteFloatRange(click.FloatRange):
    """click's FloatRange without NaN and infinity, which pass its bounds (every comparison
    with NaN is false) and then fail far from the option that let them in."""

    def convert(
        self, value: Any, param: click.Parameter | None, ctx: click.Context | None
    ) -> float:
        number = float(super().convert(value, param, ctx))
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return number


def storable_text_option(
    ctx: click.Context, param: click.Parameter, value: str | None
) -> str | None:
    """An option's text if PostgreSQL can store it (`contract.values.storable_text`): bytes that
    are no UTF-8 on the command line (Python hands them over as lone surrogates) or a NUL are
    refused naming the option, not met as an "unexpected UnicodeEncodeError" at the database."""
    from contract.values import storable_text

    if value is None:
        return None
    try:
        return storable_text(value)
    except ValueError as error:
        raise click.BadParameter(f"{value!r}: {error}", ctx, param) from None


# A token's or row's id: PostgreSQL's bigint, which a larger number would overflow.
BIGINT_ID = click.IntRange(1, 2**63 - 1)


def output_folder(path: Path, option: str) -> Path:
    """`path` made a folder this user can write into, or a BadParameter naming `option`.

    Commands call it once their inputs are read and before they compute: a folder that cannot
    be made used to fail only when the results were written, minutes of simulation later, and
    lose them."""
    return _made_folder(path, path, option)


def output_file(path: Path, option: str) -> Path:
    """`path` a file that can be written: its folder made as `output_folder` makes one."""
    if path.is_dir():
        raise click.BadParameter(f"{path} is a folder, not a file", param_hint=option)
    _made_folder(path.parent, path, option)
    return path


def _made_folder(folder: Path, named: Path, option: str) -> Path:
    """Make `folder` for the output `named` on the command line, or say why it cannot be."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        for ancestor in (folder, *folder.parents):
            if ancestor.exists():
                if not ancestor.is_dir():
                    reason = f"{named}: {ancestor} is a file, not a folder"
                    raise click.BadParameter(reason, param_hint=option) from None
                break
        reason = f"{named}: {folder} cannot be made a folder ({error.strerror or error})"
        raise click.BadParameter(reason, param_hint=option) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        reason = f"{named}: this user cannot write into {folder}"
        raise click.BadParameter(reason, param_hint=option)
    return folder


@contextmanager
def replaced_on_success(path: Path) -> Iterator[Path]:
    """A temporary file beside `path` to write into, renamed to `path` when the block ends.

    A run that fails or is stopped half-way (Ctrl-C, SIGTERM, a full disk, a bug) removes it
    instead: `motion generate` used to leave a truncated JSON array under the output's name,
    which `motion import` then read as a broken file, and an earlier good file is kept. The
    same folder keeps the rename atomic (one file system). The name holds the process id, so
    two runs writing the same output do not share one, and ends in the output's suffix, from
    which a writer such as matplotlib takes the format; the writer creates the file, with the
    permissions any output of the user gets (mkstemp's would be 0600)."""
    partial = path.with_name(f".{path.stem}.{os.getpid()}.partial{path.suffix}")
    try:
        yield partial
        partial.replace(path)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise


def write_output(path: Path, content: str | bytes) -> None:
    """Write a command's whole output file beside `path` and rename it there
    (`write_output_with`)."""
    if isinstance(content, str):
        write_output_with(path, lambda partial: partial.write_text(content))
    else:
        write_output_with(path, lambda partial: partial.write_bytes(content))


def write_output_with(path: Path, write: Callable[[Path], object]) -> None:
    """Run `write` on a file beside `path` and rename it there (`replaced_on_success`): a
    write that fails (a full disk, a file-size limit) keeps an earlier file whole, where
    writing in place truncated it; the failure is a CliError that names the file."""
    try:
        with replaced_on_success(path) as partial:
            write(partial)
    except OSError as error:
        raise CliError(
            f"{path}: cannot be written ({error.strerror or error}); an earlier file there is kept"
        ) from None


@contextmanager
def database(settings: Settings) -> Iterator[str]:
    """The URL of the database to use, starting the embedded server if none is configured."""
    from app.core.db import check_reachable  # SQLAlchemy: only for commands with a database

    if settings.database_url is not None:
        check_reachable(settings.database_url, settings.db_connect_timeout_s)
        yield settings.database_url
        return
    from app.core.embedded import embedded_postgres

    with embedded_postgres(settings.data_dir) as url:
        yield url


def settings() -> Settings:
    """The settings of this invocation."""
    return get_settings()


@dataclass(frozen=True)
class LazyCommand:
    """Where a command lives (`module:attribute`), and the first line of its help, so the
    group's listing can name it without importing it (a test checks the two agree)."""

    where: str
    summary: str


class CommandGroup(click.Group):
    """A command group whose commands are imported when a command line names them.

    `smoothfleet db upgrade` should not first import pandas, matplotlib and the simulator for
    `motion` and `sim`, nor `smoothfleet sim evaluate` SQLAlchemy and the warehouse's models:
    together they were 4-6 s before every command, and `--help`, which lists them all, paid
    for every one. `lazy` maps a command's name to its `LazyCommand`.
    """

    def __init__(
        self, *args: object, lazy: Mapping[str, LazyCommand] | None = None, **kwargs: object
    ):
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._lazy = dict(lazy or {})

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*super().list_commands(ctx), *self._lazy})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        lazy = self._lazy.get(cmd_name)
        if lazy is not None and cmd_name not in self.commands:
            module, attribute = lazy.where.split(":")
            command = getattr(importlib.import_module(module), attribute)
            assert isinstance(command, click.Command), lazy.where
            self.add_command(command, cmd_name)
        return super().get_command(ctx, cmd_name)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The listing click writes, from the summaries of the commands not yet imported."""
        names = self.list_commands(ctx)
        if not names:
            return
        limit = formatter.width - 6 - max(len(name) for name in names)
        rows = []
        for name in names:
            loaded = self.commands.get(name)
            if loaded is not None:
                if not loaded.hidden:
                    rows.append((name, loaded.get_short_help_str(limit)))
            else:
                # shortened as click shortens a command's own help
                stand_in = click.Command(name, help=self._lazy[name].summary)
                rows.append((name, stand_in.get_short_help_str(limit)))
        with formatter.section("Commands"):
            formatter.write_dl(rows)


def fleet_options(command: Callable[..., None]) -> Callable[..., None]:
    """`--duration` and `--vehicles` of a simulated fleet run (`sim fleet`, `demo`)."""
    command = click.option(
        "--vehicles",
        type=click.IntRange(1, 100),
        default=100,
        show_default=True,
        help="How many roster vehicles the simulated fleet drives.",
    )(command)
    return click.option(
        "--duration",
        type=FiniteFloatRange(min=1),
        help="Stop after this many seconds (default: run until Ctrl-C).",
    )(command)
