"""Importing MOTION files: the real record, bad documents with reasons, nothing added twice."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.motion.importer import import_motion_file
from app.motion.store import connect
from contract.units import METRES_PER_FOOT
from tests.app.motion.conftest import METRIC_FRAME, document, write

REAL_RECORD = "i24motion/INCEPTION.22-11-22.single_record_from_tutorial_notebook.json"


def _count(store: Path, table: str) -> int:
    with connect(store) as connection:
        row = connection.execute(f"SELECT count(*) FROM {table}").fetchone()
    assert row is not None
    return int(row[0])


def test_the_real_record_lands_on_the_corridor(shared_dir: Path, tmp_path: Path) -> None:
    path = shared_dir / "data" / REAL_RECORD
    report = import_motion_file(path, tmp_path)
    assert (report.documents, report.points, report.bad) == (1, 278, [])
    with connect(tmp_path) as connection:
        row = connection.execute(
            "SELECT document_id, day, first_x_m, last_x_m, lane, vehicle_class, length_m,"
            " fuel_model, points, last_t_s - first_t_s FROM motion_trajectories"
        ).fetchone()
        first = connection.execute(
            "SELECT x_m, lane FROM motion_points ORDER BY t_s LIMIT 1"
        ).fetchone()
    assert row is not None
    assert first is not None
    document_id, day, first_x, last_x, lane, vehicle_class, length_m, model, points, span = row
    assert (document_id, str(day), points) == ("638bb843e38fd878abf4f6fe", "2022-11-22", 278)
    # Westbound from milepost 59.63 to 59.52: (348480 - x_ft) * 0.3048 + 717.17 m, increasing.
    assert first_x == pytest.approx(10971.56, abs=0.01)
    assert last_x == pytest.approx(10971.56 + (314836.966 - 314245.548) * 0.3048, abs=0.01)
    assert first[0] == pytest.approx(10971.56, abs=0.01)
    # y = 65.2 ft: (65.2 - 12) / 12 -> lane 5, beyond the four through lanes.
    assert (lane, first[1], vehicle_class, model) == (5, 5, 3, "RAV4_2019")
    assert length_m == pytest.approx(23.1355 * METRES_PER_FOOT, rel=1e-5)
    assert span == pytest.approx(277 * 0.04, abs=1e-3)  # 278 points at 25 Hz


def test_reimporting_a_file_adds_nothing(shared_dir: Path, tmp_path: Path) -> None:
    path = shared_dir / "data" / REAL_RECORD
    import_motion_file(path, tmp_path)
    again = import_motion_file(path, tmp_path)
    assert again.already_imported
    assert (again.documents, again.points) == (0, 0)
    assert (_count(tmp_path, "motion_points"), _count(tmp_path, "motion_trajectories")) == (278, 1)


def test_a_document_already_stored_from_another_file_is_a_duplicate(tmp_path: Path) -> None:
    first = document("one", [0.0, 1.0], [0.0, 20.0])
    second = document("two", [0.0, 1.0], [5.0, 25.0])
    import_motion_file(write(tmp_path / "a.json", [first]), tmp_path / "s", METRIC_FRAME)
    report = import_motion_file(
        write(tmp_path / "b.json", [first, second, second]), tmp_path / "s", METRIC_FRAME
    )
    assert (report.documents, report.duplicates) == (1, 2)
    assert _count(tmp_path / "s", "motion_trajectories") == 2


def test_bad_documents_are_counted_with_their_reason_and_the_rest_imported(
    tmp_path: Path,
) -> None:
    good = document("good", [0.0, 1.0, 2.0], [0.0, 20.0, 40.0])
    no_x = {
        key: value for key, value in document("no-x", [0.0], [0.0]).items() if key != "x_position"
    }
    short = document("short", [0.0, 1.0], [0.0, 1.0]) | {"y_position": [1.0]}
    text_x = document("text", [0.0, 1.0], [0.0, 1.0]) | {"x_position": [0.0, "far"]}
    backwards = document("back", [1.0, 0.5], [0.0, 1.0])
    null_x = document("null", [0.0, 1.0], [0.0, 1.0]) | {"x_position": [0.0, None]}
    westbound = document("west", [0.0, 1.0], [0.0, 1.0], direction=-1)
    sideways = document("side", [0.0, 1.0], [0.0, 1.0]) | {"direction": 7}
    no_id = document("", [0.0, 1.0], [0.0, 1.0])
    docs = [good, no_x, short, text_x, backwards, null_x, westbound, sideways, no_id, 42]
    report = import_motion_file(write(tmp_path / "m.json", docs), tmp_path / "s", METRIC_FRAME)
    assert (report.documents, report.points, report.other_direction) == (1, 3, 1)
    reasons = {bad.index: bad.reason for bad in report.bad}
    assert reasons[1] == "no x_position array"
    assert reasons[2] == "timestamp, x_position and y_position differ in length (2, 2, 1)"
    assert reasons[3] == 'x_position[1] is a string ("far") where MOTION has a number'
    assert reasons[4] == "timestamps do not increase at point 1"
    assert reasons[5] == "non-finite or null value at point 1"
    assert reasons[7] == "direction must be -1 (westbound) or 1 (eastbound)"
    assert reasons[8] == "no _id.$oid"
    assert reasons[9] == "not a JSON object"
    assert len(reasons) == 8
    manifest = json.loads(next((tmp_path / "s" / "imports").glob("*.json")).read_text())
    assert (manifest["documents"], manifest["bad_documents"]) == (1, 8)
    assert {entry["reason"] for entry in manifest["bad"]} == set(reasons.values())


def test_timestamps_in_milliseconds_are_one_documents_error(tmp_path: Path) -> None:
    """A document whose timestamps were in milliseconds ended the whole import in 'year 54862
    is out of range', the good documents with it, staging files left behind (analytics audit)."""
    good = document("good", [1.6e9, 1.6e9 + 1], [0.0, 20.0])
    millis = document("millis", [1.6e12, 1.6e12 + 1000], [0.0, 20.0])
    report = import_motion_file(
        write(tmp_path / "m.json", [good, millis]), tmp_path / "s", METRIC_FRAME
    )
    assert report.documents == 1
    assert [bad.reason for bad in report.bad] == [
        "timestamp 1600000000000 at point 0 is no time in seconds between 1970 and 2100 "
        "(milliseconds?)"
    ]
    assert _count(tmp_path / "s", "motion_trajectories") == 1
    assert not any((tmp_path / "s" / "staging").glob("*/*"))


