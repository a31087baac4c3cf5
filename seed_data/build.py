"""Build the project's seed data from the real I-24 reference line.

    python -m seed_data.build [--shared ../shared]

Writes `seed_data/i24_wb_corridor.json` (corridor, INRIX-style segments, fine sub-segments) and
`seed_data/roster.csv` (a 100-car fleet like the paper's). Road coordinates are facts; the
segment codes, VINs and roster are this project's own and visibly marked so:
- the reference line `geo/i24_geo.json` (48 points, westbound position in metres) is resampled
  through a Catmull-Rom (cubic Hermite) spline parameterised by that position, so that x_m on our
  corridor and the position frame of `trajectories_with_inrix/*/segments.json` agree;
- INRIX-style segments take the boundaries of `segments.json` (about 0.5 mi each); real XD codes
  are not public, so ours read `SF-I24WB-NN` (NN = column of the recorded INRIX speed files);
- every INRIX-style segment is cut into equal sub-segments of at most 100 m.

The roster's RL controllers name the policy the agent package ships for them by the sha256 of
its file (`app/seed.py` stores it on the server before it adds the cars).
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
from pathlib import Path

import numpy as np

from contract.controllers import RL_CONTROLLERS
from contract.units import METRES_PER_MILE, MPS_PER_MPH
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

HERE = Path(__file__).parent
CORRIDOR_FILE = HERE / "i24_wb_corridor.json"
ROSTER_FILE = HERE / "roster.csv"

CORRIDOR_ID = "I-24-WB"
LANES = 4
# The corridor runs over the INRIX columns 2..19 of the recorded feed: 14.6 km, the length of
# the paper's I-24 test section; columns 0, 1 and 20 lie outside it (the feed still reports
# them, and ingest counts them as unknown codes).
FIRST_SEGMENT_COLUMN = 2
LAST_SEGMENT_COLUMN = 19
MAX_SUB_SEGMENT_M = 100.0
EARTH_RADIUS_M = 6_371_008.8

ROSTER_SEED = 20221116  # the first day of the paper's reported engagement figures


def segment_code(column: int) -> str:
    """Our stand-in for an INRIX XD code, keyed by the column of the recorded feed files."""
    return f"SF-I24WB-{column:02d}"


def to_plane(lat: np.ndarray, lon: np.ndarray, lat0: float, lon0: float) -> np.ndarray:
    """Equirectangular projection around (lat0, lon0): metres east, north."""
    east = np.radians(lon - lon0) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
    north = np.radians(lat - lat0) * EARTH_RADIUS_M
    return np.column_stack([east, north])


def from_plane(points: np.ndarray, lat0: float, lon0: float) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of to_plane."""
    lat = lat0 + np.degrees(points[:, 1] / EARTH_RADIUS_M)
    lon = lon0 + np.degrees(points[:, 0] / (EARTH_RADIUS_M * math.cos(math.radians(lat0))))
    return lat, lon


