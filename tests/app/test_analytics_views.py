"""The analytics views against hand-worked values (paper: Results, energy model sidebar).

Each test posts a small drive through the real ingest API (pings, status, INRIX feed) and
checks the view's figures against numbers worked by hand in the comments.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Iterator
from datetime import UTC, date, datetime, timedelta
from importlib import resources
from typing import Any

import httpx
import numpy as np
import pandas as pd
import pytest
from sqlalchemy import Connection, Engine, text

from app import analytics
from app.core.db import session_scope
from app.vehicles.service import parse_roster_csv, upsert_vehicles
from tests.support.fleet import drive, ping, post_inrix, post_pings, seed_geometry
from tests.support.servers import live_server
from tests.support.tokens import bearer, issue

# A whole hour two days back: a 10 s box boundary, inside the ping retention window, and with a
# whole UTC day after it for the second day of the engagement test.
T0 = datetime.now(UTC).replace(minute=0, second=0, microsecond=0) - timedelta(days=2)
DAY1 = T0.date()
DAY2 = DAY1 + timedelta(days=1)

Store = Callable[[list[dict[str, Any]]], None]


@pytest.fixture
def connection(seeded_engine: Engine) -> Iterator[Connection]:
    with seeded_engine.connect() as connection:
        yield connection


@pytest.fixture
def api(seeded_database_url: str, seeded_engine: Engine) -> Iterator[tuple[httpx.Client, str]]:
    """A client of the real app on this test's database, and an admin token."""
    token = issue(seeded_engine, "admin")
    with (
        live_server(seeded_database_url) as base,
        httpx.Client(base_url=base, timeout=30) as client,
    ):
        yield client, token


@pytest.fixture
def store(api: tuple[httpx.Client, str]) -> Store:
    """Post ping payloads through the ingest API."""
    client, token = api

    def write(pings: list[dict[str, Any]]) -> None:
        post_pings(client, token, pings)

    return write


def fuel(connection: Connection, speed: float, accel: float, grade: float = 0.0) -> float:
    return float(
        connection.execute(
            text("SELECT analytics.fuel_rate_g_per_s(:v, :a, :g)"),
            {"v": speed, "a": accel, "g": grade},
        ).scalar_one()
    )


# --- energy model ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("speed", "accel", "grade", "expected"),
    [
        # C(20) = 0.146320 + 0.012179*20 + 2.74326e-5*20^3 = 0.146320 + 0.243581 + 0.219461
        (20.0, 0.0, 0.0, 0.6093612764209571),
        # C(10) = 0.146320 + 0.121790 + 0.027433
        (10.0, 0.0, 0.0, 0.2955426958611346),
        # C(10) + P(10)*1 + Q(10)*1^2 = 0.295543 + 0.700131 + 0.260904
        (10.0, 1.0, 0.0, 1.2565771700477703),
        # Braking at 10 m/s: C + P*(-2) < 0 and v > vc, so the floor is 0.
        (10.0, -2.0, 0.0, 0.0),
        # Braking at 3 m/s (v <= vc = 5.98): the floor is beta.
        (3.0, -2.0, 0.0, 0.013111753095302022),
        # Uphill 1 %: C(10) + Z(10)*0.01 = 0.295543 + (1.494008 + 12.718496)*0.01
        (10.0, 0.0, 0.01, 0.2955426958611346 + 0.14212503720844846),
    ],
)
def test_fuel_rate_follows_the_papers_polynomial(
    connection: Connection, speed: float, accel: float, grade: float, expected: float
) -> None:
    assert fuel(connection, speed, accel, grade) == pytest.approx(expected, rel=1e-12)


# --- Edie boxes --------------------------------------------------------------------------------


