"""The grid index behind CorridorGeometry.locate finds the same nearest sub-segment as a
projection of every fix onto every sub-segment, on and off the corridor."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from app.seed import seed_corridor_document
from contract.corridor import EARTH_RADIUS_M, CorridorGeometry


def reference(
    corridor: CorridorGeometry, lat: NDArray[np.float64], lon: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """x_m and offset by brute force: project each fix onto every sub-segment, keep the nearest."""
    lat0, lon0 = corridor.lat.mean(), corridor.lon.mean()
    scale = EARTH_RADIUS_M * math.cos(math.radians(lat0))

    def plane(a: NDArray[np.float64], o: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.column_stack(
            [np.radians(o - lon0) * scale, np.radians(a - lat0) * EARTH_RADIUS_M]
        )

    vertices, points = plane(corridor.lat, corridor.lon), plane(lat, lon)
    x_out, offset_out = np.empty(len(points)), np.empty(len(points))
    for k, point in enumerate(points):
        best = (math.inf, math.nan)
        for i in range(len(vertices) - 1):
            start, step = vertices[i], vertices[i + 1] - vertices[i]
            fraction = min(1.0, max(0.0, float((point - start) @ step / (step @ step))))
            distance = float(np.hypot(*(start + fraction * step - point)))
            if distance < best[0]:
                x = corridor.x_m[i] + fraction * (corridor.x_m[i + 1] - corridor.x_m[i])
                best = (distance, float(x))
        offset_out[k], x_out[k] = best
    return x_out, offset_out


@pytest.fixture(scope="module")
def seed_corridor() -> CorridorGeometry:
    document = seed_corridor_document()
    return CorridorGeometry.from_segments(
        "I-24-WB", document["corridor"]["lanes"], document["i24_segments"]
    )


def test_fixes_near_and_far_match_the_brute_force_projection(
    seed_corridor: CorridorGeometry,
) -> None:
    rng = np.random.default_rng(24)
    x = rng.uniform(-1_000, seed_corridor.length_m + 1_000, 400)
    lat, lon = seed_corridor.position(x)
    # Spread from on the lanes to a few hundred metres off (1e-3 degrees ~ 100 m).
    lat = lat + rng.normal(0, 1e-3, 400) * rng.choice([0.1, 1, 4], 400)
    lon = lon + rng.normal(0, 1e-3, 400) * rng.choice([0.1, 1, 4], 400)

    located = seed_corridor.locate(lat, lon)
    x_expected, offset_expected = reference(seed_corridor, lat, lon)

    np.testing.assert_allclose(located.offset_m, offset_expected, atol=1e-6)
    np.testing.assert_allclose(located.x_m, x_expected, atol=1e-6)
    on = (offset_expected <= seed_corridor.max_offset_m) & (x_expected > 0)
    on &= x_expected < seed_corridor.length_m
    np.testing.assert_array_equal(located.on_corridor, on)
    assert 0.2 < located.on_corridor.mean() < 0.9  # both kinds of fixes were exercised


def test_a_long_winding_corridor_gets_a_coarser_grid_and_the_same_answers() -> None:
    # 400 km of zig-zag: too big for 250 m cells within the index's budget.
    angle = np.linspace(0, 12 * np.pi, 2_001)
    lat = 35.0 + np.linspace(0, 3.0, 2_001)
    lon = -86.0 + 0.05 * np.sin(angle)
    corridor = CorridorGeometry("long", np.linspace(0, 400_000, 2_001), lat, lon, lanes=3)
    rng = np.random.default_rng(7)
    pick = rng.integers(0, 2_000, 60)
    fix_lat = lat[pick] + rng.normal(0, 5e-4, 60)
    fix_lon = lon[pick] + rng.normal(0, 5e-4, 60)

    located = corridor.locate(fix_lat, fix_lon)
    x_expected, offset_expected = reference(corridor, fix_lat, fix_lon)

    np.testing.assert_allclose(located.offset_m, offset_expected, atol=1e-6)
    np.testing.assert_allclose(located.x_m, x_expected, atol=1e-6)


def test_fixes_without_a_position_are_off_the_corridor(seed_corridor: CorridorGeometry) -> None:
    located = seed_corridor.locate([np.nan, 35.98], [-86.57, np.inf])
    assert not located.on_corridor.any()


def test_one_fix_at_a_time_gives_the_vectorised_answer(seed_corridor: CorridorGeometry) -> None:
    rng = np.random.default_rng(11)
    x = rng.uniform(-1_000, seed_corridor.length_m + 1_000, 300)
    lat, lon = seed_corridor.position(x)
    lat = lat + rng.normal(0, 1e-3, 300) * rng.choice([0.1, 1, 4], 300)
    lon = lon + rng.normal(0, 1e-3, 300) * rng.choice([0.1, 1, 4], 300)
    # Headings along, across and against the corridor, and unknown.
    heading = rng.choice([np.nan, 0.0, 90.0, 180.0, 270.0], 300) + rng.uniform(0, 90, 300)
    lat[:3], lon[:3] = [np.nan, 35.98, 0.0], [-86.57, np.inf, 0.0]  # no position, far away

    located = seed_corridor.locate(lat, lon, heading)
    for k in range(len(lat)):
        x_m, offset_m, on = seed_corridor.locate_fix(float(lat[k]), float(lon[k]), heading[k])
        assert on == located.on_corridor[k], k
        if np.isfinite(located.x_m[k]):
            assert x_m == pytest.approx(located.x_m[k], abs=1e-6)
            assert offset_m == pytest.approx(located.offset_m[k], abs=1e-6)
        assert (
            seed_corridor.locate_fix(float(lat[k]), float(lon[k]))[2]
            == (seed_corridor.locate(lat[k], lon[k]).on_corridor[0])
        )
    assert 0.1 < located.on_corridor.mean() < 0.9
