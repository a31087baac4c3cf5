"""I-24 MOTION import and Edie fields at scale, each figure beside a baseline from the same run.

    .venv/bin/python -m bench.motion_import [--file F] [--warehouse-points 2000000]

1. The input: a simulated hour of the testbed's section (4 lanes, every vehicle, 25 Hz) written
   in the MOTION format by `smoothfleet motion generate` (sim.motion), made once and kept at
   `--file` (about 33 M points, 0.95 GB).
2. Import: `app.motion.importer` in a child process, into a fresh store: points/s by the wall
   clock and per CPU-second of the child, and the child's peak resident memory.
3. Re-import of the same file: what it added (nothing, checked by counting the store's rows).
4. Edie fields of 1 h x 6 km on 10 s x 200 m boxes (`app.motion.edie.edie_field`): seconds,
   best and median of 5.
Baselines, in the same run:
- ijson (C backend, floats) parsing the file's first 64 MB into documents: points/s, the
  streaming-parser speed the issue suggested;
- reading and hashing the whole file (SHA-256): MB/s, the machine's I/O yardstick.
5. With `--warehouse-points N`: the first N points in PostgreSQL (embedded, a plain table, COPY)
   against Parquet written by pyarrow, and the same Edie GROUP BY in PostgreSQL against DuckDB:
   the measurement behind keeping MOTION beside the warehouse (app/motion/store.py).
The machine's load average is printed at the start and the end: the 2 cores are shared.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

import duckdb
import ijson
import psycopg
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from app.core.db import libpq_url
from app.core.embedded import embedded_server
from app.motion.edie import EdieWindow, edie_field
from app.motion.store import files

REPO = Path(__file__).resolve().parents[1]
DEFAULT_FILE = Path(tempfile.gettempdir()) / "smoothfleet-bench-motion-hour.json"
START = "2022-11-16T13:00:00+00:00"
SECTION_START_M = 6028.0  # the testbed's upstream end on the corridor (smoothfleet.cli.motion)
BASELINE_BYTES = 64 * 1024 * 1024

CHILD_IMPORT = """
import json, resource, sys, time
from pathlib import Path
from app.motion.importer import import_motion_file
wall = time.perf_counter()
report = import_motion_file(Path(sys.argv[1]), Path(sys.argv[2]))
wall = time.perf_counter() - wall
usage = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({
    "documents": report.documents, "points": report.points, "bad": len(report.bad),
    "already": report.already_imported, "wall_s": wall,
    "cpu_s": usage.ru_utime + usage.ru_stime, "max_rss_mb": usage.ru_maxrss / 1024,
}))
"""


def load() -> str:
    return " ".join(f"{value:.1f}" for value in os.getloadavg())


def generate(path: Path) -> None:
    print(f"generating {path} (one hour, 4 lanes; a few minutes) ...", flush=True)
    subprocess.run(
        [
            sys.executable,
            "-m",
            "smoothfleet.cli",
            "motion",
            "generate",
            "-o",
            str(path),
            "--start",
            START,
            "--duration",
            "3600",
        ],
        check=True,
        cwd=REPO,
    )


def child_import(path: Path, store: Path) -> dict[str, float]:
    result = subprocess.run(
        [sys.executable, "-c", CHILD_IMPORT, str(path), str(store)],
        check=True,
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    figures: dict[str, float] = json.loads(result.stdout.strip().splitlines()[-1])
    return figures


def count_rows(store: Path) -> tuple[int, int]:
    with duckdb.connect() as connection:
        points = connection.execute(
            "SELECT count(*) FROM read_parquet(?)", [[str(p) for p in files(store, "points")]]
        ).fetchone()
        trajectories = connection.execute(
            "SELECT count(*) FROM read_parquet(?)",
            [[str(p) for p in files(store, "trajectories")]],
        ).fetchone()
    assert points is not None
    assert trajectories is not None
    return int(points[0]), int(trajectories[0])


def ijson_baseline(path: Path) -> tuple[float, float, int]:
    """ijson over the file's first BASELINE_BYTES: (points/s wall, points/s CPU, points)."""
    points = 0
    wall, cpu = time.perf_counter(), time.process_time()
    with path.open("rb") as stream:
        for document in ijson.items(stream, "item", use_float=True):
            points += len(document["timestamp"])
            if stream.tell() > BASELINE_BYTES:
                break
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return points / wall, points / cpu, points


def hash_baseline(path: Path) -> float:
    digest = hashlib.sha256()
    started = time.perf_counter()
    with path.open("rb") as stream:
        while chunk := stream.read(8 * 1024 * 1024):
            digest.update(chunk)
    return path.stat().st_size / 1e6 / (time.perf_counter() - started)


def edie_timings(store: Path) -> list[float]:
    since = datetime.fromisoformat(START)
    window = EdieWindow(
        since, since + timedelta(hours=1), SECTION_START_M, SECTION_START_M + 6000.0
    )
    timings = []
    for _ in range(5):
        started = time.perf_counter()
        field = edie_field(store, window)
        timings.append(time.perf_counter() - started)
    print(f"  {len(field):,} boxes, {int(field['points'].sum()):,} points in the window")
    return timings