def test_edie_box_with_two_vehicles(connection: Connection, store: Store) -> None:
    # Vehicle A: 10 pings at 20 m/s from x = 1010 m (to 1190 m); vehicle B: 10 pings at 10 m/s
    # from x = 1020 m. Both stay in the box [T0, T0 + 10 s) x [1000 m, 1200 m).
    store(drive("SF-001", T0, 1010.0, 20.0, 10, accel_mps2=0.0))
    store(drive("SF-002", T0, 1020.0, 10.0, 10, accel_mps2=0.0))

    boxes = analytics.read_view(connection, "edie_boxes")

    assert len(boxes) == 1
    box = boxes.iloc[0]
    assert box["t_start"] == pd.Timestamp(T0)
    assert box["x_start_m"] == 1000.0
    assert box["postmile_start"] == pytest.approx(1000.0 / 1609.344)
    assert box["vehicles"] == 2
    assert box["pings"] == 20
    # Each ping stands for 1 s (the next ping's gap; the last one the nominal second).
    assert box["time_s"] == pytest.approx(20.0)
    assert box["distance_m"] == pytest.approx(10 * 20.0 + 10 * 10.0)
    fuel_g = 10 * 0.6093612764209571 + 10 * 0.2955426958611346  # = 9.0490397 g
    assert box["fuel_g"] == pytest.approx(fuel_g, rel=1e-9)
    area = 10.0 * 200.0  # h_t * h_x in s*m
    assert box["density_veh_per_m"] == pytest.approx(20.0 / area)  # 0.01 veh/m = 10 veh/km
    assert box["flow_veh_per_s"] == pytest.approx(300.0 / area)  # 0.15 veh/s = 540 veh/h
    assert box["fuel_rate_density_g_per_s_m"] == pytest.approx(fuel_g / area, rel=1e-9)
    assert box["speed_mps"] == pytest.approx(15.0)  # u = q / rho
    assert box["fuel_rate_per_vehicle_g_per_s"] == pytest.approx(fuel_g / 20.0, rel=1e-9)
    assert box["fuel_per_distance_g_per_m"] == pytest.approx(fuel_g / 300.0, rel=1e-9)


def test_a_window_that_cuts_a_box_reads_the_whole_box(connection: Connection, store: Store) -> None:
    """A box is divided by its whole area h_t x h_x: a window starting 5 s into it would halve
    its density and flow, unless the window is widened to whole boxes (as MOTION's is)."""
    store(drive("SF-001", T0, 1010.0, 20.0, 10, accel_mps2=0.0))
    aligned = analytics.read_view(
        connection, "edie_boxes", since=T0, until=T0 + timedelta(minutes=1)
    )
    cut = analytics.read_view(
        connection, "edie_boxes", since=T0 + timedelta(seconds=5), until=T0 + timedelta(seconds=55)
    )
    direct = analytics.edie_field(connection, T0 + timedelta(seconds=5), T0 + timedelta(seconds=55))
    for boxes in (cut, direct):
        assert list(boxes["density_veh_per_m"]) == pytest.approx(list(aligned["density_veh_per_m"]))
        assert list(boxes["flow_veh_per_s"]) == pytest.approx(list(aligned["flow_veh_per_s"]))


def test_edie_splits_a_drive_across_boxes_in_time_and_space(
    connection: Connection, store: Store
) -> None:
    # 15 pings at 25 m/s from x = 1010 m: t = 0..7 s lie in [1000, 1200) m (x <= 1185 m),
    # t = 8, 9 s in [1200, 1400) m, and t = 10..14 s in the next 10 s box, still [1200, 1400).
    store(drive("SF-003", T0, 1010.0, 25.0, 15, accel_mps2=0.0))

    boxes = analytics.read_view(connection, "edie_boxes")

    found = {
        (int((row.t_start - pd.Timestamp(T0)).total_seconds()), row.x_start_m): row.pings
        for row in boxes.itertuples()
    }
    assert found == {(0, 1000.0): 8, (0, 1200.0): 2, (10, 1200.0): 5}
    assert boxes["distance_m"].sum() == pytest.approx(15 * 25.0)


def test_edie_acceleration_from_speed_differences_when_the_ping_has_none(
    connection: Connection, store: Store
) -> None:
    # 10 m/s then 11 m/s one second later: a = 1 m/s^2 for the first second, then the last ping
    # (no successor) counts as 0 m/s^2. Fuel = f(10, 1) + f(11, 0).
    store(
        [
            ping("SF-004", T0, 1010.0, 10.0),
            ping("SF-004", T0 + timedelta(seconds=1), 1020.5, 11.0),
        ]
    )

    box = analytics.read_view(connection, "edie_boxes").iloc[0]

    expected = 1.2565771700477703 + fuel(connection, 11.0, 0.0)
    assert box["fuel_g"] == pytest.approx(expected, rel=1e-6)


def test_edie_does_not_bridge_long_gaps(connection: Connection, store: Store) -> None:
    # Two pings 8 s apart (the car lost its fix): each counts one nominal second, not 8 s.
    store(
        [
            ping("SF-005", T0, 1010.0, 20.0),
            ping("SF-005", T0 + timedelta(seconds=8), 1170.0, 20.0),
        ]
    )

    box = analytics.read_view(connection, "edie_boxes").iloc[0]

    assert box["time_s"] == pytest.approx(2.0)


