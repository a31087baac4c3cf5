"""Ping ingest throughput and latency, each figure against a baseline measured in the same run.

    .venv/bin/python -m bench.ingest [--duration 8] [--rounds 3] [--workers 2]

Starts an embedded PostgreSQL in a temporary directory, migrates and seeds it, starts the real
server (`smoothfleet serve --no-planner`, group commit) and, beside it on the same database, a
naive FastAPI app doing one INSERT per request (bench/naive_ingest.py), with the same workers.
Then, in alternating slices (so the load of other work on the machine falls on both alike):
1. single-ping POSTs to each: pings/s, p50/p99 latency, and the ratio of the two;
2. batches of 100 pings to the real server, and a raw psycopg COPY of the very rows that slice
   stored (truncated and copied back in one transaction): pings/s and the ratio.
Load comes from wrk (a separate process; `apt-get install -y wrk` on Debian) running a Lua
script that makes every ping unique (100 vehicles, one ping per vehicle per second on the seed
corridor), so every ping is a new row. The table is emptied before every slice.
"""

from __future__ import annotations

import argparse
import io
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import numpy as np
import psycopg

from app.core.db import libpq_url, make_sync_engine, session_scope
from app.core.embedded import database_url, embedded_server, ensure_database
from app.core.security import issue_token
from app.migrate import upgrade
from app.seed import seed
from contract.corridor import CorridorGeometry

REPO = Path(__file__).resolve().parents[1]
VEHICLES = 100

LUA = r"""
-- One ping per vehicle per second: request n of thread t carries vehicle n % 100 + 1 at second
-- floor(n / 100) of the thread's own 4-hour window, so no two pings share (vehicle_id, ts).
local base = tonumber(os.getenv("BENCH_BASE_EPOCH"))
local batch = tonumber(os.getenv("BENCH_BATCH"))
local token = os.getenv("BENCH_TOKEN")
local positions = { __POSITIONS__ }
local threads = 0
local counter = 0

function setup(thread)
  thread:set("thread_number", threads)
  threads = threads + 1
end

function init(args)
  wrk.method = "POST"
  wrk.headers["Content-Type"] = "application/json"
  wrk.headers["Authorization"] = "Bearer " .. token
end

local function ping(n)
  local vehicle = n % 100 + 1
  local second = base + thread_number * 14400 + math.floor(n / 100)
  local where = positions[vehicle]
  return string.format(
    '{"vehicle_id":"SF-%03d","ts":"%s","lat":%.7f,"lon":%.7f,"speed_mps":%.2f,' ..
    '"accel_mps2":0.12,"heading_deg":%.1f,"lane":%d,"acc_engaged":true,' ..
    '"controller_engaged":true,"controller":"microaccel_acc","acc_speed_setting_mph":55,' ..
    '"acc_gap_setting":2,"lead_present":true,"lead_distance_m":35.5,' ..
    '"lead_rel_speed_mps":-0.4,"plan_id":1}',
    vehicle, os.date("!%Y-%m-%dT%H:%M:%SZ", second), where[1], where[2],
    20 + (n % 13), where[3], (vehicle - 1) % 4 + 1)
end

function request()
  local body
  if batch == 0 then
    body = ping(counter)
    counter = counter + 1
  else
    local parts = {}
    for k = 1, batch do
      parts[k] = ping(counter)
      counter = counter + 1
    end
    body = '{"pings":[' .. table.concat(parts, ",") .. ']}'
  end
  return wrk.format(nil, nil, nil, body)
end
"""


@dataclass(frozen=True)
class LoadResult:
    """What wrk measured."""

    requests_per_s: float
    p50_ms: float
    p99_ms: float
    requests: int
    errors: int


def free_port() -> int:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _ms(text: str) -> float:
    value, unit = re.fullmatch(r"([\d.]+)(us|ms|s|m)", text).groups()  # type: ignore[union-attr]
    return float(value) * {"us": 1e-3, "ms": 1.0, "s": 1e3, "m": 6e4}[unit]


def run_wrk(
    base_url: str, script: Path, *, batch: int, token: str, duration_s: int, connections: int
) -> LoadResult:
    env = {
        **os.environ,
        "BENCH_BASE_EPOCH": str(int((datetime.now(UTC) - timedelta(hours=20)).timestamp())),
        "BENCH_BATCH": str(batch),
        "BENCH_TOKEN": token,
    }
    command = [
        "wrk",
        "-t1",
        f"-c{connections}",
        f"-d{duration_s}s",
        "--latency",
        "--timeout",
        "10s",
        "-s",
        str(script),
        f"{base_url}/api/v1/pings",
    ]
    output = subprocess.run(command, env=env, capture_output=True, text=True, check=True).stdout
    rate = float(re.search(r"Requests/sec:\s+([\d.]+)", output).group(1))  # type: ignore[union-attr]
    p50 = _ms(re.search(r"\s50%\s+(\S+)", output).group(1))  # type: ignore[union-attr]
    p99 = _ms(re.search(r"\s99%\s+(\S+)", output).group(1))  # type: ignore[union-attr]
    requests = int(re.search(r"(\d+) requests in", output).group(1))  # type: ignore[union-attr]
    found = re.search(r"Non-2xx or 3xx responses: (\d+)", output)
    socket_errors = re.search(r"Socket errors: (.*)", output)
    errors = int(found.group(1)) if found else 0
    if socket_errors:
        print(f"    wrk: socket errors {socket_errors.group(1)}")
    return LoadResult(rate, p50, p99, requests, errors)


