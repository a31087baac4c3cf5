"""The demo's status line: its words and units, verdict changes, the workers' progress files."""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path
from zoneinfo import ZoneInfo

import httpx

from smoothfleet.cli.demo_status import (
    FleetStatus,
    StatusMonitor,
    VerdictTracker,
    read_progress,
    status_line,
)

AT = datetime(2022, 11, 16, 12, 2, 5, tzinfo=UTC)  # 06:02:05 in Nashville


def test_the_status_line_reads_in_the_pages_units() -> None:
    status = FleetStatus(
        at=AT,
        pings_per_s=99.84,
        vehicles=100,
        reporting=100,
        cleared=98,
        engaged=71,
        plan_age_s=42.4,
        inrix_age_s=212.0,
        step_interval_s=0.1049,
        late_share=0.021,
        verdict_changes=98,
        verdict_flips=0,
    )
    assert status_line(status, ZoneInfo("America/Chicago")) == (
        "06:02:05 CST  pings 99.8/s · reporting 100/100 · cleared 98 · engaged 71 · "
        "plan 42 s old · INRIX 212 s old · fleet step 0.10 s (2 % late) · "
        "verdict changes 98 (0 after clearance)"
    )


def test_missing_sources_read_as_dashes_and_none() -> None:
    status = FleetStatus(AT, None, 3, 0, 0, 0, None, None, None, None, 0)
    line = status_line(status, UTC)
    assert "pings —" in line
    assert "plan none · INRIX none · fleet step —" in line


def test_verdict_changes_are_counted_and_flips_after_a_first_clearance() -> None:
    tracker = VerdictTracker()
    assert tracker.update(AT, {"SF-001": "not cleared", "SF-002": "cleared"}) == []
    assert tracker.update(AT, {"SF-001": "cleared", "SF-002": "cleared"}) == [
        (AT, "SF-001", "not cleared", "cleared")
    ]
    tracker.update(AT, {"SF-001": "cleared", "SF-003": "cleared"})  # a new car is no change
    assert len(tracker.changes) == 1
    assert tracker.flips == 0  # SF-001 was cleared for the first time: the fleet starting
    tracker.update(AT, {"SF-001": "not cleared", "SF-002": "cleared", "SF-003": "cleared"})
    assert (len(tracker.changes), tracker.flips) == (2, 1)


def test_progress_of_all_workers_is_pooled(tmp_path: Path) -> None:
    paths = [tmp_path / "a.json", tmp_path / "b.json", tmp_path / "missing.json"]
    paths[0].write_text(
        json.dumps({"window_steps": 20, "window_late_steps": 2, "window_wall_s": 2.2})
    )
    paths[1].write_text(
        json.dumps({"window_steps": 20, "window_late_steps": 0, "window_wall_s": 2.0})
    )
    step, late = read_progress(paths)
    assert step == 4.2 / 40
    assert late == 2 / 40
    assert read_progress(paths[2:]) == (None, None)


def test_a_fleet_api_that_does_not_answer_is_said_once_per_cause() -> None:
    """The status line went silent: a run whose database another demo had dropped said
    nothing for two minutes while every poll got a 401."""
    said: list[str] = []
    monitor = StatusMonitor("http://demo.test", "token", None, [], said.append)  # type: ignore[arg-type]
    refused = httpx.Response(401, json={"detail": "invalid or revoked token"})
    monitor.http = httpx.Client(
        base_url="http://demo.test", transport=httpx.MockTransport(lambda request: refused)
    )
    assert monitor.poll() is None
    assert monitor.poll() is None
    assert said == ['status: GET /api/v1/fleet -> HTTP 401 {"detail":"invalid or revoked token"}']