def test_edie_ends_a_pings_time_at_the_next_ping_off_the_corridor(
    connection: Connection, store: Store
) -> None:
    # 1 Hz at 10 m/s for 9 s; the 4th to 6th pings are 5 km off the corridor (no x_m). Each of
    # the six pings on it stands for 1 s until the car's next ping, on the corridor or not:
    # 6 s and 60 m in the box, not the 9 s and 90 m of crediting the last ping before the
    # excursion with all of it (migration 0017).
    pings = drive("SF-006", T0, 1010.0, 10.0, 9)
    for excursion in pings[3:6]:
        excursion["lat"] += 0.045
    store(pings)

    box = analytics.read_view(connection, "edie_boxes").iloc[0]

    assert (box["pings"], box["time_s"], box["distance_m"]) == (6, 6.0, 60.0)


def test_edie_field_function_takes_other_box_sizes_and_a_window(
    connection: Connection, store: Store
) -> None:
    store(drive("SF-001", T0, 1010.0, 20.0, 10, accel_mps2=0.0))
    store(drive("SF-001", T0 + timedelta(hours=1), 1010.0, 20.0, 10, accel_mps2=0.0))

    field = analytics.edie_field(
        connection, T0, T0 + timedelta(minutes=30), h_t_s=60.0, h_x_m=1000.0
    )

    assert len(field) == 1
    assert field.iloc[0]["x_start_m"] == 1000.0
    assert field.iloc[0]["density_veh_per_m"] == pytest.approx(10.0 / (60.0 * 1000.0))
    with pytest.raises(ValueError, match="h_t_s > 0"):
        analytics.edie_field(connection, T0, T0 + timedelta(minutes=1), h_t_s=0.0)
    # a naive bound is UTC, as in every other window here (it raised TypeError beside an aware one)
    naive = analytics.edie_field(
        connection, T0.replace(tzinfo=None), T0 + timedelta(minutes=30), h_t_s=60.0, h_x_m=1000.0
    )
    pd.testing.assert_frame_equal(naive, field)


# --- engagement --------------------------------------------------------------------------------


def engaged_drive(
    vehicle_id: str, start: datetime, pings: int, engaged: int
) -> list[dict[str, Any]]:
    """`pings` pings on the corridor, the first `engaged` with the controller engaged."""
    return [
        ping(
            vehicle_id,
            start + timedelta(seconds=second),
            2000.0 + 20.0 * second,
            20.0,
            acc_engaged=True,
            controller_engaged=second < engaged,
        )
        for second in range(pings)
    ]


def test_engagement_share_per_vehicle_and_pooled_per_day(
    connection: Connection, store: Store
) -> None:
    # Day 1: A 10 of 20 pings engaged (50 %), B 9 of 30 (30 %); pooled 19 / 50 = 38 %
    # (the paper's 11/16 figure; the mean of the two shares would be 40 %).
    # Day 2: A 16 of 20, B 23 of 30: pooled 39 / 50 = 78 % (the paper's 11/17 figure).
    day2 = T0 + timedelta(days=1)
    store(engaged_drive("SF-001", T0, 20, 10))
    store(engaged_drive("SF-002", T0, 30, 9))
    store(engaged_drive("SF-001", day2, 20, 16))
    store(engaged_drive("SF-002", day2, 30, 23))
    # A fix 2 km off the road is not time on the corridor and does not count.
    off_road = ping("SF-001", T0 + timedelta(minutes=5), 3000.0, 20.0, controller_engaged=False)
    off_road["lat"] += 0.02
    store([off_road])

    per_vehicle = analytics.read_view(connection, "engagement_daily")
    fleet = analytics.read_view(connection, "engagement_fleet_daily")

    first = per_vehicle[per_vehicle["day"] == DAY1].set_index("vehicle_id")
    assert first.loc["SF-001", "pings"] == 20
    assert first.loc["SF-001", "engagement_share"] == pytest.approx(0.5)
    assert first.loc["SF-002", "engagement_share"] == pytest.approx(0.3)
    assert first.loc["SF-002", "acc_engaged_share"] == pytest.approx(1.0)
    shares = fleet.set_index("day")["engagement_share"]
    assert shares[DAY1] == pytest.approx(0.38)
    assert shares[DAY2] == pytest.approx(0.78)
    assert list(fleet["vehicles"]) == [2, 2]


# --- ping rate and latency ---------------------------------------------------------------------


