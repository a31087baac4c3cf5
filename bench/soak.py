"""Soak: the demo's 100-vehicle load on the real server for a set time; memory and latency drift.

    .venv/bin/python -m bench.soak --minutes 30

Starts an embedded PostgreSQL (or uses SMOOTHFLEET_DATABASE_URL), migrates and seeds it, runs
`smoothfleet serve` (API, dashboard, planner schedule) as its own process and the demo's fleet
and INRIX feed against it (`smoothfleet sim fleet`: 100 cars, each the real vehicle agent on a
virtual CAN bus, with its own token). Every `--sample-s` seconds it reads the server's resident
memory (the process and its children) and times a probe: 20 single pings and 5 plan reads.

It prints, per sample, memory and probe latency, then the drift: a least-squares slope per 30
minutes and the last fifth of the run against the first fifth (the baseline measured in the same
run, as a ratio). The goal is no growth trend: memory and latency slopes near zero and ratios
near 1.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import numpy as np
import psutil

from app.core.db import make_sync_engine, session_scope
from app.core.embedded import embedded_postgres
from app.core.security import issue_token
from app.migrate import upgrade
from app.seed import seed, seed_corridor_document
from contract.corridor import CorridorGeometry

PROBE_VEHICLE = "SF-001"
PROBE_PINGS = 20
PROBE_PLAN_READS = 5


@dataclass(frozen=True)
class Sample:
    """One reading of the server under load."""

    minute: float
    rss_mb: float
    ping_ms: float
    plan_ms: float
    cpu_share: float


def smoothfleet() -> str:
    return str(Path(sys.executable).parent / "smoothfleet")


def free_port() -> int:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@contextmanager
def database() -> Iterator[str]:
    """SMOOTHFLEET_DATABASE_URL, or a fresh embedded PostgreSQL for the run."""
    given = os.environ.get("SMOOTHFLEET_DATABASE_URL")
    if given:
        yield given
        return
    with tempfile.TemporaryDirectory(prefix="smoothfleet-soak-") as scratch:
        with embedded_postgres(Path(scratch)) as url:
            yield url


def tree_rss_mb(process: psutil.Process) -> float:
    """Resident memory of a process and its children (uvicorn workers), MB."""
    total = 0
    for member in [process, *process.children(recursive=True)]:
        try:
            total += member.memory_info().rss
        except psutil.NoSuchProcess:
            continue
    return total / 1e6


def tree_cpu_s(process: psutil.Process) -> float:
    total = 0.0
    for member in [process, *process.children(recursive=True)]:
        try:
            times = member.cpu_times()
            total += times.user + times.system
        except psutil.NoSuchProcess:
            continue
    return total


class Probe:
    """Times what a car does: post pings, read its plan."""

    def __init__(self, base: str, token: str) -> None:
        self.http = httpx.Client(
            base_url=base, headers={"Authorization": f"Bearer {token}"}, timeout=30
        )
        document = seed_corridor_document()
        geometry = CorridorGeometry.from_segments(
            "I-24-WB", document["corridor"]["lanes"], document["i24_segments"]
        )
        self.lat, self.lon = (float(v) for v in geometry.position(900.0))
        # A day back, one second per ping: never the fleet's own (vehicle, ts).
        self.next_ts = datetime.now(UTC).replace(microsecond=0) - timedelta(days=1)

    def ping_ms(self) -> float:
        times = []
        for _ in range(PROBE_PINGS):
            self.next_ts += timedelta(seconds=1)
            body = {
                "vehicle_id": PROBE_VEHICLE,
                "ts": self.next_ts.isoformat(),
                "lat": self.lat,
                "lon": self.lon,
                "speed_mps": 25.0,
            }
            began = time.perf_counter()
            answer = self.http.post("/api/v1/pings", json=body)
            times.append(time.perf_counter() - began)
            answer.raise_for_status()
        return 1000 * statistics.median(times)

    def plan_ms(self) -> float:
        times = []
        for _ in range(PROBE_PLAN_READS):
            began = time.perf_counter()
            answer = self.http.get(f"/api/v1/vehicles/{PROBE_VEHICLE}/plan")
            times.append(time.perf_counter() - began)
            if answer.status_code not in (200, 503):
                answer.raise_for_status()
        return 1000 * statistics.median(times)


def slope_per_30_min(minutes: list[float], values: list[float]) -> float:
    """Least-squares trend of the values, per 30 minutes."""
    if len(minutes) < 2:
        return 0.0
    return float(np.polyfit(np.asarray(minutes), np.asarray(values), 1)[0] * 30.0)


def fifth_ratio(values: list[float]) -> float:
    """Mean of the last fifth of the samples over the mean of the first fifth (the baseline)."""
    n = max(1, len(values) // 5)
    return statistics.fmean(values[-n:]) / statistics.fmean(values[:n])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0, help="how long the load runs")
    parser.add_argument("--sample-s", type=float, default=30.0, help="seconds between samples")
    parser.add_argument("--vehicles", type=int, default=100)
    args = parser.parse_args()

    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} (1 min)")
    with database() as url, tempfile.TemporaryDirectory(prefix="smoothfleet-soak-run-") as run:
        engine = make_sync_engine(url)
        upgrade(engine)
        with session_scope(engine) as session:
            seed(session)
            probe_token = issue_token(session, "operator", name="soak probe")
        engine.dispose()
        port = free_port()
        base = f"http://127.0.0.1:{port}"
        env = {
            **os.environ,
            "SMOOTHFLEET_DATABASE_URL": url,
            "SMOOTHFLEET_DATA_DIR": run,
            "SMOOTHFLEET_PORT": str(port),
        }
        with open(Path(run) / "server.log", "wb") as log:
            server = subprocess.Popen(
                [smoothfleet(), "serve", "--no-migrate"],
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        fleet: subprocess.Popen[bytes] | None = None
        try:
            deadline = time.monotonic() + 120
            while True:
                try:
                    if httpx.get(f"{base}/readyz", timeout=2).status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                if time.monotonic() > deadline:
                    raise SystemExit("the server did not become ready")
                time.sleep(0.5)
            with open(Path(run) / "fleet.log", "wb") as log:
                fleet = subprocess.Popen(
                    [
                        smoothfleet(),
                        "sim",
                        "fleet",
                        "--server",
                        base,
                        "--duration",
                        str(args.minutes * 60 + 60),
                        "--vehicles",
                        str(args.vehicles),
                    ],
                    env=env,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                )
            time.sleep(60)  # let the fleet start and the first plans publish
            probe = Probe(base, probe_token)
            process = psutil.Process(server.pid)
            samples: list[Sample] = []
            started = time.monotonic()
            last_cpu, last_time = tree_cpu_s(process), started
            print(
                f"{args.vehicles} vehicles, {args.minutes:.0f} min, a sample every "
                f"{args.sample_s:.0f} s"
            )
            print("| minute | server RSS MB | ping p50 ms | plan read p50 ms | server CPU |")
            print("|---:|---:|---:|---:|---:|")
            while time.monotonic() - started < args.minutes * 60:
                if fleet.poll() is not None:
                    raise SystemExit(f"the fleet stopped early (code {fleet.returncode})")
                ping_ms, plan_ms = probe.ping_ms(), probe.plan_ms()
                now, cpu = time.monotonic(), tree_cpu_s(process)
                sample = Sample(
                    (now - started) / 60,
                    tree_rss_mb(process),
                    ping_ms,
                    plan_ms,
                    (cpu - last_cpu) / max(now - last_time, 1e-9),
                )
                last_cpu, last_time = cpu, now
                samples.append(sample)
                print(
                    f"| {sample.minute:.1f} | {sample.rss_mb:.0f} | {sample.ping_ms:.1f} | "
                    f"{sample.plan_ms:.1f} | {100 * sample.cpu_share:.0f} % |",
                    flush=True,
                )
                time.sleep(max(0.0, args.sample_s - (time.monotonic() - now)))
        finally:
            for child in (fleet, server):
                if child is not None and child.poll() is None:
                    child.terminate()
                    try:
                        child.wait(timeout=120)
                    except subprocess.TimeoutExpired:
                        child.kill()
    minutes = [s.minute for s in samples]
    print()
    print("| drift | slope per 30 min | last fifth / first fifth (baseline) |")
    print("|---|---:|---:|")
    for name, values, unit in (
        ("server RSS", [s.rss_mb for s in samples], "MB"),
        ("ping p50", [s.ping_ms for s in samples], "ms"),
        ("plan read p50", [s.plan_ms for s in samples], "ms"),
    ):
        print(
            f"| {name} | {slope_per_30_min(minutes, values):+.2f} {unit} | "
            f"{fifth_ratio(values):.2f}x |"
        )
    print(f"machine after the run: load average {os.getloadavg()[0]:.2f} (1 min)")


if __name__ == "__main__":
    main()
