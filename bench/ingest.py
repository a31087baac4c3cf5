"""Ping ingest against the plainest async FastAPI handler, both measured in the same run.

    .venv/bin/python -m bench.ingest [--duration 8] [--rounds 2] [--workers 2]

Starts an embedded PostgreSQL in a temporary directory, migrates and seeds it, starts the real
server (`smoothfleet serve --no-planner`, group commit) and, beside it on the same database, the
plain handler (bench/naive_ingest.py: one INSERT ... ON CONFLICT DO NOTHING per request through
a psycopg pool, durable commit), with the same workers. Load comes from bench/load.py in this
process. In alternating slices (so the load of other work on the machine falls on both alike):
1. single pings at saturation (closed loop, `--connections` clients back to back);
2. single pings at fixed offered rates (500, 1,000, 2,000 pings/s, constant rate, latency from
   when each request was due: no coordinated omission);
3. batches of 100 and of 1,000 pings to the real server (closed loop), and a raw psycopg COPY
   of the very rows that slice stored (truncated and copied back in one transaction).
Every ping is unique (100 vehicles on the seed corridor, one ping per vehicle per second).
Figures: pings/s, p50, p99, p99.9 and max latency in ms, non-2xx answers.

`--probe-stalls` starts both servers with bench/stall_probe on their PYTHONPATH and prints, per
server, the garbage collections over 2 ms and the event-loop callbacks over 10 ms that happened
while its load ran: what held requests that were otherwise ready.
"""

from __future__ import annotations

import argparse
import gc
import io
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import numpy as np
import psycopg
import uvloop

from app.core.db import libpq_url, session_scope
from app.core.security import issue_token
from bench.load import Body, Latencies, constant_rate, saturate
from bench.warehouse import seeded_warehouse
from contract.corridor import CorridorGeometry

REPO = Path(__file__).resolve().parents[1]
STALL_PROBE = Path(__file__).resolve().parent / "stall_probe"
VEHICLES = 100
SLICE_PINGS = 10**6