def test_ping_rate_and_latency_per_vehicle_hour(
    connection: Connection, api: tuple[httpx.Client, str]
) -> None:
    # SF-001: 10 pings 1 s apart -> 9 intervals in 9 s = 1 Hz. SF-002: 5 pings 2 s apart -> 0.5 Hz.
    # Both uploads come as one spooled batch a minute later: every ping of a batch gets the same
    # received_at, so SF-001's latencies are (received - T) - 0..9 s: median and mean 4.5 s below
    # the largest.
    client, token = api
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(seconds=60)
    sent_after = datetime.now(UTC)
    post_pings(client, token, drive("SF-001", start, 1010.0, 20.0, 10))
    sent_before = datetime.now(UTC)
    post_pings(
        client,
        token,
        [
            ping("SF-002", start + timedelta(seconds=2 * i), 1010.0 + 40.0 * i, 20.0)
            for i in range(5)
        ],
    )

    read_after = datetime.now(UTC)  # the views' now() is their transaction's start
    rates = analytics.read_view(connection, "ping_rate_hourly")
    fleet = analytics.read_view(connection, "fleet_ping_hourly")
    read_before = datetime.now(UTC)

    by_vehicle = rates.groupby("vehicle_id")["pings"].sum()
    assert dict(by_vehicle) == {"SF-001": 10, "SF-002": 5}
    sf001 = rates[rates["vehicle_id"] == "SF-001"]
    if len(sf001) == 1:  # (the drive did not straddle an hour boundary)
        row = sf001.iloc[0]
        assert row["ping_rate_hz"] == pytest.approx(1.0)
        assert row["latency_p50_s"] == pytest.approx(row["latency_max_s"] - 4.5)
        assert row["latency_mean_s"] == pytest.approx(row["latency_max_s"] - 4.5)
        assert row["hour"] == pd.Timestamp(start).floor("h")
    sf002 = rates[rates["vehicle_id"] == "SF-002"]
    if len(sf002) == 1:
        assert sf002.iloc[0]["ping_rate_hz"] == pytest.approx(0.5)
    longest = rates["latency_max_s"].max()
    assert (sent_after - start).total_seconds() <= longest
    assert longest <= (sent_before - start).total_seconds() + 5.0
    assert fleet["pings"].sum() == 15
    assert fleet["vehicles"].max() == 2
    # the hour still running is divided by the time it has run (at least a minute), not by
    # 3,600 s: at half past, a fleet pinging at 100/s read 50/s
    for hour in fleet.itertuples():
        ran = [
            min(3600.0, max(60.0, (t - hour.hour).total_seconds()))
            for t in (read_after, read_before)
        ]
        assert hour.pings / ran[1] - 1e-9 <= hour.pings_per_s <= hour.pings / ran[0] + 1e-9


# --- INRIX latency -----------------------------------------------------------------------------


def test_a_break_in_driving_is_no_slow_pinging(connection: Connection, store: Store) -> None:
    """SF-004 pinged at 1 Hz for 10 s, was switched off for 2 minutes, and pinged at 1 Hz for
    10 s more in the same hour: (n - 1) / (last - first) read 18 / 149 s = 0.12 Hz, and the
    docs' "cars that ping slowly" flagged it (analytics audit). SF-006 pings every 10 s: slow,
    and still read so."""
    hour = T0.replace(minute=10, second=0, microsecond=0)
    first = [
        ping("SF-004", hour + timedelta(seconds=i), 1010.0 + 20.0 * i, 20.0) for i in range(10)
    ]
    second = [
        ping("SF-004", hour + timedelta(seconds=140 + i), 1010.0 + 20.0 * i, 20.0)
        for i in range(10)
    ]
    slow = [
        ping("SF-006", hour + timedelta(seconds=10 * i), 1010.0 + 200.0 * i, 20.0) for i in range(7)
    ]
    store(first + second + slow)

    rates = analytics.read_view(connection, "ping_rate_hourly").set_index("vehicle_id")

    assert rates.loc["SF-004", "pings"] == 20
    assert rates.loc["SF-004", "ping_rate_hz"] == pytest.approx(1.0)
    assert rates.loc["SF-006", "ping_rate_hz"] == pytest.approx(0.1)


