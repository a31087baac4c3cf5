"""The demo's road: simulated INRIX in the provider's format, and human leaders in the traffic."""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np
import pytest

from app.feeds.inrix import parse_response, readings_of
from sim.drives import drive_from_speeds
from sim.fleet.traffic import CorridorTraffic, Segment, TrafficLeaders

SEGMENTS = [Segment("SF-I24WB-02", 0.0, 800.0), Segment("SF-I24WB-03", 800.0, 1600.0)]


def test_steady_traffic_reads_as_its_speed_in_mph() -> None:
    traffic = CorridorTraffic(drive_from_speeds("steady", np.full(601, 26.8224)))
    now = datetime(2026, 1, 5, 12, 0, tzinfo=UTC)
    document = traffic.inrix_response(600.0, now, SEGMENTS)
    response = parse_response(document)
    snapshot = readings_of(response)
    assert snapshot.refused == []
    readings = snapshot.readings
    assert [r.xd_code for r in readings] == ["SF-I24WB-02", "SF-I24WB-03"]
    # 26.8224 m/s = 60 mph; stamped with the end of the minute that ended 3 minutes ago
    assert document["result"]["segmentspeeds"][0]["segments"][0]["speed"] == 60.0
    assert readings[0].speed_mps == pytest.approx(26.8224, abs=0.01)
    # (each set is read on its own since 9c714f1: the reading carries the set's time)
    assert {r.measured_at for r in readings} == {datetime(2026, 1, 5, 11, 57, tzinfo=UTC)}
    # 800 m at 26.8224 m/s = 0.4971 min
    assert document["result"]["segmentspeeds"][0]["segments"][0]["travelTimeMinutes"] == (
        pytest.approx(0.4971, abs=1e-4)
    )


def test_a_slowdown_shows_in_the_minute_it_crosses_the_segment() -> None:
    # 30 m/s for 100 s, then 10 m/s: the slow front travels upstream at 15 km/h from 3000 m
    speeds = np.concatenate([np.full(1000, 30.0), np.full(2001, 10.0)])
    traffic = CorridorTraffic(drive_from_speeds("step", speeds))
    segment = [Segment("S", 2000.0, 3000.0)]
    assert traffic.segment_speeds_mps(60.0, segment)[0] == pytest.approx(30.0)
    assert 10.0 < traffic.segment_speeds_mps(180.0, segment)[0] < 30.0
    assert traffic.segment_speeds_mps(400.0, segment)[0] == pytest.approx(10.0)


def test_leaders_drive_at_the_traffic_speed_where_they_are() -> None:
    traffic = CorridorTraffic(drive_from_speeds("steady", np.full(601, 20.0)))
    leaders = TrafficLeaders(traffic, np.array([100.0, 5000.0]), start_s=0.0)
    leaders.advance(10.0)
    np.testing.assert_allclose(leaders.position_m, [300.0, 5200.0])
    assert leaders.leader(1).state(10.0) == pytest.approx((5200.0, 20.0))
    leaders.wrap(1, 5000.0)
    assert leaders.leader(1).state(10.0)[0] == pytest.approx(200.0)
