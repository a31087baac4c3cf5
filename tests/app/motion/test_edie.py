"""Edie's fields of MOTION points against boxes worked by hand (paper, "Results")."""

from __future__ import annotations

import math
from datetime import UTC, datetime
from pathlib import Path

import pytest

from app.motion.edie import EdieWindow, EdieWindowError, day_window, edie_field
from app.motion.importer import import_motion_file
from app.motion.store import connect
from tests.app.motion.conftest import METRIC_FRAME, document, write

T0 = 1_668_600_000.0  # 2022-11-16 12:00:00 UTC, a multiple of 10 s
SINCE = datetime(2022, 11, 16, 12, 0, tzinfo=UTC)
UNTIL = datetime(2022, 11, 16, 12, 0, 10, tzinfo=UTC)
# RAV4 fuel rate at steady speed: c0 + c1 v + c3 v^3 (sim/energy.py).
F20 = 0.14631964767035743 + 0.012179045946260292 * 20 + 2.7432588728174234e-05 * 20**3
F10 = 0.14631964767035743 + 0.012179045946260292 * 10 + 2.7432588728174234e-05 * 10**3


@pytest.fixture
def store(tmp_path: Path) -> Path:
    # Car A, lane 1: 6 points 1 s apart at 20 m/s from x = 0: 5 s and 100 m in the box.
    # Car B, lane 2: 10 points 1 s apart at 10 m/s from x = 50: 9 s and 90 m in the box.
    # Car C, lane 1: in the next box along the road (200-400 m), 2 s at 5 m/s.
    a = document("a", [T0 + k for k in range(6)], [20.0 * k for k in range(6)], lane=1)
    b = document("b", [T0 + k for k in range(10)], [50 + 10.0 * k for k in range(10)], lane=2)
    c = document("c", [T0, T0 + 1, T0 + 2], [250.0, 255.0, 260.0], lane=1)
    target = tmp_path / "store"
    import_motion_file(write(tmp_path / "m.json", [a, b, c]), target, METRIC_FRAME)
    return target


def test_one_box_worked_by_hand(store: Path) -> None:
    field = edie_field(store, EdieWindow(SINCE, UNTIL, 0.0, 200.0))
    assert len(field) == 1
    box = field.iloc[0]
    assert (box["t_start_s"], box["x_start_m"]) == (T0, 0.0)
    assert (box["vehicles"], box["points"]) == (2, 16)
    assert box["time_s"] == pytest.approx(14.0)  # 5 + 9 vehicle-seconds
    assert box["distance_m"] == pytest.approx(190.0)  # 100 + 90 m
    fuel = 5 * F20 + 9 * F10  # 5 x 0.60936 + 9 x 0.29554 = 5.7067 g
    assert box["fuel_g"] == pytest.approx(fuel, rel=1e-6)
    area = 10.0 * 200.0
    assert box["density_veh_per_m"] == pytest.approx(14.0 / area)  # rho = 0.007 veh/m
    assert box["flow_veh_per_s"] == pytest.approx(190.0 / area)  # q = 0.095 veh/s
    assert box["fuel_rate_density_g_per_s_m"] == pytest.approx(fuel / area, rel=1e-6)
    assert box["speed_mps"] == pytest.approx(190.0 / 14.0)  # u = q / rho = 13.57 m/s
    assert box["fuel_rate_per_vehicle_g_per_s"] == pytest.approx(fuel / 14.0, rel=1e-6)
    assert box["fuel_per_distance_g_per_m"] == pytest.approx(fuel / 190.0, rel=1e-6)


def test_one_lane(store: Path) -> None:
    field = edie_field(store, EdieWindow(SINCE, UNTIL, 0.0, 400.0, lane=1))
    assert field["x_start_m"].tolist() == [0.0, 200.0]
    first, second = field.iloc[0], field.iloc[1]
    assert (first["vehicles"], first["speed_mps"]) == (1, pytest.approx(20.0))
    assert first["fuel_per_distance_g_per_m"] == pytest.approx(F20 / 20.0, rel=1e-6)
    assert (second["time_s"], second["distance_m"]) == (pytest.approx(2.0), pytest.approx(10.0))