def test_inrix_latency_per_snapshot(
    connection: Connection, api: tuple[httpx.Client, str], seeded_engine: Engine
) -> None:
    # One snapshot of three segments measured 180 s ago (the paper's ~3 min INRIX delay), at
    # 44.7, 49.2 and 53.7 mph = 19.98, 21.99, 24.01 m/s (1 mph = 0.44704 m/s). Their mean speed
    # is the space-mean speed, length over travel time: the seed's first three segments are
    # 717.17, 824.46 and 998.17 m long (2539.80 m), driven in 35.89 + 37.49 + 41.58 = 114.95 s,
    # so 22.094 m/s; the plain mean of the three speeds, 21.99 m/s, gives the 717 m segment the
    # weight of the 998 m one (and reads a congested road fast: the migration's example).
    client, token = api
    with seeded_engine.connect() as reader:
        codes, lengths = zip(
            *reader.execute(
                text("SELECT xd_code, length_m FROM dim_inrix_segment ORDER BY seq LIMIT 3")
            ).all(),
            strict=True,
        )
    measured = datetime.now(UTC).replace(microsecond=0) - timedelta(seconds=180)
    before = datetime.now(UTC)
    post_inrix(client, token, measured, dict(zip(codes, [44.7, 49.2, 53.7], strict=True)))
    after = datetime.now(UTC)

    latency = analytics.read_view(connection, "inrix_latency")

    assert len(latency) == 1
    row = latency.iloc[0]
    assert row["segments"] == 3
    assert row["realtime_segments"] == 3
    assert (before - measured).total_seconds() <= row["latency_s"]
    assert row["latency_s"] <= (after - measured).total_seconds()
    assert [round(length, 2) for length in lengths] == [717.17, 824.46, 998.17]
    assert row["mean_speed_mps"] == pytest.approx(22.094, abs=1e-3)
    # a closed segment is counted as closed and left out of the open road's mean speed
    closed = measured + timedelta(minutes=1)
    post_inrix(
        client, token, closed, dict(zip(codes, [44.7, 49.2, 53.7], strict=True)), closed=codes[2]
    )
    row = analytics.read_view(connection, "inrix_latency").iloc[-1]
    assert (row["segments"], row["closed_segments"]) == (3, 1)
    assert row["mean_speed_mps"] == pytest.approx(1541.63 / (35.89 + 37.49), rel=1e-3)
    # an open segment of standing traffic takes unbounded time to drive: the road's space-mean
    # speed is 0 (it was left out, and the road read as fast as its moving segments)
    standing = measured + timedelta(minutes=2)
    post_inrix(client, token, standing, dict(zip(codes, [44.7, 0.0, 53.7], strict=True)))
    row = analytics.read_view(connection, "inrix_latency").iloc[-1]
    assert row["mean_speed_mps"] == 0.0


# --- plan adherence ----------------------------------------------------------------------------


def segment_at(x_m: float) -> dict[str, Any]:
    from app.seed import seed_corridor_document

    for segment in seed_corridor_document()["i24_segments"]:
        if segment["start_x_m"] <= x_m < segment["end_x_m"]:
            return dict(segment)
    raise AssertionError(f"no segment at {x_m}")


def publish_plan(engine: Engine, targets: dict[tuple[int, int], float]) -> int:
    """A published plan with the given (lane, segment id) -> target speed rows."""
    with engine.begin() as writer:
        plan_id = int(
            writer.execute(
                text(
                    "INSERT INTO plan_run (corridor_id, status, algorithm, started_at, "
                    "published_at, valid_until) VALUES ('I-24-WB', 'published', 'test', :t, :t, "
                    ":t + interval '3 min') RETURNING plan_id"
                ),
                {"t": T0 - timedelta(seconds=30)},
            ).scalar_one()
        )
        writer.execute(
            text(
                "INSERT INTO fact_speed_planner (corridor_id, plan_id, lane, i24_segment_id, "
                "target_speed_mps) VALUES ('I-24-WB', :plan_id, :lane, :segment, :target)"
            ),
            [
                {"plan_id": plan_id, "lane": lane, "segment": segment, "target": target}
                for (lane, segment), target in targets.items()
            ],
        )
    return plan_id