def test_a_position_off_i24_or_a_class_past_16_bits_is_one_documents_error(tmp_path: Path) -> None:
    """Positions were taken as given: one point 1e9 m along sized the day figure's grid at 5 M
    boxes a column, 1e300 ft was stored as an infinite x with NaN fuel, and a lane 300,000 ft
    across the road was lane 17,797."""
    good = document("good", [1.6e9, 1.6e9 + 1], [0.0, 20.0])
    far = document("far", [1.6e9, 1.6e9 + 1], [0.0, 1e9])
    across = document("across", [1.6e9, 1.6e9 + 1], [0.0, 20.0]) | {"y_position": [-18.0, 3e5]}
    # and a class over the store's 16 bits wrapped (70000 was stored as 4464)
    wide = document("wide", [1.6e9, 1.6e9 + 1], [0.0, 20.0], vehicle_class=70_000)
    report = import_motion_file(
        write(tmp_path / "m.json", [good, far, across, wide]), tmp_path / "s", METRIC_FRAME
    )
    assert report.documents == 1
    reasons = {bad.index: bad.reason for bad in report.bad}
    assert reasons[1].startswith("position (3280839895.01312, -18) ft at point 1 is not on I-24")
    assert reasons[2].startswith("position (65.6167979002625, 300000) ft at point 1 is not on I-24")
    assert reasons[3] == "coarse_vehicle_class 70000 is no vehicle class (0 to 32,767)"
    assert _count(tmp_path / "s", "motion_trajectories") == 1


