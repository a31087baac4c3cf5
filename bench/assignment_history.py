"""The fleet directory's corridor-history query against years of assignment changes.

    .venv/bin/python -m bench.assignment_history [--repeat 20] [--histories 1x365,4x1095]

Every ingest process reloads its fleet directory once per `roster_cache_ttl_s` (30 s by
default); the reload reads, for every vehicle, the corridors it was assigned whose span ended
within the ping retention window (90 days and a day's margin:
`app.ingest.directory.CORRIDOR_ENDS_SQL`). `dim_vehicle_assignment` keeps every change for
good, and no index serves `valid_to > :since`, so the query reads the whole history. This
measures what that costs as the history grows, and what an index on `valid_to` would save.

Each history is `C`x`D`: the seed roster's 100 cars, each reassigned C times a day for D days
(every tenth change to another corridor and back at the next, the others to another lane), the
open row last, on the car's own corridor.
Measured in the same run, on the same embedded PostgreSQL and rows:
- `as shipped`: the query as the reload runs it, on the table's own indexes;
- `scan floor`: `SELECT count(*)` over the table, what any query reading every row pays;
- `with index`: the query again after `CREATE INDEX ... (valid_to)` and ANALYZE (dropped after).
Figures are the median (and min) of --repeat runs after one warm-up.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta

from sqlalchemy import Engine, text

from app.ingest.directory import CORRIDOR_ENDS_SQL, HISTORY_MARGIN
from bench.warehouse import seeded_warehouse

RETENTION = timedelta(days=90)  # Settings.ping_retention_days' default
SECOND_CORRIDOR = "BENCH-EB"
NOW = datetime.now(UTC).replace(microsecond=0)

# The history of every seeded car, rebuilt: change n (0-based) of N starts at
# now - (N - n) * period; the last one is the open row (valid_to = infinity). The rows are
# written directly, as the trigger of migration 0012 would have written them over the years.
REBUILD_HISTORY = text(
    """
    WITH changes AS (
        SELECT v.vehicle_id, v.route, n,
               CASE WHEN n % 10 = 9 AND n < :changes - 1 THEN :second
                    ELSE v.corridor_id END AS corridor_id,
               1 + (n + length(v.vehicle_id)) % 4 AS assigned_lane,
               :now - (:changes - n) * :period AS valid_from
        FROM dim_vehicle v, generate_series(0, :changes - 1) AS n
    )
    INSERT INTO dim_vehicle_assignment
        (vehicle_id, valid_from, valid_to, corridor_id, route, assigned_lane)
    SELECT vehicle_id,
           CASE WHEN n = 0 THEN '-infinity'::timestamptz ELSE valid_from END,
           CASE WHEN n = :changes - 1 THEN 'infinity'::timestamptz
                ELSE valid_from + :period END,
           corridor_id, route, assigned_lane
    FROM changes
    """
)


def build_history(engine: Engine, per_day: int, days: int) -> int:
    """Replace every car's assignment history with `per_day` changes a day over `days` days;
    the number of rows."""
    changes = per_day * days
    with engine.begin() as connection:
        connection.execute(
            text(
                "INSERT INTO dim_corridor (corridor_id, name, direction, lanes, length_m, "
                "speed_limit_mps, min_target_speed_mps) SELECT :second, 'bench corridor', 'EB', "
                "lanes, length_m, speed_limit_mps, min_target_speed_mps FROM dim_corridor "
                "LIMIT 1 ON CONFLICT DO NOTHING"
            ),
            {"second": SECOND_CORRIDOR},
        )
        connection.execute(text("DELETE FROM dim_vehicle_assignment"))
        connection.execute(
            REBUILD_HISTORY,
            {
                "second": SECOND_CORRIDOR,
                "now": NOW,
                "changes": changes,
                "period": timedelta(days=1) / per_day,
            },
        )
        connection.execute(text("ANALYZE dim_vehicle_assignment"))
        rows = connection.execute(text("SELECT count(*) FROM dim_vehicle_assignment")).scalar_one()
    return int(rows)


def timed(step: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Median and min wall time of `repeat` runs (s), after one warm-up."""
    step()
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        step()
        times.append(time.perf_counter() - started)
    return statistics.median(times), min(times)


def measure(engine: Engine, repeat: int) -> dict[str, tuple[float, float]]:
    """The three figures of the module docstring, on the history in place now."""
    since = NOW - RETENTION - HISTORY_MARGIN
    ends: list[int] = []

    def reload_query() -> None:
        with engine.connect() as connection:
            ends.append(len(connection.execute(CORRIDOR_ENDS_SQL, {"since": since}).all()))

    def scan_floor() -> None:
        with engine.connect() as connection:
            connection.execute(text("SELECT count(*) FROM dim_vehicle_assignment")).scalar_one()

    figures = {"as shipped": timed(reload_query, repeat), "scan floor": timed(scan_floor, repeat)}
    with engine.begin() as connection:
        connection.execute(
            text("CREATE INDEX bench_assignment_valid_to ON dim_vehicle_assignment (valid_to)")
        )
        connection.execute(text("ANALYZE dim_vehicle_assignment"))
    shipped_ends = ends[-1]
    figures["with index"] = timed(reload_query, repeat)
    assert ends[-1] == shipped_ends, "the index changed the query's answer"
    with engine.begin() as connection:
        connection.execute(text("DROP INDEX bench_assignment_valid_to"))
    print(f"    corridor ends in the window: {shipped_ends}")
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument(
        "--histories",
        default="1x365,4x1095",
        help="changes a day x days, comma-separated (e.g. 1x365: once a day for a year)",
    )
    args = parser.parse_args()
    histories = [tuple(int(part) for part in item.split("x")) for item in args.histories.split(",")]

    with seeded_warehouse("bench-assignment-") as warehouse:
        for per_day, days in histories:
            rows = build_history(warehouse.engine, per_day, days)
            print(f"history {per_day} change(s) a day x {days} days: {rows:,} rows")
            for name, (median, least) in measure(warehouse.engine, args.repeat).items():
                print(f"    {name:<11} median {median * 1000:7.2f} ms  (min {least * 1000:.2f})")


if __name__ == "__main__":
    main()
