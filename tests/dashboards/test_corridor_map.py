"""The corridor map's and the time-space figure's geometry (pure: no server)."""

from __future__ import annotations

import re
from datetime import UTC, datetime
from zoneinfo import ZoneInfo

import numpy as np
import pytest

from dashboards.corridor_map import MapCar, MapSegment, corridor_map, plane_m
from dashboards.figures import Trajectory, local_time_ticks, trajectory_pieces


def test_the_plane_is_metres_east_and_north() -> None:
    # 0.01 degree of latitude is 6371 km * pi / 18000 = 1111.95 m; of longitude at 60 degrees
    # north, half of that.
    points = plane_m(np.array([60.01, 60.0]), np.array([10.0, 10.01]), 60.0, 10.0)
    assert points[0] == pytest.approx([0.0, 1111.95], abs=0.01)
    assert points[1] == pytest.approx([555.97, 0.0], abs=0.01)


def straight_road() -> list[MapSegment]:
    """Two 500 m segments due north; the second is a buffer with 20 m/s in lane 1."""
    return [
        MapSegment(0.0, 500.0, 36.0, -86.0, 36.0045, -86.0, {1: 30.0, 2: 30.0}, False),
        MapSegment(500.0, 1000.0, 36.0045, -86.0, 36.009, -86.0, {1: 20.0, 2: 30.0}, True),
    ]


def test_lanes_take_the_plans_colours_and_buffers_are_shaded() -> None:
    svg = corridor_map("m", straight_road(), 2, [], 75.0)
    lanes = re.findall(r'<line class="lane" data-lane="(\d)"[^>]*stroke="(#\w+)"', svg)
    assert len(lanes) == 4
    assert lanes[0][1] == lanes[2][1]  # lane 1 and 2 at 30 m/s on the first segment
    assert lanes[1][1] != lanes[0][1]  # lane 1 at 20 m/s on the second
    assert svg.count('class="buffer"') == 1
    assert "lane 1: 45 mph" in svg  # 20 m/s


def test_a_road_without_a_plan_is_grey() -> None:
    road = [MapSegment(0.0, 500.0, 36.0, -86.0, 36.0045, -86.0, {}, False)]
    svg = corridor_map("m", road, 1, [], 75.0)
    assert 'stroke="#9ca3af"' in svg
    assert "no plan" in svg


def test_cars_link_to_their_pages_in_their_state_at_their_place() -> None:
    cars = [
        MapCar("SF-001", 250.0, 1, "engaged", 25.0),
        MapCar("SF-002", 750.0, 2, "not reporting", 0.0),
    ]
    svg = corridor_map("m", straight_road(), 2, cars, 75.0)
    found = re.findall(
        r'<a href="/vehicles/([\w-]+)" data-vehicle="[\w-]+" data-state="([\w ]+)">'
        r'<circle cx="([\d.]+)" cy="([\d.]+)"',
        svg,
    )
    assert [(v, s) for v, s, _, _ in found] == [("SF-001", "engaged"), ("SF-002", "not reporting")]
    # North up: the car further along a northbound road is higher on the map (smaller y).
    assert float(found[1][3]) < float(found[0][3])
    # Lane 1 is left of travel: on a northbound road, further west (smaller x).
    assert float(found[0][2]) < float(found[1][2])
    assert "SF-001: engaged, lane 1, 56 mph" in svg


def test_trajectories_break_at_gaps_and_at_a_re_entry() -> None:
    path = Trajectory(
        "SF-001",
        np.array([0.0, 10.0, 20.0, 60.0, 70.0, 80.0]),
        np.array([1.0, 1.1, 1.2, 1.5, 0.1, 0.2]),  # a 40 s gap, then back to the start
        np.array([True, True, False, False, False, True]),
    )
    pieces, engaged = trajectory_pieces(path, max_gap_s=30.0)
    assert pieces[:, 0, 0].tolist() == [0.0, 10.0, 70.0]
    assert engaged.tolist() == [True, True, False]


def test_time_ticks_fall_on_whole_local_minutes() -> None:
    zone = ZoneInfo("America/Chicago")
    start = datetime(2022, 11, 16, 12, 7, 30, tzinfo=UTC).timestamp()  # 06:07:30 CST
    ticks = local_time_ticks(start, start + 3600.0, zone)
    assert list(ticks.values()) == ["06:10", "06:20", "06:30", "06:40", "06:50", "07:00"]