@contextmanager
def server(command: list[str], env: dict[str, str], base_url: str, log: Path) -> Iterator[None]:
    """A server process, ready when its pings endpoint answers; stopped afterwards."""
    with log.open("w") as log_file:
        process = subprocess.Popen(command, env=env, cwd=REPO, stdout=log_file, stderr=log_file)
    try:
        deadline = time.monotonic() + 180
        while True:
            try:
                httpx.post(f"{base_url}/api/v1/pings", json={}, timeout=2)
                break
            except httpx.HTTPError:
                if process.poll() is not None or time.monotonic() > deadline:
                    tail = "\n".join(log.read_text().splitlines()[-5:])
                    raise RuntimeError(f"{command[0]} did not start:\n{tail}") from None
                time.sleep(0.2)
        yield
    finally:
        process.terminate()
        process.wait(timeout=30)


def count_pings(url: str) -> int:
    with psycopg.connect(libpq_url(url)) as connection:
        row = connection.execute("SELECT count(*) FROM fact_vehicle_ping").fetchone()
        return int(row[0]) if row else 0


def truncate(url: str) -> None:
    with psycopg.connect(libpq_url(url)) as connection:
        connection.execute("TRUNCATE fact_vehicle_ping")


def copy_rate(url: str) -> tuple[float, int]:
    """Rows/s of one raw COPY (in one transaction) of the rows stored now."""
    buffer = io.BytesIO()
    with psycopg.connect(libpq_url(url)) as connection:
        with connection.cursor().copy("COPY (SELECT * FROM fact_vehicle_ping) TO STDOUT") as copy:
            for chunk in copy:
                buffer.write(chunk)
        connection.execute("TRUNCATE fact_vehicle_ping")
    data = buffer.getvalue()
    rows = data.count(b"\n")
    with psycopg.connect(libpq_url(url)) as connection:
        started = time.perf_counter()
        with connection.cursor().copy("COPY fact_vehicle_ping FROM STDIN") as copy:
            for offset in range(0, len(data), 1 << 20):
                copy.write(data[offset : offset + (1 << 20)])
        connection.commit()
        elapsed = time.perf_counter() - started
    return rows / elapsed, rows


def corridor_positions(url: str) -> str:
    """A Lua table of (lat, lon, heading) for 100 vehicles spread along the seed corridor."""
    with psycopg.connect(libpq_url(url)) as connection:
        segments = connection.execute(
            "SELECT start_x_m, end_x_m, start_lat, start_lon, end_lat, end_lon "
            "FROM dim_i24_segment ORDER BY seq"
        ).fetchall()
    names = ("start_x_m", "end_x_m", "start_lat", "start_lon", "end_lat", "end_lon")
    geometry = CorridorGeometry.from_segments(
        "I-24-WB", 4, [dict(zip(names, row, strict=True)) for row in segments]
    )
    x = np.linspace(100, geometry.length_m - 100, VEHICLES)
    lat, lon = geometry.position(x)
    heading = geometry.heading_deg(x)
    return ", ".join(
        f"{{{a:.7f}, {o:.7f}, {h:.1f}}}" for a, o, h in zip(lat, lon, heading, strict=True)
    )


def load_conditions() -> str:
    one, five, _ = os.getloadavg()
    return f"{os.cpu_count()} CPUs, load average {one:.2f} (1 min) / {five:.2f} (5 min)"


