"""Dashboard page render time for a 100-vehicle fleet, against baselines measured in the same run.

    .venv/bin/python -m bench.dashboard [--requests 30] [--minutes 10]

Starts an embedded PostgreSQL in a temporary directory, migrates and seeds it (100 cars), runs
the real app (uvicorn, one worker, planner schedule off), and posts through the API what the
fleet would send in `--minutes` minutes: one ping per car per second, one status per car every
10 s, an INRIX snapshot per minute, and the real planner's plan, which every ping follows. A
logged-in client then times each page `--requests` times (sequentially, after 3 warm-ups).

Baselines, same server and database:
- `GET /healthz`: the HTTP round trip with no database and no template (the floor);
- the fleet snapshot query alone (last ping and last status of every car, the `fleet()` service
  without readiness or HTML), timed in-process with psycopg.

Then what an operator's pages cost the fleet: one batch of pings (one per car, as the cars'
uploads arrive every second) posted `--requests` times, 0.2 s apart, while a second client
fetches a chart page over and over, and with no page fetched (the baseline). The dashboard and
the ingest API share the server's event loop, so whatever a page does on it, every ping waits
for.

With `--profile-fleet N`, last, the fleet view (`app.fleet.service.fleet`, what the piStatus
page and `GET /api/v1/fleet` read) runs N times in this process's own event loop under cProfile,
and the functions that took most of its time are printed, with the time on the event loop's
thread (the profile) against the wall time of the N views.
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import pstats
import re
import statistics
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime, timedelta

import httpx
import psycopg
import uvicorn
from sqlalchemy import text
from sqlalchemy.ext.asyncio import async_sessionmaker

from app.core.config import load_settings
from app.core.db import libpq_url, make_async_engine, make_sync_engine, session_scope
from app.core.security import issue_token
from app.fleet.readiness import Thresholds
from app.fleet.service import fleet
from app.plans.jobs import run_planner
from app.seed import seed_corridor_document
from app.users.service import save_user
from bench.warehouse import seeded_warehouse
from contract.corridor import CorridorGeometry
from smoothfleet.server import create_app

PAGES = (
    "/api/v1/fleet",
    "/fleet",
    "/fleet/live",
    "/vehicles/SF-001",
    "/plans",
    "/feeds",
    "/analytics",
)
PASSWORD = "bench-password-1"
FLEET_SQL = """
SELECT v.vehicle_id, p.ts, s.ts
FROM dim_vehicle v
LEFT JOIN LATERAL (SELECT ts FROM fact_vehicle_ping WHERE vehicle_id = v.vehicle_id
                   AND ts >= now() - interval '2 days' ORDER BY ts DESC LIMIT 1) p ON true
LEFT JOIN LATERAL (SELECT ts FROM fact_vehicle_status WHERE vehicle_id = v.vehicle_id
                   ORDER BY ts DESC LIMIT 1) s ON true
ORDER BY v.vehicle_id
"""


@contextmanager
def serving(url: str) -> Iterator[str]:
    # One operator token loads the whole fleet's data: measure pages, not the rate limiter.
    app = create_app(
        load_settings(database_url=url, planner_enabled=False, rate_limit_per_token_per_s=0)
    )
    server = uvicorn.Server(
        uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning", lifespan="on")
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not server.started:
        time.sleep(0.02)
    port = server.servers[0].sockets[0].getsockname()[1]
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=30)


def load_fleet(client: httpx.Client, token: str, url: str, minutes: int) -> int:
    """Post `minutes` of the fleet's pings, statuses and INRIX snapshots; returns pings sent."""
    document = seed_corridor_document()
    geometry = corridor_geometry()
    headers = {"Authorization": f"Bearer {token}"}
    end = datetime.now(UTC).replace(microsecond=0)
    start = end - timedelta(minutes=minutes)
    seconds = minutes * 60
    codes = [segment["xd_code"] for segment in document["inrix_segments"]]
    for minute in range(minutes):
        measured = start + timedelta(minutes=minute)
        client.post(
            "/api/v1/feeds/inrix",
            json={
                "result": {
                    "segmentspeeds": [
                        {
                            "timestamp": measured.isoformat(),
                            "segments": [
                                {"code": code, "speed": 25.0 if 8 <= i <= 10 else 60.0, "score": 30}
                                for i, code in enumerate(codes)
                            ],
                        }
                    ]
                }
            },
            headers=headers,
        ).raise_for_status()
    outcomes = run_planner(make_sync_engine(url), load_settings(database_url=url))
    plan_id = outcomes[0].plan_id
    sent = 0
    for car in range(1, 101):
        vehicle_id = f"SF-{car:03d}"
        x0 = 100.0 + 130.0 * car
        pings = []
        for second in range(seconds):
            x = (x0 + 25.0 * second) % (geometry.length_m - 200.0) + 100.0
            lat, lon = geometry.position(x)
            pings.append(
                {
                    "vehicle_id": vehicle_id,
                    "ts": (start + timedelta(seconds=second)).isoformat(),
                    "lat": float(lat),
                    "lon": float(lon),
                    "speed_mps": 25.0,
                    "controller_engaged": second % 3 != 0,
                    "acc_engaged": True,
                    "plan_id": plan_id,
                }
            )
        for first in range(0, len(pings), 1000):
            response = client.post(
                "/api/v1/pings", json={"pings": pings[first : first + 1000]}, headers=headers
            )
            response.raise_for_status()
        sent += len(pings)
        for second in range(0, seconds, 10):
            client.post(
                f"/api/v1/vehicles/{vehicle_id}/status",
                json={
                    "ts": (start + timedelta(seconds=second)).isoformat(),
                    "agent_version": "1.0.0",
                    "can_ok": True,
                    "can_msgs_per_s": 1800,
                    "gps_fix": True,
                    "gps_satellites": 10,
                    "acc_available": True,
                    "controller": "microaccel_acc",
                    "controller_running": True,
                    "plan_age_s": 20,
                    "spool_backlog": 0,
                    "disk_free_mb": 9000,
                    "cpu_temp_c": 60,
                    "ups_on_battery": False,
                },
                headers=headers,
            ).raise_for_status()
    return sent