def test_plan_adherence_compares_speed_with_the_target_where_the_car_was(
    seeded_engine: Engine, connection: Connection, store: Store
) -> None:
    segment = segment_at(5000.0)
    middle = (segment["start_x_m"] + segment["end_x_m"]) / 2
    plan_id = publish_plan(
        seeded_engine, {(2, segment["i24_segment_id"]): 20.0, (3, segment["i24_segment_id"]): 25.0}
    )
    # Lane 2 (SF-002's assigned lane, no lane in the ping): speeds 18, 22, 25 against 20 m/s.
    store(
        [
            ping(
                "SF-002",
                T0 + timedelta(seconds=i),
                middle,
                speed,
                plan_id=plan_id,
                controller_engaged=i < 2,
            )
            for i, speed in enumerate([18.0, 22.0, 25.0])
        ]
    )
    # A ping reporting lane 3 is compared with lane 3's target; one without a plan is left out.
    store([ping("SF-001", T0, middle, 24.0, plan_id=plan_id, lane=3)])
    store([ping("SF-003", T0, middle, 24.0)])

    detail = analytics.read_view(connection, "plan_adherence")
    daily = analytics.read_view(connection, "plan_adherence_daily").set_index("vehicle_id")

    assert sorted(detail["vehicle_id"]) == ["SF-001", "SF-002", "SF-002", "SF-002"]
    sf001 = detail[detail["vehicle_id"] == "SF-001"].iloc[0]
    assert (sf001["lane"], sf001["target_speed_mps"], sf001["speed_error_mps"]) == (3, 25.0, -1.0)
    assert sf001["plan_age_s"] == pytest.approx(30.0)
    # Errors -2, +2, +5: mean 5/3, mean |e| 3, RMS sqrt((4 + 4 + 25) / 3) = sqrt(11).
    assert daily.loc["SF-002", "pings"] == 3
    assert daily.loc["SF-002", "mean_speed_error_mps"] == pytest.approx(5 / 3)
    assert daily.loc["SF-002", "mean_abs_speed_error_mps"] == pytest.approx(3.0)
    assert daily.loc["SF-002", "rms_speed_error_mps"] == pytest.approx(math.sqrt(11))
    assert daily.loc["SF-002", "engaged_mean_abs_speed_error_mps"] == pytest.approx(2.0)


def reassign(client: httpx.Client, token: str, vehicle_id: str, lane: int) -> datetime:
    """Move a car to another lane through the API (as an operator does); the time after it."""
    response = client.put(
        f"/api/v1/vehicles/{vehicle_id}/assignment",
        json={"lane": lane, "route": "B", "controller": {"name": "microaccel_acc", "params": {}}},
        headers=bearer(token),
    )
    assert response.status_code == 200, response.text
    return datetime.now(UTC)


def test_plan_adherence_reads_each_ping_against_the_lane_assigned_at_its_time(
    seeded_engine: Engine, connection: Connection, api: tuple[httpx.Client, str], store: Store
) -> None:
    """A reassignment does not rewrite a car's history: pings without a lane from before it
    are compared with the old lane's target, those after it with the new lane's."""
    segment = segment_at(5000.0)
    middle = (segment["start_x_m"] + segment["end_x_m"]) / 2
    plan_id = publish_plan(
        seeded_engine, {(2, segment["i24_segment_id"]): 20.0, (3, segment["i24_segment_id"]): 25.0}
    )
    # SF-002 drives in its seed lane 2 at 22 m/s (no lane in its pings), is moved to lane 3,
    # and drives on at 22 m/s: +2 m/s against lane 2's 20 before, -3 against lane 3's 25 after.
    store(
        [ping("SF-002", T0 + timedelta(seconds=i), middle, 22.0, plan_id=plan_id) for i in (0, 1)]
    )
    moved = reassign(*api, "SF-002", 3)
    store(
        [
            ping("SF-002", moved + timedelta(seconds=i), middle, 22.0, plan_id=plan_id)
            for i in (0, 1, 2)
        ]
    )

    detail = analytics.read_view(connection, "plan_adherence").sort_values("ts")

    assert list(detail["lane"]) == [2, 2, 3, 3, 3]
    assert list(detail["target_speed_mps"]) == [20.0, 20.0, 25.0, 25.0, 25.0]
    assert list(detail["speed_error_mps"]) == [2.0, 2.0, -3.0, -3.0, -3.0]
    daily = analytics.read_view(connection, "plan_adherence_daily").set_index("day")
    assert daily.loc[DAY1, "mean_speed_error_mps"] == pytest.approx(2.0)
    assert daily.loc[moved.date(), "mean_speed_error_mps"] == pytest.approx(-3.0)