@dataclass
class Totals:
    """A measurement summed over its rounds."""

    pings: float = 0.0
    seconds: float = 0.0
    p50_ms: list[float] = field(default_factory=list)
    p99_ms: list[float] = field(default_factory=list)
    rows: int = 0
    errors: int = 0

    def add(self, result: LoadResult, pings_per_request: int, seconds: float, rows: int) -> None:
        self.pings += result.requests_per_s * pings_per_request * seconds
        self.seconds += seconds
        self.p50_ms.append(result.p50_ms)
        self.p99_ms.append(result.p99_ms)
        self.rows += rows
        self.errors += result.errors

    @property
    def rate(self) -> float:
        return self.pings / self.seconds

    def latency(self) -> str:
        return f"{statistics.median(self.p50_ms):.1f} | {max(self.p99_ms):.1f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=int, default=8, help="seconds per load slice")
    parser.add_argument("--rounds", type=int, default=3, help="slices per measurement")
    parser.add_argument("--workers", type=int, default=2, help="uvicorn workers per server")
    parser.add_argument("--connections", type=int, default=64, help="wrk connections")
    parser.add_argument("--batch", type=int, default=100, help="pings per batch request")
    args = parser.parse_args()
    if shutil.which("wrk") is None:
        sys.exit("bench/ingest.py needs wrk: apt-get install -y wrk (Debian/Ubuntu)")

    print(f"machine before the run: {load_conditions()}")
    single, baseline, batched = Totals(), Totals(), Totals()
    copy_rows = 0
    copy_seconds = 0.0
    with tempfile.TemporaryDirectory(prefix="sf-bench-ingest-") as scratch:
        scratch_dir = Path(scratch)
        with embedded_server(scratch_dir / "pgdata", delete_on_exit=True) as server_url:
            ensure_database(server_url, "bench")
            url = database_url(server_url, "bench")
            engine = make_sync_engine(url)
            upgrade(engine)
            with session_scope(engine) as session:
                seed(session)
                token = issue_token(session, "operator", name="bench")
            engine.dispose()
            script = scratch_dir / "pings.lua"
            script.write_text(LUA.replace("__POSITIONS__", corridor_positions(url)))
            env = {
                **os.environ,
                "SMOOTHFLEET_DATABASE_URL": url,
                "SMOOTHFLEET_WORKERS": str(args.workers),
                # One operator token carries the whole load: measure ingest, not the limiter.
                "SMOOTHFLEET_RATE_LIMIT_PER_TOKEN_PER_S": "0",
            }
            ours_port, naive_port = free_port(), free_port()
            ours_url, naive_url = (f"http://127.0.0.1:{p}" for p in (ours_port, naive_port))
            ours = [
                str(Path(sys.executable).parent / "smoothfleet"),
                "serve",
                "--no-migrate",
                "--no-planner",
                "--port",
                str(ours_port),
            ]
            naive = [
                sys.executable,
                "-m",
                "uvicorn",
                "bench.naive_ingest:create_app",
                "--factory",
                "--port",
                str(naive_port),
                "--workers",
                str(args.workers),
                "--log-level",
                "warning",
                "--no-access-log",
            ]

            def measure(base: str, batch: int, totals: Totals, seconds: int) -> None:
                truncate(url)
                result = run_wrk(
                    base,
                    script,
                    batch=batch,
                    token=token,
                    duration_s=seconds,
                    connections=args.connections,
                )
                totals.add(result, max(batch, 1), seconds, count_pings(url))

            # Both servers run side by side; the slices alternate so that the load the other
            # engineers put on the shared machine falls on both sides alike.
            with (
                server(ours, env, ours_url, scratch_dir / "serve.log"),
                server(naive, env, naive_url, scratch_dir / "naive.log"),
            ):
                for base in (ours_url, naive_url):  # warm-up
                    measure(base, 0, Totals(), 2)
                for _ in range(args.rounds):
                    measure(ours_url, 0, single, args.duration)
                    measure(naive_url, 0, baseline, args.duration)
                    measure(ours_url, args.batch, batched, args.duration)
                    rate, rows = copy_rate(url)
                    copy_rows += rows
                    copy_seconds += rows / rate
            truncate(url)

    print(f"machine after the run:  {load_conditions()}")
    print(
        f"wrk: 1 thread, {args.connections} connections; {args.rounds} alternating slices of "
        f"{args.duration} s per measurement; {args.workers} uvicorn worker(s) per server"
    )
    print()
    print("| what | pings/s | p50 ms | p99 ms | rows stored | non-2xx | vs baseline |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    print(
        f"| single pings, smoothfleet (group commit) | {single.rate:,.0f} | {single.latency()} | "
        f"{single.rows:,} | {single.errors} | {single.rate / baseline.rate:.2f}x |"
    )
    print(
        f"| single pings, naive one INSERT per request | {baseline.rate:,.0f} | "
        f"{baseline.latency()} | {baseline.rows:,} | {baseline.errors} | 1x |"
    )
    copy_per_s = copy_rows / copy_seconds
    print(
        f"| batches of {args.batch}, smoothfleet | {batched.rate:,.0f} | {batched.latency()} | "
        f"{batched.rows:,} | {batched.errors} | {batched.rate / copy_per_s:.0%} of COPY |"
    )
    print(
        f"| raw psycopg COPY of those rows (one transaction per slice) | {copy_per_s:,.0f} | | "
        f"| {copy_rows:,} | | 100% |"
    )
    print()
    print("p50: median over the slices; p99: the worst slice's.")


if __name__ == "__main__":
    main()
