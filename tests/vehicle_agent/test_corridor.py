"""Map-matching GPS fixes to the corridor, checked on the real I-24 drives."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from app.seed import seed_corridor_document
from vehicle_agent.corridor import CorridorGeometry


@pytest.fixture(scope="module")
def corridor() -> CorridorGeometry:
    document = seed_corridor_document()
    return CorridorGeometry.from_segments(
        "I-24-WB", document["corridor"]["lanes"], document["i24_segments"]
    )


def test_vertices_map_to_their_own_positions(corridor: CorridorGeometry) -> None:
    located = corridor.locate(corridor.lat[1:-1], corridor.lon[1:-1])
    np.testing.assert_allclose(located.x_m, corridor.x_m[1:-1], atol=0.01)
    assert located.offset_m.max() < 0.01
    assert located.on_corridor.all()


def test_position_and_locate_are_inverse(corridor: CorridorGeometry) -> None:
    x = np.linspace(50, corridor.length_m - 50, 500)
    lat, lon = corridor.position(x)
    np.testing.assert_allclose(corridor.locate(lat, lon).x_m, x, atol=0.5)


def test_a_point_beside_the_road_is_off_corridor(corridor: CorridorGeometry) -> None:
    lat, lon = corridor.position(5_000.0)
    heading = np.radians(corridor.heading_deg(5_000.0)[0])
    # 300 m to the right of travel: east/north offset turned 90 degrees from the heading.
    east, north = 300 * np.cos(heading), -300 * np.sin(heading)
    beside_lat = lat + np.degrees(north / 6_371_008.8)
    beside_lon = lon + np.degrees(east / (6_371_008.8 * np.cos(np.radians(lat))))
    located = corridor.locate(beside_lat, beside_lon)
    assert located.offset_m[0] == pytest.approx(300, abs=5)
    assert not located.on_corridor[0]


def test_real_westbound_drive_stays_on_the_corridor_and_moves_forward(
    corridor: CorridorGeometry, shared_dir: Path
) -> None:
    drive = shared_dir / "data/trajectories/2021-03-12-22-20-57_masterArray_0_7509.csv"
    with drive.open() as handle:
        rows = list(csv.DictReader(handle))
    lat = np.array([float(r["LatitudeGPS"]) for r in rows])
    lon = np.array([float(r["LongitudeGPS"]) for r in rows])
    travelled = np.array([float(r["DistanceGPS"]) for r in rows])
    located = corridor.locate(lat, lon)
    inside = located.on_corridor
    assert inside.mean() > 0.95
    # Progress along x matches the distance driven (DistanceGPS counts down westbound here).
    slope = np.polyfit(travelled[inside], located.x_m[inside], 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.01)