EDIE_SQL = """
SELECT floor(t_s / 10) * 10 AS t_start_s, floor(x_m / 200) * 200 AS x_start_m,
       sum(dt_s) / 2000 AS density, sum(dx_m) / 2000 AS flow,
       sum(fuel_g) / nullif(sum(dx_m), 0) AS psi, count(DISTINCT trajectory_id) AS vehicles
FROM motion_point GROUP BY 1, 2
"""


def warehouse_comparison(store: Path, points: int) -> None:
    table = pq.ParquetFile(files(store, "points")[0]).read_row_groups([0, 1]).slice(0, points)
    rows = table.num_rows
    print(f"\nwarehouse vs Parquet + DuckDB on the first {rows:,} points")
    with tempfile.TemporaryDirectory() as scratch:
        started = time.perf_counter()
        pq.write_table(table, Path(scratch) / "p.parquet")
        parquet_s = time.perf_counter() - started
        buffer = io.BytesIO()
        pa_csv.write_csv(table, buffer, pa_csv.WriteOptions(include_header=False))
        data = buffer.getvalue()
        with (
            embedded_server(Path(scratch) / "pg", delete_on_exit=True) as url,
            psycopg.connect(libpq_url(url), autocommit=True) as connection,
        ):
            connection.execute(
                "CREATE TABLE motion_point (trajectory_id bigint, t_s double precision,"
                " x_m real, lane smallint, speed_mps real, accel_mps2 real, dt_s real,"
                " dx_m real, fuel_g real)"
            )
            started = time.perf_counter()
            with (
                connection.cursor() as cursor,
                cursor.copy("COPY motion_point FROM STDIN (FORMAT csv)") as copy,
            ):
                copy.write(data)
            copy_s = time.perf_counter() - started
            connection.execute("VACUUM ANALYZE motion_point")
            pg_query = []
            for _ in range(3):
                started = time.perf_counter()
                connection.execute(EDIE_SQL).fetchall()
                pg_query.append(time.perf_counter() - started)
        duck_query = []
        with duckdb.connect() as duck:
            duck.execute(
                f"CREATE VIEW motion_point AS SELECT * FROM read_parquet('{scratch}/p.parquet')"
            )
            for _ in range(3):
                started = time.perf_counter()
                duck.execute(EDIE_SQL).fetchall()
                duck_query.append(time.perf_counter() - started)
    print(
        f"  load:  PostgreSQL COPY {rows / copy_s:>12,.0f} points/s"
        f"   Parquet (pyarrow) {rows / parquet_s:>12,.0f} points/s"
    )
    print(
        f"  Edie:  PostgreSQL      {min(pg_query):>8.2f} s (best of 3)"
        f"   DuckDB on Parquet {min(duck_query):>8.2f} s"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--file", type=Path, default=DEFAULT_FILE)
    parser.add_argument("--warehouse-points", type=int, default=0)
    args = parser.parse_args()
    print(f"load average at start: {load()}  ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC)")
    if not args.file.exists():
        generate(args.file)
    size_mb = args.file.stat().st_size / 1e6
    print(f"input: {args.file} ({size_mb:,.0f} MB)")
    with tempfile.TemporaryDirectory() as scratch:
        store = Path(scratch) / "store"
        first = child_import(args.file, store)
        print(
            f"\nimport: {first['documents']:,.0f} trajectories, {first['points']:,.0f} points, "
            f"{first['bad']:.0f} bad"
        )
        wall_rate = first["points"] / first["wall_s"]
        print(
            f"  {wall_rate:>12,.0f} points/s (wall, {first['wall_s']:.1f} s)"
            f"   {first['points'] / first['cpu_s']:>12,.0f} points per CPU-second"
            f"   peak memory {first['max_rss_mb']:,.0f} MB"
        )
        before = count_rows(store)
        again = child_import(args.file, store)
        after = count_rows(store)
        print(
            f"re-import: already imported = {bool(again['already'])}, added "
            f"{after[0] - before[0]} points and {after[1] - before[1]} trajectories "
            f"({again['wall_s']:.1f} s)"
        )
        print("\nEdie fields, 1 h x 6 km, 10 s x 200 m boxes:")
        timings = edie_timings(store)
        print(f"  best {min(timings):.2f} s, median {statistics.median(timings):.2f} s")
        print("\nbaselines (same run):")
        wall_rate, cpu_rate, points = ijson_baseline(args.file)
        print(
            f"  ijson (yajl2_c, floats), first {BASELINE_BYTES >> 20} MB ({points:,} points): "
            f"{wall_rate:,.0f} points/s (wall), {cpu_rate:,.0f} per CPU-second"
        )
        print(f"  read + SHA-256 of the whole file: {hash_baseline(args.file):,.0f} MB/s")
        if args.warehouse_points:
            warehouse_comparison(store, args.warehouse_points)
    print(f"\nload average at the end: {load()}")


if __name__ == "__main__":
    main()