def test_edie_boxes_put_each_ping_on_the_corridor_assigned_at_its_time(
    seeded_engine: Engine, connection: Connection
) -> None:
    """A car moved to another corridor (a roster import) keeps its earlier boxes on the first."""
    with seeded_engine.begin() as writer:
        writer.execute(
            text(
                "INSERT INTO dim_corridor (corridor_id, name, direction, lanes, length_m, "
                "speed_limit_mps, min_target_speed_mps) "
                "VALUES ('I-24-EB', 'I-24 eastbound', 'EB', 4, 6000, 31.3, 4.5)"
            )
        )

    def drive_at(start: datetime) -> None:
        # 10 pings at 20 m/s from x = 1010 m, written as ingest would have map-matched them.
        with seeded_engine.begin() as writer:
            writer.execute(
                text(
                    "INSERT INTO fact_vehicle_ping (vehicle_id, ts, lat, lon, speed_mps, "
                    "accel_mps2, x_m) VALUES ('SF-001', :ts, 36.0, -86.6, 20, 0, :x)"
                ),
                [{"ts": start + timedelta(seconds=i), "x": 1010.0 + 20.0 * i} for i in range(10)],
            )

    drive_at(T0)
    with session_scope(seeded_engine) as session:
        with resources.as_file(resources.files("seed_data").joinpath("roster.csv")) as roster:
            (row,) = [row for row in parse_roster_csv(roster) if row.vehicle_id == "SF-001"]
        upsert_vehicles(
            session, [row.model_copy(update={"corridor_id": "I-24-EB"})], update_existing=True
        )
    # the next whole 10 s box but one, so the drive fills one box
    moved = datetime.fromtimestamp((math.floor(datetime.now(UTC).timestamp() / 10) + 2) * 10, UTC)
    drive_at(moved)

    boxes = analytics.read_view(connection, "edie_boxes").sort_values("t_start")

    assert list(boxes["corridor_id"]) == ["I-24-WB", "I-24-EB"]
    assert list(boxes["pings"]) == [10, 10]
    assert list(boxes["t_start"]) == [pd.Timestamp(T0), pd.Timestamp(moved)]


# --- app.analytics: registry, windows, CSV ------------------------------------------------------


def test_every_view_of_the_schema_is_registered(connection: Connection) -> None:
    names = set(
        connection.execute(
            text("SELECT table_name FROM information_schema.views WHERE table_schema = 'analytics'")
        ).scalars()
    )
    assert names == set(analytics.VIEWS)


@pytest.mark.parametrize("name", sorted(analytics.VIEWS))
def test_every_view_answers_on_an_empty_database(connection: Connection, name: str) -> None:
    frame = analytics.read_view(connection, name)
    assert frame.empty
    assert len(frame.columns) >= 3


def test_read_view_filters_by_time_and_vehicle(connection: Connection, store: Store) -> None:
    store(engaged_drive("SF-001", T0, 10, 5))
    store(engaged_drive("SF-002", T0 + timedelta(days=1), 10, 5))

    later = analytics.read_view(connection, "engagement_daily", since=T0 + timedelta(days=1))
    one = analytics.read_view(connection, "engagement_daily", vehicle_id="SF-001")
    window = analytics.read_view(connection, "edie_boxes", since=T0, until=T0 + timedelta(hours=1))

    assert list(later["vehicle_id"]) == ["SF-002"]
    assert list(one["day"]) == [DAY1]
    assert set(window["t_start"].dt.date) == {DAY1}
    with pytest.raises(analytics.UnknownView, match="choose one of: edie_boxes"):
        analytics.read_view(connection, "pings; DROP TABLE dim_vehicle")
    with pytest.raises(analytics.NotPerVehicle, match="no vehicle_id"):
        analytics.read_view(connection, "fleet_ping_hourly", vehicle_id="SF-001")
    with pytest.raises(analytics.EmptyWindow, match="is before since"):
        analytics.read_view(connection, "engagement_daily", since=T0, until=T0 - timedelta(days=1))


def test_a_date_or_naive_bound_is_utc_on_the_views_filtered_on_their_own_time(
    seeded_engine: Engine,
) -> None:
    """inrix_latency and plan_adherence are filtered on their own time column, and a date or a
    naive bound reached PostgreSQL as it was, to be read in the session's time zone: in a
    session in Nashville's (a server's default zone, or PGTZ) since=date(2022, 11, 16) began at
    06:00 UTC and lost the night's snapshots, while every other view's window began at UTC
    midnight, as the module reads a date or naive bound."""
    measured = datetime(2022, 11, 16, 3, 0, tzinfo=UTC)  # 21:00 on the 15th in Nashville
    with seeded_engine.begin() as connection:
        corridor_id, xd_code = connection.execute(
            text("SELECT corridor_id, xd_code FROM dim_inrix_segment ORDER BY seq LIMIT 1")
        ).one()
        connection.execute(
            text(
                "INSERT INTO fact_inrix_estimate (corridor_id, xd_code, measured_at, speed_mps)"
                " VALUES (:corridor, :xd, :measured, 25.0)"
            ),
            {"corridor": corridor_id, "xd": xd_code, "measured": measured},
        )
    with seeded_engine.connect() as connection:
        connection.execute(text("SET LOCAL TIME ZONE 'America/Chicago'"))
        day = analytics.read_view(
            connection, "inrix_latency", since=date(2022, 11, 16), until=date(2022, 11, 17)
        )
        hours = analytics.read_view(
            connection,
            "inrix_latency",
            since=datetime(2022, 11, 16, 2, 0),
            until=datetime(2022, 11, 16, 4, 0),
        )

    assert list(day["measured_at"]) == [measured]
    assert list(hours["measured_at"]) == [measured]


