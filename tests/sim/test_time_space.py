"""`smoothfleet sim time-space`: the all-human platoon beside the recommended pair, drawn."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from sim.drives import drive_from_speeds
from tests.sim.test_evaluate import short_drives, write_drive
from tests.support.servers import cli_env, run_cli


def test_the_diagram_shows_both_platoons_and_says_what_the_pair_did(
    shared_dir: Path, tmp_path: Path
) -> None:
    stop_and_go, _ = short_drives(shared_dir)
    drive = tmp_path / "2021-04-05-21-39-05_slice.csv"
    write_drive(stop_and_go.slice(0.0, 120.0), drive)  # two minutes of it: one wave
    output = tmp_path / "figures" / "time_space.png"
    result = run_cli(
        "sim", "time-space", "--drive", str(drive), "-o", str(output), env=cli_env(), timeout=300
    )
    assert result.returncode == 0, result.stderr
    assert f"wrote {output}" in " ".join(result.stdout.split())
    # two panels side by side, in colour (speed), on a white page
    with Image.open(output) as image:
        width, height = image.size
        pixels = np.asarray(image.convert("RGB"), dtype=np.int16)
    assert width > 1.8 * height
    coloured = np.ptp(pixels, axis=2) > 60
    left, right = coloured[:, : width // 2], coloured[:, width // 2 :]
    assert left.mean() > 0.02
    assert right.mean() > 0.02
    # the pair's figures in its panel's title, and on the terminal
    assert "fuel saving +" in result.stdout or "fuel saving -" in result.stdout
    assert "takeovers" in result.stdout


def test_a_leader_that_never_moves_has_no_saving_to_show(tmp_path: Path) -> None:
    drive = tmp_path / "2021-05-02-10-00-00_parked.csv"
    write_drive(drive_from_speeds("parked", np.zeros(600)), drive)
    result = run_cli(
        "sim", "time-space", "--drive", str(drive), "-o", str(tmp_path / "ts.png"), env=cli_env()
    )
    assert result.returncode == 0, result.stderr
    assert "fuel saving n/a, network speed n/a" in result.stdout


def test_a_missing_drive_is_named(tmp_path: Path) -> None:
    result = run_cli(
        "sim", "time-space", "--drive", str(tmp_path / "none.csv"), "-o", "x.png", env=cli_env()
    )
    assert result.returncode != 0
    assert "none.csv' does not exist" in result.stderr


def test_a_figure_name_without_a_known_format_is_refused_before_the_simulation(
    tmp_path: Path,
) -> None:
    """`-o ts` ran both platoons and then failed "Format 'partial' is not supported"."""
    for name in ("ts", "ts.xyz"):
        result = run_cli("sim", "time-space", "-o", str(tmp_path / name), env=cli_env())
        assert result.returncode == 2
        assert "name the figure's format by its suffix, one of" in result.stderr
        assert ".png" in result.stderr
