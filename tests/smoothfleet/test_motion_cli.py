"""`smoothfleet motion ...` in a subprocess, on the real record and a generated stretch."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import pytest

from tests.support.servers import cli_env, run_cli

REAL_RECORD = "i24motion/INCEPTION.22-11-22.single_record_from_tutorial_notebook.json"


@pytest.mark.slow  # five CLI processes, one of them simulating a minute of traffic
def test_generate_import_twice_fields_and_plot(
    shared_dir: Path, seeded_database_url: str, tmp_path: Path
) -> None:
    env = cli_env(
        SMOOTHFLEET_DATABASE_URL=seeded_database_url, SMOOTHFLEET_MOTION_DIR=str(tmp_path / "s")
    )
    generated = tmp_path / "hour.json"
    made = run_cli(
        "motion",
        "generate",
        "-o",
        str(generated),
        "--start",
        "2022-11-16T12:00:00Z",
        "--duration",
        "60",
        "--lanes",
        "2",
        env=env,
    )
    assert made.returncode == 0, made.stderr
    assert "trajectories" in " ".join(made.stdout.split())

    real = shared_dir / "data" / REAL_RECORD
    first = run_cli("motion", "import", str(generated), str(real), env=env)
    assert first.returncode == 0, first.stderr
    assert "1 trajectories, 278 points imported" in " ".join(first.stdout.split())
    again = run_cli("motion", "import", str(generated), env=env)
    assert again.returncode == 0, again.stderr
    assert "already imported" in " ".join(again.stdout.split())

    fields = run_cli(
        "motion",
        "edie",
        "--since",
        "2022-11-16T12:00",
        "--until",
        "2022-11-16T12:01",
        "--from-m",
        "6000",
        "--to-m",
        "13000",
        env=env,
    )
    assert fields.returncode == 0, fields.stderr
    rows = list(csv.DictReader(io.StringIO(fields.stdout)))
    assert rows
    assert all(float(row["density_veh_per_m"]) > 0 for row in rows)
    assert {"fuel_per_distance_g_per_m", "speed_mps", "vehicles"} <= set(rows[0])

    figure = tmp_path / "figure.png"
    plotted = run_cli("motion", "plot", "--date", "2022-11-16", "-o", str(figure), env=env)
    assert plotted.returncode == 0, plotted.stderr
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    nothing = run_cli("motion", "plot", "--date", "2001-01-01", "-o", str(figure), env=env)
    assert nothing.returncode == 1
    assert "no MOTION trajectories imported for 2001-01-01" in " ".join(nothing.stderr.split())


def test_a_missing_file_and_a_bad_window_say_what_is_wrong(tmp_path: Path) -> None:
    env = cli_env(SMOOTHFLEET_MOTION_DIR=str(tmp_path / "s"), SMOOTHFLEET_DATA_DIR=str(tmp_path))
    missing = run_cli("motion", "import", str(tmp_path / "none.json"), env=env)
    assert missing.returncode == 1
    assert "none.json: no such file" in " ".join(missing.stderr.split())
    backwards = run_cli(
        "motion", "edie", "--since", "2022-11-16T13:00", "--until", "2022-11-16T12:00", env=env
    )
    assert backwards.returncode == 1
    assert "must be after since" in " ".join(backwards.stderr.split())
    # a tie point or a box that is no finite number is refused at the option, before any
    # position is computed from it (NaN imported NaN positions; infinity overflowed)
    nan_anchor = run_cli(
        "motion", "import", "--anchor-x-ft", "nan", str(tmp_path / "none.json"), env=env
    )
    assert nan_anchor.returncode == 2
    assert "'--anchor-x-ft': 'nan' is not a finite number" in nan_anchor.stderr
    endless = run_cli(
        "motion",
        "edie",
        "--since",
        "2022-11-16T12:00",
        "--until",
        "2022-11-16T13:00",
        "--h-x",
        "inf",
        env=env,
    )
    assert endless.returncode == 2
    assert "'--h-x': 'inf' is not a finite number" in endless.stderr