def test_export_csv_writes_a_header_and_iso_times(connection: Connection, store: Store) -> None:
    store(drive("SF-001", T0, 1010.0, 20.0, 3))
    out = io.StringIO()

    rows = analytics.export_csv(analytics.read_view(connection, "ping_rate_hourly"), out)

    lines = out.getvalue().splitlines()
    assert rows == 1
    assert lines[0].startswith("vehicle_id,hour,pings,")
    assert lines[1].startswith(f"SF-001,{T0:%Y-%m-%dT%H}:00:00.000000+0000,3,")


def test_seed_geometry_round_trips_positions() -> None:
    lat, lon = seed_geometry().position(5000.0)
    assert seed_geometry().locate(lat, lon).x_m[0] == pytest.approx(5000.0, abs=0.01)


def test_the_sql_energy_model_matches_the_simulators(connection: Connection) -> None:
    from sim.energy import RAV4_2019

    speeds = np.linspace(0.0, 35.0, 15)
    accels = np.linspace(-3.0, 2.5, 12)
    grades = (-0.02, 0.0, 0.03)
    for grade in grades:
        for accel in accels:
            expected = RAV4_2019.fuel_rate_gps(speeds, accel, grade)
            found = [fuel(connection, float(v), float(accel), grade) for v in speeds]
            np.testing.assert_allclose(found, expected, rtol=1e-12, atol=1e-15)


def test_a_window_keeps_whole_days_and_hours(connection: Connection, store: Store) -> None:
    # Pings at 13:00 and 13:30 of DAY1: a window starting at 13:20 still returns the whole
    # day (20 pings) and the whole 13:00 hour, as filtering the view by day or hour would.
    store(engaged_drive("SF-001", T0, 10, 5))
    store(engaged_drive("SF-001", T0 + timedelta(minutes=30), 10, 5))
    since = T0 + timedelta(minutes=20)

    days = analytics.read_view(connection, "engagement_daily", since=since)
    # a window within one day keeps that day whole too (its end is no midnight)
    within = analytics.read_view(
        connection, "engagement_daily", since=since, until=since + timedelta(hours=1)
    )
    hours = analytics.read_view(connection, "fleet_ping_hourly", since=since, until=since)
    none = analytics.read_view(connection, "fleet_ping_hourly", since=T0 + timedelta(hours=1))

    assert list(days["pings"]) == [20]
    assert list(within["pings"]) == [20]
    assert list(hours["pings"]) == [20]
    assert none.empty


@pytest.mark.parametrize(
    ("column", "since", "until", "window"),
    [
        # midnight in Nashville's winter is 06:00 UTC, in the middle of the view's UTC day
        ("day", "2022-11-16T00:00-06:00", "2022-11-17T00:00-06:00", ("16T00:00", "18T00:00")),
        # a half-hour zone: 10:00+05:30 is 04:30 UTC, in the middle of the 04:00 hour
        ("hour", "2022-11-16T10:00+05:30", "2022-11-16T11:00+05:30", ("16T04:00", "16T06:00")),
        ("day", "2022-11-16T00:00", "2022-11-17T00:00", ("16T00:00", "17T00:00")),  # UTC
        # equal bounds ask for the bucket they fall in, on its start as inside it (on its start
        # they gave no row at all: analytics audit)
        ("day", "2022-11-16T00:00", "2022-11-16T00:00", ("16T00:00", "17T00:00")),
        ("day", "2022-11-16T12:00", "2022-11-16T12:00", ("16T00:00", "17T00:00")),
        ("hour", "2022-11-16T13:00", "2022-11-16T13:00", ("16T13:00", "16T14:00")),
    ],
)
def test_a_window_in_another_zone_is_cut_at_the_views_utc_days_and_hours(
    column: str, since: str, until: str, window: tuple[str, str]
) -> None:
    """A bound written in local time was cut at local midnight: the first UTC day came back
    holding only the pings after 06:00 UTC, labelled as the whole day."""
    lower, upper = analytics.bucket_window(
        column, datetime.fromisoformat(since), datetime.fromisoformat(until)
    )
    expected = tuple(datetime.fromisoformat(f"2022-11-{end}+00:00") for end in window)
    assert (lower, upper) == expected
