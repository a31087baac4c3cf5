"""The readers of the recorded data: units, holes, and errors that name the file and row."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contract.recorded import RecordingError, read_inrix_minutes, read_trajectory


def test_a_drive_is_read_in_si_with_its_gps(tmp_path: Path) -> None:
    path = tmp_path / "drive.csv"
    path.write_text(
        ",Time,Velocity,LongitudeGPS,LatitudeGPS\n0,100.0,36,-86.6,36.06\n1,100.1,90,,\n"
    )
    drive = read_trajectory(path)
    assert drive.name == "drive"
    np.testing.assert_allclose(drive.time_unix_s, [100.0, 100.1])
    # 36 km/h = 10 m/s, 90 km/h = 25 m/s
    np.testing.assert_allclose(drive.speed_mps, [10.0, 25.0])
    np.testing.assert_allclose(drive.latitude_deg, [36.06, np.nan])
    np.testing.assert_allclose(drive.longitude_deg, [-86.6, np.nan])


def test_a_drive_without_gps_columns_has_no_fixes(tmp_path: Path) -> None:
    folder = tmp_path / "2021-03-08-drive"
    folder.mkdir()
    (folder / "trajectory.csv").write_text("Time,Velocity\n1.0,3.6\n")
    drive = read_trajectory(folder / "trajectory.csv")
    assert drive.name == "2021-03-08-drive"
    assert np.isnan(drive.latitude_deg).all()


def test_text_in_a_number_column_is_named(tmp_path: Path) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("Time,Velocity\n1.0,3.6\n1.1,fast\n")
    with pytest.raises(RecordingError, match=r"bad.csv row 3: 'fast' is not a number"):
        read_trajectory(path)


def test_a_missing_column_is_named(tmp_path: Path) -> None:
    path = tmp_path / "other.csv"
    path.write_text("Time,Speed\n1.0,3.6\n")
    with pytest.raises(RecordingError, match="other.csv: no column Velocity"):
        read_trajectory(path)


def _inrix_folder(folder: Path, *, cvalue_times: str = "-60.0,0.0") -> Path:
    folder.mkdir()
    (folder / "segments.json").write_text("[0.0, 800.0]")
    (folder / "speed.csv").write_text("time,0,1\n-60.0,30.5,20.0\n0.0,29.0,\n")
    (folder / "confidence.csv").write_text("time,0,1\n-60.0,30,10\n0.0,30,30\n")
    first, second = cvalue_times.split(",")
    (folder / "cvalue.csv").write_text(f"time,0,1\n{first},90,50\n{second},80,70\n")
    return folder


def test_inrix_minutes_beside_a_drive(tmp_path: Path) -> None:
    minutes = read_inrix_minutes(_inrix_folder(tmp_path / "drive"))
    np.testing.assert_allclose(minutes.segment_start_m, [0.0, 800.0])
    np.testing.assert_allclose(minutes.time_s, [-60.0, 0.0])
    np.testing.assert_allclose(minutes.speed_mps, [[30.5, 20.0], [29.0, np.nan]])
    np.testing.assert_allclose(minutes.score, [[30, 10], [30, 30]])
    np.testing.assert_allclose(minutes.c_value, [[90, 50], [80, 70]])


def test_a_spreadsheets_byte_order_mark_is_no_part_of_the_first_name(tmp_path: Path) -> None:
    """Saved as "CSV UTF-8" with Time first, a drive was refused: "no column Time"."""
    path = tmp_path / "excel.csv"
    path.write_bytes("\ufeffTime,Velocity\r\n1.0,36.0\r\n1.1,36.0\r\n".encode())
    assert read_trajectory(path).speed_mps.tolist() == [10.0, 10.0]


@pytest.mark.parametrize("where", ["header", "rows"])
def test_a_file_that_is_not_utf8_is_named(tmp_path: Path, where: str) -> None:
    """It was "unexpected UnicodeDecodeError", naming no file among a folder of drives."""
    path = tmp_path / "latin.csv"
    if where == "header":
        path.write_bytes("Time,Velocity,Température\n1.0,36.0,5\n".encode("cp1252"))
    else:
        path.write_bytes("Time,Velocity,Note\n1.0,36.0,é\n".encode("cp1252"))
    with pytest.raises(RecordingError, match=r"latin.csv: not UTF-8 text \(.*CSV UTF-8$"):
        read_trajectory(path)


def test_inrix_minutes_that_do_not_increase_are_refused_by_file_and_row(tmp_path: Path) -> None:
    """A repeated minute failed only once simulating had begun, in the planner, naming no
    folder."""
    folder = _inrix_folder(tmp_path / "drive")
    for name in ("speed.csv", "confidence.csv", "cvalue.csv"):
        lines = (folder / name).read_text().splitlines()
        (folder / name).write_text("\n".join([lines[0], lines[1], lines[1], lines[2]]) + "\n")
    with pytest.raises(RecordingError, match=r"speed.csv row 3: time -60 s after -60 s"):
        read_inrix_minutes(folder)


def test_inrix_tables_that_disagree_are_refused(tmp_path: Path) -> None:
    folder = _inrix_folder(tmp_path / "drive", cvalue_times="-60.0,60.0")
    with pytest.raises(RecordingError, match="speed, confidence and cvalue rows differ"):
        read_inrix_minutes(folder)


def test_the_shared_inrix_minutes(shared_dir: Path) -> None:
    folder = next((shared_dir / "data" / "trajectories_with_inrix").iterdir())
    minutes = read_inrix_minutes(folder)
    assert minutes.speed_mps.shape == (len(minutes.time_s), 21)
    assert np.all(np.diff(minutes.time_s) == pytest.approx(60.0))
    assert minutes.time_s[0] < 0  # the minutes before the drive are there too
    assert read_trajectory(folder / "trajectory.csv").name == folder.name


def test_a_header_alone_is_an_empty_drive(tmp_path: Path) -> None:
    path = tmp_path / "empty.csv"
    path.write_text("Time,Velocity\n")
    assert len(read_trajectory(path).time_unix_s) == 0
