"""Map-matching GPS fixes to the corridor, checked on the real I-24 drives."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from app.seed import seed_corridor_document
from contract.corridor import CorridorGeometry, trusted_heading


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


def read_drive(path: Path) -> dict[str, np.ndarray]:
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    columns = ("LatitudeGPS", "LongitudeGPS", "DistanceGPS", "Velocity")
    drive = {name: np.array([float(r[name]) for r in rows]) for name in columns}
    drive["heading"] = track_heading(drive["LatitudeGPS"], drive["LongitudeGPS"])
    return drive


def track_heading(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Course over ground from successive fixes, as a receiver reports it (the files' own
    Bearing column is not a compass heading), over 1 s so GPS jitter does not dominate."""
    north = np.radians(lat[10:] - lat[:-10])
    east = np.radians(lon[10:] - lon[:-10]) * np.cos(np.radians(lat[10:]))
    heading = np.degrees(np.arctan2(east, north)) % 360.0
    return np.concatenate([heading, np.full(10, np.nan)])


WESTBOUND = "data/trajectories_with_inrix/2021-03-15-12-46-38_2T3MWRFVXLW056972_masterArray_0_4917"
# The files of data/trajectories/ are labelled westbound, but their GPS runs from the Nashville
# end towards Murfreesboro: they are eastbound on this reference line.
EASTBOUND = "data/trajectories/2021-03-12-22-20-57_masterArray_0_7509.csv"


def test_a_real_westbound_drive_stays_on_the_corridor_and_moves_forward(
    corridor: CorridorGeometry, shared_dir: Path
) -> None:
    drive = read_drive(shared_dir / WESTBOUND / "trajectory.csv")
    heading = trusted_heading(drive["heading"], drive["Velocity"] / 3.6)
    located = corridor.locate(drive["LatitudeGPS"], drive["LongitudeGPS"], heading)
    inside = located.on_corridor
    assert inside.mean() > 0.95
    # x_m grows with the distance driven, metre for metre.
    slope = np.polyfit(drive["DistanceGPS"][inside], located.x_m[inside], 1)[0]
    assert slope == pytest.approx(1.0, abs=0.01)


def test_a_drive_the_other_way_is_off_the_corridor_when_its_heading_is_known(
    corridor: CorridorGeometry, shared_dir: Path
) -> None:
    drive = read_drive(shared_dir / EASTBOUND)
    positions_only = corridor.locate(drive["LatitudeGPS"], drive["LongitudeGPS"])
    assert positions_only.on_corridor.mean() > 0.95  # near enough to the line, by position
    slope = np.polyfit(drive["DistanceGPS"], positions_only.x_m, 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.01)  # ... but travelling against x
    heading = trusted_heading(drive["heading"], drive["Velocity"] / 3.6)
    with_heading = corridor.locate(drive["LatitudeGPS"], drive["LongitudeGPS"], heading)
    moving = (drive["Velocity"] / 3.6 >= 2.0) & np.isfinite(drive["heading"])
    assert moving.mean() > 0.9
    assert with_heading.on_corridor[moving].mean() < 0.01


def test_an_unknown_heading_does_not_take_a_fix_off_the_corridor(
    corridor: CorridorGeometry,
) -> None:
    lat, lon = corridor.position(5_000.0)
    along = float(corridor.heading_deg(5_000.0)[0])
    located = corridor.locate(
        [lat, lat, lat, lat],
        [lon, lon, lon, lon],
        trusted_heading([along + 80, along + 100, along + 180, along + 180], [30, 30, 30, 0.5]),
    )
    assert located.on_corridor.tolist() == [True, False, False, True]