def test_bigger_boxes_and_a_window_widened_to_whole_boxes(store: Path) -> None:
    # One 20 s x 400 m box holds all three cars: 16 s and 200 m.
    field = edie_field(store, EdieWindow(SINCE, UNTIL, 10.0, 390.0, h_t_s=20.0, h_x_m=400.0))
    assert len(field) == 1
    assert field.iloc[0]["time_s"] == pytest.approx(16.0)
    assert field.iloc[0]["distance_m"] == pytest.approx(200.0)
    assert field.iloc[0]["density_veh_per_m"] == pytest.approx(16.0 / 8000.0)


def test_a_window_with_nothing_in_it_has_no_boxes(store: Path) -> None:
    later = datetime(2022, 11, 17, tzinfo=UTC)
    assert edie_field(store, EdieWindow(later, later.replace(hour=1), 0, 200)).empty


def test_an_empty_store_has_no_boxes(tmp_path: Path) -> None:
    assert edie_field(tmp_path, EdieWindow(SINCE, UNTIL, 0, 200)).empty


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"until": SINCE}, "must be after since"),
        ({"x_to_m": 0.0}, "must be beyond x_from_m"),
        ({"h_t_s": 0.0}, "box size must be positive"),
        ({"lane": 0}, "lanes are numbered from 1"),
        ({"since": datetime(2022, 11, 16)}, "has no time zone"),
    ],
)
def test_windows_that_cannot_make_a_field_say_why(changes: dict[str, object], message: str) -> None:
    arguments: dict[str, object] = {
        "since": SINCE,
        "until": UNTIL,
        "x_from_m": 0.0,
        "x_to_m": 200.0,
        **changes,
    }
    with pytest.raises(EdieWindowError, match=message):
        EdieWindow(**arguments)  # type: ignore[arg-type]


def test_boxes_that_are_not_whole_cells_are_summed_from_the_points(store: Path) -> None:
    # 5 s x 100 m at [T0, T0 + 5) x [0, 100): A's points 0-4 (5 s, 100 m) and B's points 0-4
    # (50-90 m: 5 s, 50 m).
    window = EdieWindow(SINCE, SINCE.replace(second=5), 0.0, 100.0, h_t_s=5.0, h_x_m=100.0)
    assert not window.whole_cells
    box = edie_field(store, window).iloc[0]
    assert (box["time_s"], box["distance_m"]) == (pytest.approx(10.0), pytest.approx(150.0))
    assert box["density_veh_per_m"] == pytest.approx(10.0 / 500.0)
    assert box["speed_mps"] == pytest.approx(15.0)
    assert box["fuel_g"] == pytest.approx(5 * F20 + 5 * F10, rel=1e-6)


def test_cells_and_points_give_the_same_field(store: Path) -> None:
    window = EdieWindow(SINCE, UNTIL, 0.0, 400.0, h_t_s=20.0, h_x_m=400.0)
    assert window.whole_cells
    with connect(store) as connection:
        by_points, by_cells = (
            connection.execute(
                f"SELECT * FROM {macro}(?, ?, 0, 400, h_t_s := 20, h_x_m := 400)",
                [T0, T0 + 20],
            ).fetchall()
            for macro in ("motion_edie", "motion_edie_cells")
        )
    assert len(by_points) == len(by_cells) == 1
    # float32 point columns against float64 cell sums: equal to single precision.
    assert list(by_points[0]) == pytest.approx(list(by_cells[0]), rel=1e-6)


def test_a_day_of_one_point_fragments_still_has_a_window(tmp_path: Path) -> None:
    """The importer takes a one-point document; a day holding only such fragments spans no
    time, and its window raised EdieWindowError: a 500 on the MOTION page, a traceback in
    `smoothfleet motion plot`."""
    target = tmp_path / "store"
    import_motion_file(
        write(tmp_path / "m.json", [document("a", [T0], [100.0])]), target, METRIC_FRAME
    )

    window = day_window(target, SINCE.date())

    assert (window.since, window.until) == (SINCE, UNTIL)
    assert window.x_to_m - window.x_from_m == 200.0
    (box,) = edie_field(target, window).itertuples()
    # a point drives no distance in no time: no density, no flow, no speed to read
    assert (box.vehicles, box.time_s, box.distance_m, box.density_veh_per_m) == (1, 0, 0, 0)
    assert math.isnan(box.speed_mps)