def free_port() -> int:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class Pings:
    """Unique ping bodies: 100 vehicles along the corridor, one ping per vehicle per second."""

    def __init__(self, positions: list[tuple[float, float, float]]) -> None:
        self._where = [  # each vehicle's place, formatted once
            f'"lat":{lat:.7f},"lon":{lon:.7f},"heading_deg":{heading:.1f},'
            for lat, lon, heading in positions
        ]
        # 30 days back, and each slice 10^6 pings (10^4 s) further: inside the retention
        # window, never in the future, every (vehicle_id, ts) new.
        self.base = int((datetime.now(UTC) - timedelta(days=30)).timestamp())
        self.used = 0  # pings handed out so far, so every slice's pings are new rows
        self._second = -1
        self._ts = ""

    def _one(self, n: int) -> str:
        vehicle = n % VEHICLES
        second = self.base + n // VEHICLES
        if second != self._second:  # 100 pings share each second: format it once
            self._second = second
            self._ts = datetime.fromtimestamp(second, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
        return (
            f'{{"vehicle_id":"SF-{vehicle + 1:03d}","ts":"{self._ts}",{self._where[vehicle]}'
            '"speed_mps":24.5,"accel_mps2":0.12,"lane":2,"acc_engaged":true,"controller_engaged":true,"controller":"microaccel_acc",'
            '"acc_speed_setting_mph":55,"acc_gap_setting":2,"lead_present":true,'
            '"lead_distance_m":35.5,"lead_rel_speed_mps":-0.4,"plan_id":1}'
        )

    def single(self) -> Body:
        start = self.used
        self.used += SLICE_PINGS

        def body(i: int) -> bytes:
            return self._one(start + i).encode()

        return body

    def batches(self, size: int) -> Body:
        start = self.used
        self.used += SLICE_PINGS

        def body(i: int) -> bytes:
            first = start + i * size
            return (
                '{"pings":[' + ",".join(self._one(first + k) for k in range(size)) + "]}"
            ).encode()

        return body


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


def corridor_positions(url: str) -> list[tuple[float, float, float]]:
    """(lat, lon, heading) of 100 vehicles spread along the seed corridor."""
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
    return [(float(a), float(o), float(h)) for a, o, h in zip(lat, lon, heading, strict=True)]


def stalls_during(prefix: Path, windows: list[tuple[float, float]]) -> str:
    """A summary of the stall probe's notes (bench/stall_probe) that fall in the windows."""
    kinds: dict[str, list[float]] = {}
    callbacks: dict[str, list[float]] = {}
    for path in prefix.parent.glob(prefix.name + ".*"):
        for line in path.read_text().splitlines():
            stamp, what, held_ms = line.split("\t")
            if not any(start <= float(stamp) <= end for start, end in windows):
                continue
            kind = what if what.startswith("gc") else "callback > 10 ms"
            kinds.setdefault(kind, []).append(float(held_ms))
            if not what.startswith("gc"):
                callbacks.setdefault(what.removeprefix("callback "), []).append(float(held_ms))
    seconds = sum(end - start for start, end in windows)
    lines = [f"  over {seconds:.0f} s of load:"]
    for kind, held in sorted(kinds.items()):
        lines.append(
            f"  {kind:<18} {len(held):5d} times, {sum(held):8.1f} ms in all, "
            f"longest {max(held):6.1f} ms"
        )
    for what, held in sorted(callbacks.items(), key=lambda item: -sum(item[1]))[:3]:
        lines.append(f"    {len(held):4d} x {max(held):6.1f} ms max  {what}")
    if not kinds:
        lines.append("  none noted")
    return "\n".join(lines)


def load_conditions() -> str:
    one, five, _ = os.getloadavg()
    return f"{os.cpu_count()} CPUs, load average {one:.2f} (1 min) / {five:.2f} (5 min)"


@dataclass
class Totals:
    """A measurement over its slices: every latency, answered pings, rows, errors."""

    latencies: list[np.ndarray] = field(default_factory=list)
    pings: float = 0.0
    seconds: float = 0.0
    rows: int = 0
    errors: int = 0

    def add(self, result: Latencies, pings_per_request: int, rows: int) -> None:
        self.latencies.append(result.seconds)
        self.pings += len(result.seconds) * pings_per_request
        self.seconds += result.duration_s
        self.rows += rows
        self.errors += result.non_2xx

    @property
    def rate(self) -> float:
        return self.pings / self.seconds if self.seconds else 0.0

    def row(self, what: str, extra: str = "") -> str:
        every = np.concatenate(self.latencies) * 1000 if self.latencies else np.zeros(1)
        p50, p99, p999 = np.percentile(every, [50, 99, 99.9])
        return (
            f"| {what} | {self.rate:,.0f} | {p50:.1f} | {p99:.1f} | {p999:.1f} | "
            f"{every.max():.1f} | {self.rows:,} | {self.errors} | {extra} |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=int, default=8, help="seconds per load slice")
    parser.add_argument("--rounds", type=int, default=2, help="slices per measurement")
    parser.add_argument("--workers", type=int, default=2, help="uvicorn workers per server")
    parser.add_argument("--connections", type=int, default=32, help="clients at saturation")
    parser.add_argument(
        "--rates", default="500,1000,2000", help="offered single-ping rates, pings/s"
    )
    parser.add_argument(
        "--probe-stalls", action="store_true", help="note long GCs and loop callbacks"
    )
    args = parser.parse_args()
    rates = [int(rate) for rate in args.rates.split(",")]

    print(f"machine before the run: {load_conditions()}")
    saturated = {"ours": Totals(), "plain": Totals()}
    offered = {(side, rate): Totals() for side in ("ours", "plain") for rate in rates}
    batched = {size: Totals() for size in (100, 1000)}
    copy_rows = dict.fromkeys(batched, 0)
    copy_seconds = dict.fromkeys(batched, 0.0)
    with seeded_warehouse("sf-bench-ingest-") as warehouse:
        scratch_dir, url = warehouse.scratch, warehouse.url
        with session_scope(warehouse.engine) as session:
            token = issue_token(session, "operator", name="bench")
        warehouse.engine.dispose()  # the servers measured hold the database's connections
        pings = Pings(corridor_positions(url))
        env = {
            **os.environ,
            "SMOOTHFLEET_DATABASE_URL": url,
            "SMOOTHFLEET_WORKERS": str(args.workers),
            # One operator token carries the whole load: measure ingest, not the limiter.
            "SMOOTHFLEET_RATE_LIMIT_PER_TOKEN_PER_S": "0",
        }
        envs = {side: dict(env) for side in ("ours", "plain")}
        if args.probe_stalls:
            for side, side_env in envs.items():
                side_env["PYTHONPATH"] = os.pathsep.join(
                    [str(STALL_PROBE), str(REPO), side_env.get("PYTHONPATH", "")]
                )
                side_env["SMOOTHFLEET_STALL_LOG"] = str(scratch_dir / f"stalls-{side}")
        loaded: dict[str, list[tuple[float, float]]] = {"ours": [], "plain": []}
        ours_port, plain_port = free_port(), free_port()
        bases = {
            "ours": f"http://127.0.0.1:{ours_port}",
            "plain": f"http://127.0.0.1:{plain_port}",
        }
        ours = [
            str(Path(sys.executable).parent / "smoothfleet"),
            "serve",
            "--no-migrate",
            "--no-planner",
            "--port",
            str(ours_port),
        ]
        plain = [
            sys.executable,
            "-m",
            "uvicorn",
            "bench.naive_ingest:create_app",
            "--factory",
            "--port",
            str(plain_port),
            "--workers",
            str(args.workers),
            "--log-level",
            "warning",
            "--no-access-log",
        ]

        def run(load: object, side: str = "ours") -> Latencies:
            truncate(url)
            # The generator's own garbage collections would delay requests past their due
            # time and count as the server's latency: none while the load runs. Its loop is
            # uvloop, as the servers' is: the generator shares their two cores, so the less
            # it spends a request, the less it weighs on what is measured.
            gc.collect()
            gc.disable()
            started = time.time()
            try:
                result: Latencies = uvloop.run(load)  # type: ignore[arg-type]
            finally:
                gc.enable()
            loaded[side].append((started, time.time()))
            return result

        with (
            server(ours, envs["ours"], bases["ours"], scratch_dir / "serve.log"),
            server(plain, envs["plain"], bases["plain"], scratch_dir / "plain.log"),
        ):
            for base in bases.values():  # warm-up
                uvloop.run(
                    saturate(
                        f"{base}/api/v1/pings",
                        token,
                        pings.single(),
                        connections=8,
                        duration_s=2,
                    )
                )
                truncate(url)
            for _ in range(args.rounds):
                for side, base in bases.items():
                    result = run(
                        saturate(
                            f"{base}/api/v1/pings",
                            token,
                            pings.single(),
                            connections=args.connections,
                            duration_s=args.duration,
                        ),
                        side,
                    )
                    saturated[side].add(result, 1, count_pings(url))
                for rate in rates:
                    for side, base in bases.items():
                        result = run(
                            constant_rate(
                                f"{base}/api/v1/pings",
                                token,
                                pings.single(),
                                rate=rate,
                                duration_s=args.duration,
                            ),
                            side,
                        )
                        offered[side, rate].add(result, 1, count_pings(url))
                for size in batched:
                    result = run(
                        saturate(
                            f"{bases['ours']}/api/v1/pings",
                            token,
                            pings.batches(size),
                            connections=4,
                            duration_s=args.duration,
                        )
                    )
                    batched[size].add(result, size, count_pings(url))
                    copied_per_s, rows = copy_rate(url)
                    copy_rows[size] += rows
                    copy_seconds[size] += rows / copied_per_s
        truncate(url)
        stalls = {
            side: stalls_during(scratch_dir / f"stalls-{side}", windows)
            for side, windows in loaded.items()
            if args.probe_stalls
        }

    print(f"machine after the run:  {load_conditions()}")
    print(
        f"{args.rounds} alternating slices of {args.duration} s per measurement; "
        f"{args.workers} uvicorn worker(s) per server; saturation: {args.connections} clients"
    )
    print()
    print("| what | pings/s | p50 ms | p99 ms | p99.9 ms | max ms | rows stored | non-2xx | |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|")
    ratio = saturated["ours"].rate / saturated["plain"].rate
    print(saturated["ours"].row("saturation, smoothfleet", f"{ratio:.2f}x the plain handler"))
    print(saturated["plain"].row("saturation, plain handler"))
    for rate in rates:
        for side, name in (("ours", "smoothfleet"), ("plain", "plain handler")):
            print(offered[side, rate].row(f"{rate:,} pings/s offered, {name}"))
    for size, totals in batched.items():
        rows, seconds = copy_rows[size], copy_seconds[size]
        copy_per_s = rows / seconds if seconds else 0.0
        print(
            totals.row(
                f"batches of {size:,}, smoothfleet", f"{totals.rate / copy_per_s:.0%} of COPY"
            )
        )
        print(f"| raw COPY of those rows | {copy_per_s:,.0f} | | | | | {rows:,} | | 100% |")
    print()
    print("Latency: every request of every slice; at offered rates from when it was due.")
    for side, notes in stalls.items():
        print()
        print(f"stalls in the {'smoothfleet' if side == 'ours' else 'plain'} server's processes:")
        print(notes)


if __name__ == "__main__":
    main()
