"""Planner speed: one full cycle on the seed corridor (14.6 km x 4 lanes, 158 sub-segments).

    .venv/bin/python -m bench.planner [--repeat 5] [--fleets 100,10000]

(as a module: run as a script, this file would shadow the `planner` package)

A cycle is what the schedule runs every 60 s, in one transaction: read 15 minutes of INRIX,
pool the window's pings per lane and sub-segment, predict, fuse, smooth, find bottlenecks
against the earlier plans, design buffers, and publish plan_run + 632 target rows
(planner.warehouse.run_cycle, committed). The per-vehicle observations of the window
(fact_vehicle_observation) are then written in their own transaction
(store_window_observations), timed separately. Each fleet sends 60 pings per vehicle in the
window: 100 vehicles = 6,000 pings, 10,000 vehicles = 600,000 pings. Goals (issue 4):
<= 200 ms and <= 2 s.

Baselines measured in the same run, on the same embedded PostgreSQL and rows:
- `scan`: `SELECT count(*), avg(speed_mps)` over the window's pings, the least any planner
  reading its pings pays;
- `empty`: the cycle with no pings in the window (INRIX, compute and publish only).
Figures are the median (and min) of --repeat runs after one warm-up.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta

from sqlalchemy import Engine, text
from sqlalchemy.orm import Session

from bench.warehouse import seeded_warehouse
from planner import PlannerParams
from planner.warehouse import CycleOutcome, run_cycle, store_window_observations

CORRIDOR = "I-24-WB"
PINGS_PER_VEHICLE = 60  # one a second over the 60 s window
NOW = datetime.now(UTC).replace(microsecond=0)

ADD_VEHICLES = text(
    """
    INSERT INTO dim_vehicle (vehicle_id, vin, make, model, year, actuation, corridor_id, route,
                             assigned_lane, controller_name)
    SELECT 'BENCH-' || lpad(n::text, 5, '0'), 'BENCHVIN' || lpad(n::text, 9, '0'), 'Nissan',
           'Rogue', 2023, 'acc', :corridor, 'A', 1 + n % 4, 'microaccel_acc'
    FROM generate_series(1, :vehicles) AS n
    ON CONFLICT (vehicle_id) DO NOTHING
    """
)

# Each vehicle drives 60 s from its own start; a slow region at 8.3-9.7 km as in the tests.
ADD_PINGS = text(
    """
    INSERT INTO fact_vehicle_ping (vehicle_id, ts, lat, lon, speed_mps, x_m, lane)
    SELECT 'BENCH-' || lpad(n::text, 5, '0'),
           :now - make_interval(secs => 59 - s),
           36.0, -86.6,
           CASE WHEN position BETWEEN 8300 AND 9700 THEN 6.0 ELSE 29.0 END,
           position,
           CASE WHEN n % 10 = 0 THEN NULL ELSE 1 + n % 4 END
    FROM generate_series(1, :vehicles) AS n,
         generate_series(0, 59) AS s,
         LATERAL (SELECT ((n * 137.7 + s * 25.0)::numeric % 14500)::real AS position) AS p
    """
)


def prepare(engine: Engine, vehicles: int) -> None:
    """The fleet's pings in the window ending NOW (and nothing else in it)."""
    with engine.begin() as connection:
        connection.execute(text("DELETE FROM fact_vehicle_ping"))
        if vehicles:
            connection.execute(ADD_VEHICLES, {"corridor": CORRIDOR, "vehicles": vehicles})
            connection.execute(ADD_PINGS, {"now": NOW, "vehicles": vehicles})
    # What autovacuum does soon after such a load; without it the first cycles plan blind.
    with engine.connect().execution_options(isolation_level="AUTOCOMMIT") as connection:
        connection.execute(text("VACUUM ANALYZE"))


def add_inrix(engine: Engine) -> None:
    """15 INRIX minutes ending 3 minutes before NOW, slow over SF-I24WB-11..14."""
    with engine.begin() as connection:
        connection.execute(
            text(
                "INSERT INTO fact_inrix_estimate (corridor_id, xd_code, measured_at, speed_mps, "
                "received_at) SELECT :corridor, xd_code, :now - make_interval(mins => m), "
                "CASE WHEN seq BETWEEN 10 AND 13 THEN 7.0 ELSE 29.0 END, "
                ":now - make_interval(mins => m) FROM dim_inrix_segment, "
                "generate_series(3, 17) AS m WHERE corridor_id = :corridor"
            ),
            {"corridor": CORRIDOR, "now": NOW},
        )


def timed(action: Callable[[], object], repeat: int) -> list[float]:
    """Wall times (ms) of `repeat` runs after one warm-up."""
    action()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        action()
        times.append((time.perf_counter() - start) * 1000)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--fleets", default="100,10000", help="vehicle counts, comma-separated")
    args = parser.parse_args()
    fleets = [int(count) for count in args.fleets.split(",")]
    params = PlannerParams()

    with seeded_warehouse("bench-planner-") as warehouse:
        engine = warehouse.engine
        add_inrix(engine)

        outcomes: list[CycleOutcome] = []

        def cycle() -> None:
            with Session(engine) as session, session.begin():
                outcome = run_cycle(
                    session,
                    CORRIDOR,
                    algorithm="kernel_smooth_buffer",
                    params=params,
                    valid_for_s=180.0,
                    now=NOW,
                )
            assert outcome.status == "published", outcome.reason
            outcomes.append(outcome)

        def observations() -> None:
            with Session(engine) as session, session.begin():
                store_window_observations(session, outcomes[-1])

        def scan() -> None:
            with engine.connect() as connection:
                connection.execute(
                    text(
                        "SELECT count(*), avg(speed_mps) FROM fact_vehicle_ping "
                        "WHERE ts > :start AND ts <= :end"
                    ),
                    {"start": NOW - timedelta(seconds=60), "end": NOW},
                ).one()

        rows: list[tuple[str, list[float], list[float], list[float]]] = []
        for vehicles in [0, *fleets]:
            prepare(engine, vehicles)
            label = f"{vehicles:,} vehicles ({vehicles * PINGS_PER_VEHICLE:,} pings)"
            rows.append(
                (
                    label,
                    timed(cycle, args.repeat),
                    timed(scan, args.repeat),
                    timed(observations, args.repeat),
                )
            )
        engine.dispose()

    empty_ms = statistics.median(rows[0][1])
    print(f"planner cycle on {CORRIDOR} (158 sub-segments x 4 lanes), {args.repeat} runs each")
    print(
        f"{'fleet':34s} {'cycle ms (to publish)':>22s} {'scan ms':>8s} {'/scan':>6s} "
        f"{'/empty':>7s} {'then observations ms':>21s}"
    )
    for label, cycle_ms, scan_ms, stored_ms in rows:
        median_cycle, median_scan = statistics.median(cycle_ms), statistics.median(scan_ms)
        print(
            f"{label:34s} {median_cycle:9.1f} (min {min(cycle_ms):7.1f}) {median_scan:8.1f} "
            f"{median_cycle / median_scan:5.1f}x {median_cycle / empty_ms:6.1f}x "
            f"{statistics.median(stored_ms):21.1f}"
        )


if __name__ == "__main__":
    main()