def corridor_geometry() -> CorridorGeometry:
    """The seed corridor, as the server has it."""
    document = seed_corridor_document()
    return CorridorGeometry.from_segments(
        "I-24-WB", document["corridor"]["lanes"], document["i24_segments"]
    )


def ping_batch_while(
    client: httpx.Client, token: str, path: str | None, requests: int
) -> list[float]:
    """Milliseconds to post each of `requests` batches (one ping per car, now), 0.2 s apart,
    while another client with `client`'s login fetches `path` without pause (None: nothing)."""
    geometry = corridor_geometry()
    places = [geometry.position(100.0 + 130.0 * car) for car in range(1, 101)]
    stop = threading.Event()

    def operator() -> None:
        with httpx.Client(
            base_url=str(client.base_url), cookies=client.cookies, timeout=60
        ) as viewer:
            while not stop.is_set():
                viewer.get(path).raise_for_status()  # type: ignore[arg-type]

    viewing = threading.Thread(target=operator, daemon=True) if path else None
    if viewing is not None:
        viewing.start()
        time.sleep(1.0)  # the page's first renders under way
    timings = []
    try:
        for _ in range(requests):
            ts = datetime.now(UTC).isoformat(timespec="milliseconds")
            pings = [
                {
                    "vehicle_id": f"SF-{car:03d}",
                    "ts": ts,
                    "lat": float(lat),
                    "lon": float(lon),
                    "speed_mps": 25.0,
                    "controller_engaged": True,
                }
                for car, (lat, lon) in enumerate(places, start=1)
            ]
            started = time.perf_counter()
            client.post(
                "/api/v1/pings", json={"pings": pings}, headers={"Authorization": f"Bearer {token}"}
            ).raise_for_status()
            timings.append((time.perf_counter() - started) * 1000.0)
            time.sleep(0.2)
    finally:
        stop.set()
        if viewing is not None:
            viewing.join(timeout=60)
    return timings


def profile_fleet(url: str, views: int) -> None:
    """`app.fleet.service.fleet` `views` times on this thread's event loop under cProfile; the
    grading's worker thread is outside the profile, so the profile is what holds the loop."""
    limits = Thresholds.from_settings(load_settings(database_url=url))

    async def run() -> None:
        engine = make_async_engine(url)
        factory = async_sessionmaker(engine, expire_on_commit=False)
        profiler = cProfile.Profile()
        try:
            async with factory() as session, session.begin():
                await fleet(session, datetime.now(UTC), limits)  # warm-up
            started = time.perf_counter()
            for _ in range(views):
                async with factory() as session, session.begin():
                    profiler.enable()
                    await fleet(session, datetime.now(UTC), limits)
                    profiler.disable()
            wall_s = time.perf_counter() - started
        finally:
            await engine.dispose()
        stats = pstats.Stats(profiler)
        profiled_s = stats.total_tt  # type: ignore[attr-defined]
        # the loop waiting in epoll (for the database, or the grading's thread) is idle time
        idle_s = sum(
            timing[2]
            for (_, _, name), timing in stats.stats.items()  # type: ignore[attr-defined]
            if name == "<method 'poll' of 'select.epoll' objects>"
        )
        print(
            f"\nfleet view x {views}: {1000 * wall_s / views:.1f} ms wall a view; on the event "
            f"loop's thread {1000 * (profiled_s - idle_s) / views:.1f} ms busy and "
            f"{1000 * idle_s / views:.1f} ms waiting"
        )
        stats.sort_stats("cumulative").print_stats(25)
        stats.sort_stats("tottime").print_stats(15)

    asyncio.run(run())


