"""Reading the real drives: units, positions, scenario kind, and clear errors for bad files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.drives import DriveError, drive_from_speeds, load_drive, load_drives

HEADER = "Time,Velocity\n"


def test_the_shared_drives(shared_dir: Path) -> None:
    drives = load_drives(shared_dir / "data" / "trajectories")
    assert len(drives) == 32
    kinds = {drive.name: drive.kind for drive in drives}
    # the six drives first shared: the two that never slow below 22 m/s are free flow
    assert {
        name: kinds[name]
        for name in (
            "2021-03-08-22-35-14_masterArray_0_5373",
            "2021-03-09-13-35-04_masterArray_0_4633",
            "2021-03-12-22-20-57_masterArray_0_7509",
            "2021-04-05-21-39-05_masterArray_1_9955",
            "2021-04-07-12-33-03_masterArray_0_4031",
            "2021-04-19-22-09-19_masterArray_0_5905",
        )
    } == {
        "2021-03-08-22-35-14_masterArray_0_5373": "shockwave",
        "2021-03-09-13-35-04_masterArray_0_4633": "freeflow",
        "2021-03-12-22-20-57_masterArray_0_7509": "shockwave",
        "2021-04-05-21-39-05_masterArray_1_9955": "shockwave",
        "2021-04-07-12-33-03_masterArray_0_4031": "freeflow",
        "2021-04-19-22-09-19_masterArray_0_5905": "shockwave",
    }
    # all 32: 20 with at least one slowdown wave, 12 free flow (16 sessions on 14 dates)
    assert sum(kind == "shockwave" for kind in kinds.values()) == 20
    assert len({name[:10] for name in kinds}) == 14
    for drive in drives:
        assert drive.dt_s == 0.1
        # each covers the same I-24 section: 13.09-13.10 km by GPS, about 1 % less by the
        # integrated wheel speed
        assert drive.position_m[-1] == pytest.approx(12_950, rel=0.005)


def test_speed_is_read_in_kmh_and_integrated(tmp_path: Path) -> None:
    path = tmp_path / "drive.csv"
    path.write_text(HEADER + "100.0,36\n100.1,36\n100.2,72\n")
    drive = load_drive(path)
    np.testing.assert_allclose(drive.speed_mps, [10.0, 10.0, 20.0])
    # trapezoids: 1.0 m, then (10 + 20) / 2 x 0.1 = 1.5 m
    np.testing.assert_allclose(drive.position_m, [0.0, 1.0, 2.5])
    np.testing.assert_allclose(drive.accel_mps2, [0.0, 100.0, 100.0])
    assert drive.duration_s == pytest.approx(0.2)
    # on its grid: nothing filled
    assert drive.filled_s == 0.0


def test_dropped_and_jittered_samples_are_filled_onto_the_grid(tmp_path: Path) -> None:
    path = tmp_path / "dropped.csv"
    # 100.2 and 100.3 dropped (a 0.3 s step), then one sample logged 0.04 s late
    path.write_text(HEADER + "100.0,36\n100.1,36\n100.4,72\n100.54,72\n100.6,72\n")
    drive = load_drive(path)
    assert drive.start_unix_s == 100.0
    assert drive.steps == 6
    # the dropped samples on the line between their neighbours (10 and 20 m/s), the late one
    # read at 100.5 between 100.4 and 100.54, both at 20 m/s
    np.testing.assert_allclose(drive.speed_mps, [10, 10, 10 + 10 / 3, 10 + 20 / 3, 20, 20, 20])
    # the steps off the grid: 0.3, 0.14 and 0.06 s
    assert drive.filled_s == pytest.approx(0.5)


@pytest.mark.parametrize(
    ("name", "rows", "error"),
    [
        ("gappy", "100.0,36\n100.1,36\n101.3,36\n", r"row 4: time step 1.200 s, a gap in the rec"),
        ("twice", "100.0,36\n100.1,36\n100.1,36\n", r"row 4: time step 0.000 s, time does not"),
        ("holes", "100.0,36\n100.1,\n", r"row 3: Time and Velocity must be finite"),
    ],
)
def test_a_recording_the_replay_cannot_use_is_named(
    tmp_path: Path, name: str, rows: str, error: str
) -> None:
    path = tmp_path / f"{name}.csv"
    path.write_text(HEADER + rows)
    with pytest.raises(DriveError, match=rf"{name}.csv {error}"):
        load_drive(path)


def test_every_refused_drive_of_a_folder_is_named_at_once(tmp_path: Path) -> None:
    (tmp_path / "a_good.csv").write_text(HEADER + "100.0,36\n100.1,36\n")
    (tmp_path / "b_gappy.csv").write_text(HEADER + "100.0,36\n101.3,36\n")
    (tmp_path / "c_holes.csv").write_text(HEADER + "100.0,36\n100.1,\n")
    with pytest.raises(DriveError) as refused:
        load_drives(tmp_path)
    lines = str(refused.value).splitlines()
    assert lines[0] == f"2 of the 3 drives in {tmp_path} cannot be replayed:"
    assert lines[1].startswith(f"{tmp_path / 'b_gappy.csv'} row 3: time step 1.300 s")
    assert lines[2].startswith(f"{tmp_path / 'c_holes.csv'} row 3: Time and Velocity")
    # one bad file alone is refused with its own message
    (tmp_path / "b_gappy.csv").unlink()
    with pytest.raises(DriveError, match=r"^\S+c_holes.csv row 3: Time and Velocity"):
        load_drives(tmp_path)


def test_a_file_without_the_columns_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "other.csv"
    path.write_text("a,b\n1,2\n")
    with pytest.raises(DriveError, match="other.csv"):
        load_drive(path)


def test_slices_for_short_runs(shared_dir: Path) -> None:
    drive = load_drives(shared_dir / "data" / "trajectories")[0]
    part = drive.slice(100.0, 60.0)
    assert part.steps == 600
    np.testing.assert_allclose(part.speed_mps, drive.speed_mps[1000:1601])
    with pytest.raises(DriveError, match="outside the drive"):
        drive.slice(500.0, 100.0)


def test_a_speed_that_changes_faster_than_a_car_can_is_counted() -> None:
    """A sample of 0 in a highway drive (170 m/s^2 each way) was replayed without a word, and
    the platoon's one takeover was the glitch's."""
    speeds = np.full(100, 17.0)
    speeds[60] = 0.0
    assert drive_from_speeds("glitch", speeds).glitches == (2, 5.9)
    assert drive_from_speeds("steady", np.full(100, 17.0)).glitches[0] == 0
    braking = 17.0 - 0.9 * np.arange(19)  # 9 m/s^2: hard, but a car
    assert drive_from_speeds("braking", braking).glitches[0] == 0