def test_a_file_of_numbers_is_bad_content_not_a_crash(tmp_path: Path) -> None:
    """'[1, 2, 3]' ended in 'max() arg is an empty sequence' (analytics audit)."""
    path = tmp_path / "numbers.json"
    path.write_text("[1, 2, 3]")
    report = import_motion_file(path, tmp_path / "s", METRIC_FRAME)
    assert (report.documents, [bad.reason for bad in report.bad]) == (0, ["not a JSON object"])


def test_a_file_with_nothing_to_import_is_counted_not_an_error(tmp_path: Path) -> None:
    """A file of the other direction only, or of bad documents only, imports nothing and says
    why (it used to end in an IndexError)."""
    westbound = [document(f"w{i}", [0.0, 1.0], [0.0, 1.0], direction=-1) for i in range(3)]
    other = import_motion_file(write(tmp_path / "w.json", westbound), tmp_path / "s", METRIC_FRAME)
    assert (other.documents, other.other_direction, other.bad) == (0, 3, [])
    broken = [document("short", [0.0, 1.0], [0.0]), {"a": 1}]
    bad = import_motion_file(write(tmp_path / "b.json", broken), tmp_path / "s", METRIC_FRAME)
    assert (bad.documents, len(bad.bad)) == (0, 2)
    assert _count(tmp_path / "s", "motion_trajectories") == 0


def test_a_file_that_breaks_off_keeps_the_documents_before_the_break(tmp_path: Path) -> None:
    text = json.dumps([document("a", [0.0, 1.0], [0.0, 20.0]), document("b", [0.0], [1.0])])
    path = tmp_path / "cut.json"
    path.write_text(text[: text.index('"b"') + 20])
    report = import_motion_file(path, tmp_path / "s", METRIC_FRAME)
    assert report.documents == 1
    assert report.file_error is not None
    assert "the file ends inside a document" in report.file_error
    assert import_motion_file(path, tmp_path / "s", METRIC_FRAME).already_imported


WRONG_TYPES = [
    ({"timestamp": ["0.0", "1.0"]}, 'timestamp[0] is a string ("0.0") where MOTION has a number'),
    ({"y_position": [-18.0, True]}, "y_position[1] is true where MOTION has a number"),
    ({"length": "15.5"}, 'length is a string ("15.5") where MOTION has a number'),
    ({"x_position": "123.4"}, 'x_position is a string ("123.4") where MOTION has an array'),
    (
        {"coarse_vehicle_class": 1.6},
        "coarse_vehicle_class is the number 1.6 where MOTION has an integer",
    ),
]


@pytest.mark.parametrize("broken_neighbour", [False, True], ids=["batch", "per-document"])
@pytest.mark.parametrize(
    ("patch", "reason"),
    WRONG_TYPES,
    ids=["quoted-numbers", "boolean", "quoted-scalar", "string-for-array", "fraction-for-integer"],
)
def test_a_value_of_the_wrong_type_is_refused_on_both_read_paths_with_the_same_reason(
    tmp_path: Path, patch: dict[str, object], reason: str, broken_neighbour: bool
) -> None:
    """MOTION writes numbers as JSON numbers. A batch of good documents is read in one go; one
    document no reader can take (a word among the positions) sends the whole batch through the
    per-document reader. A number written as a string, a boolean or a fraction where MOTION has an
    integer must be refused on both paths alike: the batch reader (DuckDB) used to cast them ("1.6"
    silently became vehicle class 2), the per-document reader refused them with Arrow's message,
    which names no field for an integer and calls the document "row 0"."""
    good = document("good", [0.0, 1.0], [0.0, 20.0])
    docs = [good, document("typed", [0.0, 1.0], [0.0, 20.0]) | patch]
    if broken_neighbour:
        docs.append(document("word", [0.0, 1.0], [0.0, 1.0]) | {"x_position": [0.0, "far"]})
    report = import_motion_file(write(tmp_path / "m.json", docs), tmp_path / "s", METRIC_FRAME)
    assert report.documents == 1
    reasons = {bad.index: bad.reason for bad in report.bad}
    assert reasons[1] == reason
    assert len(reasons) == 1 + broken_neighbour
    assert _count(tmp_path / "s", "motion_trajectories") == 1