def log_in(client: httpx.Client) -> None:
    form = client.get("/login")
    token = re.search(r'name="csrf_token" value="([^"]+)"', form.text)
    assert token is not None
    response = client.post(
        "/login",
        data={"username": "bench", "password": PASSWORD, "csrf_token": token.group(1)},
    )
    assert response.status_code == 303, response.text


def time_requests(client: httpx.Client, path: str, requests: int) -> list[float]:
    for _ in range(3):
        client.get(path).raise_for_status()
    timings = []
    for _ in range(requests):
        started = time.perf_counter()
        response = client.get(path)
        timings.append((time.perf_counter() - started) * 1000.0)
        response.raise_for_status()
    return timings


def time_sql(url: str, requests: int) -> list[float]:
    timings = []
    with psycopg.connect(libpq_url(url)) as connection:
        for round_number in range(requests + 3):
            started = time.perf_counter()
            connection.execute(FLEET_SQL).fetchall()
            if round_number >= 3:
                timings.append((time.perf_counter() - started) * 1000.0)
    return timings


def p95(values: list[float]) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=30)
    parser.add_argument("--minutes", type=int, default=10)
    parser.add_argument(
        "--profile-fleet", type=int, default=0, metavar="N", help="profile N fleet views, last"
    )
    args = parser.parse_args()
    with seeded_warehouse("bench-dashboard-") as warehouse:
        url, engine = warehouse.url, warehouse.engine
        with session_scope(engine) as session:
            save_user(session, "bench", "viewer", PASSWORD)
            token = issue_token(session, "admin", name="bench")
        with serving(url) as base, httpx.Client(base_url=base, timeout=60) as client:
            started = time.perf_counter()
            pings = load_fleet(client, token, url, args.minutes)
            print(f"loaded {pings} pings of 100 cars in {time.perf_counter() - started:.0f} s")
            with engine.connect() as connection:
                counts = connection.execute(
                    text(
                        "SELECT (SELECT count(*) FROM fact_vehicle_ping), "
                        "(SELECT count(*) FROM fact_vehicle_status), "
                        "(SELECT count(*) FROM plan_run WHERE status = 'published')"
                    )
                ).one()
            print(f"database: {counts[0]} pings, {counts[1]} status reports, {counts[2]} plan(s)")
            # Statistics of the fresh ping partition, as autovacuum gathers them within a minute.
            with engine.connect() as connection:
                connection.execute(text("ANALYZE"))
            client.headers["Authorization"] = f"Bearer {token}"
            log_in(client)
            floor = time_requests(client, "/healthz", args.requests)
            sql = time_sql(url, args.requests)
            floor_median = statistics.median(floor)
            print(f"\n{'what':<28}{'median ms':>10}{'p95 ms':>9}{'x /healthz':>12}")
            print(
                f"{'GET /healthz (baseline)':<28}{floor_median:>10.1f}{p95(floor):>9.1f}"
                f"{1.0:>12.1f}"
            )
            print(
                f"{'fleet SQL alone (baseline)':<28}{statistics.median(sql):>10.1f}"
                f"{p95(sql):>9.1f}{statistics.median(sql) / floor_median:>12.1f}"
            )
            for path in PAGES:
                timings = time_requests(client, path, args.requests)
                median = statistics.median(timings)
                print(
                    f"{'GET ' + path:<28}{median:>10.1f}{p95(timings):>9.1f}"
                    f"{median / floor_median:>12.1f}"
                )
            del client.headers["Authorization"]  # the operator's pages go by their login
            print(f"\n{'100 pings posted, while':<40}{'median ms':>10}{'p95 ms':>9}{'max ms':>9}")
            for viewed in (None, "/fleet/live", "/vehicles/SF-001", "/plans", "/feeds"):
                batches = ping_batch_while(client, token, viewed, args.requests)
                label = "no page is viewed (baseline)" if viewed is None else f"GET {viewed} loops"
                print(
                    f"{label:<40}{statistics.median(batches):>10.1f}{p95(batches):>9.1f}"
                    f"{max(batches):>9.1f}"
                )
        if args.profile_fleet:
            profile_fleet(url, args.profile_fleet)


if __name__ == "__main__":
    main()
