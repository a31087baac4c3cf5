"""`smoothfleet motion ...` in a subprocess, on the real record and a generated stretch."""

from __future__ import annotations

import csv
import io
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.support.servers import cli_env, run_cli, smoothfleet_command

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

    # A write that fails half-way (here a 1,000-byte file-size limit, as a full disk would)
    # kept none of the earlier file: the figure and the CSV were written in place. Now the
    # earlier file stays whole and the command says what failed.
    table = tmp_path / "fields.csv"
    table.write_text("an earlier field")
    edie_window = ["--since", "2022-11-16T12:00", "--until", "2022-11-16T12:01"]
    for output, command in (
        (figure, ["motion", "plot", "--date", "2022-11-16", "-o", str(figure)]),
        (table, ["motion", "edie", *edie_window, "--to-m", "13000", "-o", str(table)]),
    ):
        earlier = output.read_bytes()
        limited = run_cli(*command, env=env, file_size_limit_bytes=1000)
        assert limited.returncode == 1, limited.stderr
        assert output.read_bytes() == earlier
        assert "cannot be written (File too large); an earlier file there is kept" in " ".join(
            limited.stderr.split()
        )
        assert not [path for path in tmp_path.iterdir() if ".partial" in path.name]


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


def test_generate_refuses_a_bad_option_before_writing_anything(tmp_path: Path) -> None:
    """`--seed -1` stopped as "unexpected ValueError" from numpy once the output was opened,
    and left its first two bytes ("[\\n") under the output's name."""
    output = tmp_path / "out" / "hour.json"
    for option, value, reason in (
        ("--seed", "-1", "-1 is not in the range x>=0"),
        ("--lanes", "0", "0 is not in the range x>=1"),
    ):
        refused = run_cli("motion", "generate", "-o", str(output), option, value, env=cli_env())
        assert refused.returncode == 2, (option, refused.stderr)
        assert f"Invalid value for '{option}': {reason}" in refused.stderr
        assert "unexpected" not in refused.stderr
        assert not output.exists()
        assert not output.parent.exists() or not list(output.parent.iterdir())


def test_a_stopped_generate_leaves_no_partial_file_and_keeps_the_earlier_one(
    tmp_path: Path,
) -> None:
    """Stopped half-way, the output was a truncated JSON array in place of the earlier file.

    Stopped by SIGTERM (a service manager's stop; Ctrl-C unwinds the same way): the CLI installs
    its own SIGTERM handler, where a SIGINT would be ignored by a child of a shell that runs the
    tests in the background, as POSIX shells start background jobs with SIGINT ignored."""
    output = tmp_path / "hour.json"
    output.write_text("an earlier run's hour")
    process = subprocess.Popen(
        [*smoothfleet_command(), "motion", "generate", "-o", str(output), "--duration", "3600"],
        env=cli_env(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while len(list(tmp_path.iterdir())) < 2 and output.read_text() == "an earlier run's hour":
            assert process.poll() is None, process.communicate()[1]
            assert time.monotonic() < deadline, "the simulation never started writing"
            time.sleep(0.05)
        time.sleep(0.5)  # some trajectories written
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
        process.wait()
    assert process.returncode == 128 + signal.SIGTERM, stderr
    assert output.read_text() == "an earlier run's hour"
    assert list(tmp_path.iterdir()) == [output]
