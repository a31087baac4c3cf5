"""Output folders and files are checked before a command computes, not when it writes: a path
that cannot hold the results used to fail after minutes of simulation and lose them."""

from __future__ import annotations

from pathlib import Path

import click
import pytest

from smoothfleet.cli.common import output_file, output_folder
from tests.support.servers import cli_env, run_cli


def test_folders_and_their_parents_are_made(tmp_path: Path) -> None:
    made = output_folder(tmp_path / "a" / "b", "--out")
    assert made.is_dir()
    assert output_folder(made, "--out") == made  # an existing one is kept
    assert output_file(tmp_path / "c" / "figure.png", "-o") == tmp_path / "c" / "figure.png"
    assert (tmp_path / "c").is_dir()
    assert not (tmp_path / "c" / "figure.png").exists()


def test_a_file_in_the_way_is_named(tmp_path: Path) -> None:
    blocker = tmp_path / "results"
    blocker.write_text("an earlier run's CSV")
    with pytest.raises(click.BadParameter, match=f"{blocker} is a file, not a folder"):
        output_folder(blocker / "sub", "--out")
    with pytest.raises(click.BadParameter, match=f"{blocker}/x.png: {blocker} is a file"):
        output_file(blocker / "x.png", "-o")
    with pytest.raises(click.BadParameter, match=f"{tmp_path} is a folder, not a file"):
        output_file(tmp_path, "-o")
    assert blocker.read_text() == "an earlier run's CSV"


def test_commands_refuse_it_before_computing(tmp_path: Path, shared_dir: Path) -> None:
    blocker = tmp_path / "results"
    blocker.write_text("")
    recorded = sorted((shared_dir / "data" / "trajectories_with_inrix").iterdir())[0]
    for command in (
        ("inrix", "convert", str(recorded), str(blocker / "recording.jsonl")),
        ("sim", "evaluate", "--out", str(blocker / "evaluation")),
        ("sim", "select", "--out", str(blocker / "selection")),
        ("sim", "time-space", "-o", str(blocker / "time_space.png")),
        ("sim", "optimum", "--out", str(blocker / "optimum")),
    ):
        result = run_cli(*command, env=cli_env())
        assert result.returncode == 2, (command, result.stderr)
        assert f"{blocker} is a file, not a folder" in result.stderr
        assert "Traceback" not in result.stderr