def catmull_rom(knots: np.ndarray, points: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Catmull-Rom spline through `points` (at parameters `knots`), evaluated `at`.

    The tangent at an inner knot is the finite difference of its neighbours over their
    parameter span; the ends use one-sided differences. Each span is a cubic Hermite piece.
    """
    tangents = np.empty_like(points)
    tangents[1:-1] = (points[2:] - points[:-2]) / (knots[2:] - knots[:-2])[:, None]
    tangents[0] = (points[1] - points[0]) / (knots[1] - knots[0])
    tangents[-1] = (points[-1] - points[-2]) / (knots[-1] - knots[-2])
    span = np.clip(np.searchsorted(knots, at, side="right") - 1, 0, len(knots) - 2)
    width = knots[span + 1] - knots[span]
    u = ((at - knots[span]) / width)[:, None]
    h00 = 2 * u**3 - 3 * u**2 + 1
    h10 = u**3 - 2 * u**2 + u
    h01 = -2 * u**3 + 3 * u**2
    h11 = u**3 - u**2
    curve: np.ndarray = (
        h00 * points[span]
        + h10 * width[:, None] * tangents[span]
        + h01 * points[span + 1]
        + h11 * width[:, None] * tangents[span + 1]
    )
    return curve


def build_corridor(shared: Path) -> dict[str, object]:
    """The corridor, its INRIX-style segments and its fine sub-segments."""
    geo = json.loads((shared / "data/geo/i24_geo.json").read_text())
    position = np.asarray(geo["position"], dtype=float)
    lat = np.asarray(geo["latitude"], dtype=float)
    lon = np.asarray(geo["longitude"], dtype=float)
    lat0, lon0 = float(lat.mean()), float(lon.mean())
    plane = to_plane(lat, lon, lat0, lon0)

    inrix_dirs = sorted((shared / "data/trajectories_with_inrix").iterdir())
    starts = np.asarray(json.loads((inrix_dirs[0] / "segments.json").read_text()), dtype=float)
    origin = starts[FIRST_SEGMENT_COLUMN]
    end = starts[LAST_SEGMENT_COLUMN + 1]

    def lat_lon_at(geo_position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return from_plane(catmull_rom(position, plane, geo_position), lat0, lon0)

    inrix_segments = []
    sub_segments = []
    sub_id = 0
    for column in range(FIRST_SEGMENT_COLUMN, LAST_SEGMENT_COLUMN + 1):
        seg_start, seg_end = float(starts[column]), float(starts[column + 1])
        (start_lat, end_lat), (start_lon, end_lon) = lat_lon_at(np.array([seg_start, seg_end]))
        inrix_segments.append(
            {
                "xd_code": segment_code(column),
                "seq": column - FIRST_SEGMENT_COLUMN + 1,
                "start_x_m": round(seg_start - origin, 2),
                "end_x_m": round(seg_end - origin, 2),
                "length_m": round(seg_end - seg_start, 2),
                "start_postmile": round((seg_start - origin) / METRES_PER_MILE, 4),
                "end_postmile": round((seg_end - origin) / METRES_PER_MILE, 4),
                "lanes": LANES,
                "start_lat": round(float(start_lat), 7),
                "start_lon": round(float(start_lon), 7),
                "end_lat": round(float(end_lat), 7),
                "end_lon": round(float(end_lon), 7),
            }
        )
        pieces = math.ceil((seg_end - seg_start) / MAX_SUB_SEGMENT_M)
        bounds = np.linspace(seg_start, seg_end, pieces + 1)
        sub_lat, sub_lon = lat_lon_at(bounds)
        for k in range(pieces):
            sub_id += 1
            sub_segments.append(
                {
                    "i24_segment_id": sub_id,
                    "seq": sub_id,
                    "xd_code": segment_code(column),
                    "start_x_m": round(float(bounds[k] - origin), 2),
                    "end_x_m": round(float(bounds[k + 1] - origin), 2),
                    "start_postmile": round(float(bounds[k] - origin) / METRES_PER_MILE, 4),
                    "end_postmile": round(float(bounds[k + 1] - origin) / METRES_PER_MILE, 4),
                    "lanes": LANES,
                    "start_lat": round(float(sub_lat[k]), 7),
                    "start_lon": round(float(sub_lon[k]), 7),
                    "end_lat": round(float(sub_lat[k + 1]), 7),
                    "end_lon": round(float(sub_lon[k + 1]), 7),
                }
            )
    return {
        "source": "resampled from ../shared/data/geo/i24_geo.json (I-24 reference line); "
        "segment boundaries from trajectories_with_inrix/*/segments.json; codes, VINs and "
        "roster are smoothfleet's own",
        "corridor": {
            "corridor_id": CORRIDOR_ID,
            "name": "Interstate 24 westbound, Nashville TN (I-24 MOTION section)",
            "direction": "westbound",
            "lanes": LANES,
            "length_m": round(float(end - origin), 2),
            "speed_limit_mps": round(70 * MPS_PER_MPH, 4),
            "min_target_speed_mps": round(20 * MPS_PER_MPH, 4),
            "postmile_at_start": 0.0,
            "reference_line_origin_m": round(float(origin), 4),
        },
        "inrix_segments": inrix_segments,
        "i24_segments": sub_segments,
    }


VIN_WEIGHTS = (8, 7, 6, 5, 4, 3, 2, 10, 0, 9, 8, 7, 6, 5, 4, 3, 2)
VIN_VALUES = {
    **{str(d): d for d in range(10)},
    **dict(zip("ABCDEFGH", range(1, 9), strict=True)),
    **dict(zip("JKLMN", range(1, 6), strict=True)),
    "P": 7,
    "R": 9,
    **dict(zip("STUVWXYZ", range(2, 10), strict=True)),
}
YEAR_CODES = {2020: "L", 2021: "M", 2022: "N", 2023: "P"}


def vin(prefix8: str, year: int, plant: str, serial: int) -> str:
    """A synthetic VIN with a valid ISO 3779 check digit (serials 9xxxxx mark it as ours)."""
    body = f"{prefix8}0{YEAR_CODES[year]}{plant}9{serial:05d}"
    total = sum(VIN_VALUES[ch] * w for ch, w in zip(body, VIN_WEIGHTS, strict=True))
    check = "X" if total % 11 == 10 else str(total % 11)
    return body[:8] + check + body[9:]


# The controllers follow the simulator's verdict (docs/simulation.md): the acceleration cars run
# the recommended rl_accel (sim/recommended.py); for the ACC-button cars no pair meets the aims,
# and they keep microaccel_acc.
FLEET = (
    # (count, make, model, year(s), actuation, VIN prefix, plant, controller)
    (82, "Nissan", "Rogue", (2023,), "acc", "JN8BT3BB", "W", "microaccel_acc"),
    (15, "Cadillac", "XT5", (2022,), "acc", "1GYKNCRS", "Z", "microaccel_acc"),
    (3, "Toyota", "RAV4", (2020, 2021), "accel", "2T3MWRFV", "W", "rl_accel"),
)
ROSTER_FIELDS = (
    "vehicle_id",
    "vin",
    "make",
    "model",
    "year",
    "actuation",
    "corridor_id",
    "route",
    "assigned_lane",
    "controller_name",
    "controller_params",
)


def controller_params(controller: str) -> str:
    """A roster row's controller params (JSON): an RL controller runs the policy the agent
    package ships for it, named by the sha256 of its file, so every car of the roster runs the
    same, verified file, downloaded from the server."""
    if controller not in RL_CONTROLLERS:
        return "{}"
    policy = BUNDLED_POLICIES / f"{controller}.npz"
    return json.dumps({"policy_sha256": hashlib.sha256(policy.read_bytes()).hexdigest()})


def build_roster() -> list[dict[str, object]]:
    """100 cars: mostly Rogues and XT5s on ACC set points, a few RAV4s on acceleration."""
    rng = np.random.default_rng(ROSTER_SEED)
    rows: list[dict[str, object]] = []
    number = 0
    for count, make, model, years, actuation, prefix, plant, controller in FLEET:
        for k in range(count):
            number += 1
            year = years[k % len(years)]
            # One car in ten runs the hand-designed `simple` controller, as a control group.
            name = "simple" if number % 10 == 0 else controller
            rows.append(
                {
                    "vehicle_id": f"SF-{number:03d}",
                    "vin": vin(prefix, year, plant, int(rng.integers(0, 100_000))),
                    "make": make,
                    "model": model,
                    "year": year,
                    "actuation": actuation,
                    "corridor_id": CORRIDOR_ID,
                    # Two partly overlapping routes, as in the paper's experimental design.
                    "route": "A" if number % 2 else "B",
                    "assigned_lane": 1 + (number - 1) % LANES,
                    "controller_name": name,
                    "controller_params": controller_params(name),
                }
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=HERE.parent.parent / "shared")
    args = parser.parse_args()
    corridor = build_corridor(args.shared)
    CORRIDOR_FILE.write_text(json.dumps(corridor, indent=1) + "\n")
    with ROSTER_FILE.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=ROSTER_FIELDS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(build_roster())
    segments = corridor["inrix_segments"]
    subs = corridor["i24_segments"]
    assert isinstance(segments, list)
    assert isinstance(subs, list)
    print(f"wrote {CORRIDOR_FILE.name}: {len(segments)} INRIX-style segments, {len(subs)} subs")
    print(f"wrote {ROSTER_FILE.name}: 100 vehicles")


if __name__ == "__main__":
    main()
