"""`smoothfleet sim optimum` in a subprocess: a folder of drives in, optimum.csv and a cache out."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from sim.drives import load_drive
from sim.optimum import OPTIMUM_COLUMNS
from tests.support.servers import cli_env, run_cli


def _write_drive(path: Path, speed_kmh: np.ndarray) -> None:
    """A drive CSV as the recorder writes it: unix `Time` at 0.1 s, `Velocity` in km/h."""
    times = 1.6e9 + 0.1 * np.arange(len(speed_kmh))
    lines = ["Time,Velocity"] + [f"{t:.1f},{v:.4f}" for t, v in zip(times, speed_kmh, strict=True)]
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.slow
def test_cli_optimum_writes_one_row_per_drive_and_reuses_its_cache(tmp_path: Path) -> None:
    drives = tmp_path / "drives"
    drives.mkdir()
    t = np.arange(0.0, 60.05, 0.1)
    _write_drive(drives / "steady.csv", np.full(len(t), 90.0))
    _write_drive(drives / "dip.csv", 90.0 - 45.0 * np.exp(-(((t - 20.0) / 5.0) ** 2)))
    out = tmp_path / "out"
    args = ("sim", "optimum", "--drives", str(drives), "--humans", "4", "--out", str(out))

    first = run_cli(*args, env=cli_env(), timeout=300)
    assert first.returncode == 0, first.stderr
    with (out / "optimum.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == OPTIMUM_COLUMNS
    assert [row["drive"] for row in rows] == ["dip", "steady"]
    # the bound per group of drives: the dip's is a wave (not stop-and-go: above 10 m/s)
    saving = {row["drive"]: float(row["fuel_saving_pct"]) for row in rows}
    assert f"shockwave (1 drives): mean {saving['dip']:+.2f} %" in first.stdout
    assert f"freeflow (1 drives): mean {saving['steady']:+.2f} %" in first.stdout
    assert "stop-and-go" not in first.stdout
    by_drive = {row["drive"]: row for row in rows}
    assert float(by_drive["dip"]["fuel_saving_pct"]) > 1.0
    assert abs(float(by_drive["steady"]["fuel_saving_pct"])) < 0.1
    for row in rows:
        # what the bound was computed on, for `sim evaluate --optimum` to check
        assert row["drive_fingerprint"] == load_drive(drives / f"{row['drive']}.csv").fingerprint
        assert row["humans"] == "4"
        assert int(row["collisions"]) == 0
        assert float(row["gap_out_of_bounds_s"]) == 0.0
        accel = np.load(out / "optimum" / f"{row['drive']}.npy")
        assert len(accel) == 600

    # same drives, same settings: the cached rows come back as they were
    cached = (out / "optimum" / "dip.json").stat().st_mtime_ns
    again = run_cli(*args, "--drive", "dip", env=cli_env(), timeout=300)
    assert again.returncode == 0, again.stderr
    assert (out / "optimum" / "dip.json").stat().st_mtime_ns == cached
    with (out / "optimum.csv").open(newline="") as handle:
        assert list(csv.DictReader(handle)) == [by_drive["dip"]]

    # a second start: its own cache files beside the first's, the better of the two in the CSV
    both = run_cli(
        *args,
        "--drive",
        "dip",
        "--start-smoothing",
        "0",
        "--start-smoothing",
        "20",
        env=cli_env(),
        timeout=300,
    )
    assert both.returncode == 0, both.stderr
    assert (out / "optimum" / "dip.json").stat().st_mtime_ns == cached
    assert (out / "optimum" / "dip.start20s.npy").exists()
    with (out / "optimum.csv").open(newline="") as handle:
        [row] = list(csv.DictReader(handle))
    from_zero = float(by_drive["dip"]["fuel_saving_pct"])
    assert float(row["fuel_saving_pct"]) >= from_zero
    assert row["start_smoothing_s"] in ("0.0", "20.0")
    assert f"{from_zero:+.2f} % from 0 s" in both.stdout
    assert "from 20 s)" in both.stdout

    # another budget is another bound: the cache is not read, and the search stops on it (one
    # iteration in each of the four penalty stages)
    capped = run_cli(*args, "--drive", "dip", "--max-iterations", "1", env=cli_env(), timeout=300)
    assert capped.returncode == 0, capped.stderr
    assert (out / "optimum" / "dip.json").stat().st_mtime_ns != cached
    with (out / "optimum.csv").open(newline="") as handle:
        [row] = list(csv.DictReader(handle))
    assert 1 <= int(row["iterations"]) <= 4


def test_cli_optimum_names_an_unknown_drive_and_a_missing_folder(tmp_path: Path) -> None:
    missing = run_cli(
        "sim", "optimum", "--drives", str(tmp_path / "nowhere"), env=cli_env(), timeout=300
    )
    assert missing.returncode != 0
    assert "nowhere" in missing.stderr
    drives = tmp_path / "drives"
    drives.mkdir()
    _write_drive(drives / "steady.csv", np.full(20, 90.0))
    unknown = run_cli(
        "sim", "optimum", "--drives", str(drives), "--drive", "nope", env=cli_env(), timeout=300
    )
    assert unknown.returncode != 0
    assert "no drive nope" in unknown.stderr
    backwards = run_cli(
        "sim", "optimum", "--drives", str(drives), "--start-smoothing", "-5", env=cli_env()
    )
    assert backwards.returncode != 0
    assert "--start-smoothing" in backwards.stderr
    no_budget = run_cli(
        "sim", "optimum", "--drives", str(drives), "--max-iterations", "0", env=cli_env()
    )
    assert no_budget.returncode != 0
    # refused for its value, not as an option the command does not know
    assert "'--max-iterations': 0 is not in the range x>=1" in no_budget.stderr


def test_a_drive_without_a_bound_is_named_and_the_others_are_written(tmp_path: Path) -> None:
    drives = tmp_path / "drives"
    drives.mkdir()
    _write_drive(drives / "parked.csv", np.zeros(20))
    _write_drive(drives / "steady.csv", np.full(20, 90.0))
    out = tmp_path / "out"
    result = run_cli(
        "sim",
        "optimum",
        "--drives",
        str(drives),
        "--humans",
        "4",
        "--out",
        str(out),
        env=cli_env(),
        timeout=300,
    )
    assert result.returncode != 0
    assert "no bound for 1 of 2 drives: parked: the leader never moves" in result.stderr
    assert "Traceback" not in result.stderr
    # the drive after it still has its bound
    with (out / "optimum.csv").open(newline="") as handle:
        assert [row["drive"] for row in csv.DictReader(handle)] == ["steady"]
