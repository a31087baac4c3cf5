"""Readiness checks: each grade at its thresholds' edges, and the deployment verdict."""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime, timedelta

import pytest

from app.core.config import load_settings
from app.fleet.readiness import (
    CHECK_NAMES,
    LastPing,
    LastStatus,
    Thresholds,
    VehicleFacts,
    assess,
    describe_age,
    grade_falling,
    grade_rising,
)

NOW = datetime(2022, 11, 16, 13, 0, 0, tzinfo=UTC)
LIMITS = Thresholds.from_settings(load_settings())


def healthy_status(**changes: object) -> LastStatus:
    status = LastStatus(
        ts=NOW - timedelta(seconds=5),
        received_at=NOW - timedelta(seconds=5),
        agent_version="1.0.0",
        is_can_ok=True,
        can_msgs_per_s=1800.0,
        has_gps_fix=True,
        gps_satellites=11,
        is_acc_available=True,
        controller="microaccel_acc",
        is_controller_running=True,
        plan_age_s=20.0,
        spool_backlog=0,
        disk_free_mb=12000.0,
        cpu_temp_c=55.0,
        is_ups_on_battery=False,
    )
    return replace(status, **changes)  # type: ignore[arg-type]


def healthy_facts(**changes: object) -> VehicleFacts:
    facts = VehicleFacts(
        vehicle_id="SF-001",
        assigned_controller="microaccel_acc",
        is_active=True,
        is_in_maintenance=False,
        last_ping=LastPing(
            ts=NOW - timedelta(seconds=1),
            received_at=NOW,
            speed_mps=20.0,
            x_m=1000.0,
            lane=1,
            is_acc_engaged=True,
            is_controller_engaged=True,
            controller="microaccel_acc",
            plan_id=1,
        ),
        last_status=healthy_status(),
    )
    return replace(facts, **changes)  # type: ignore[arg-type]


def test_the_default_thresholds_come_from_the_settings() -> None:
    assert LIMITS.status_age_s == (30.0, 60.0)
    assert LIMITS.disk_free_mb == (2000.0, 500.0)


@pytest.mark.parametrize(
    ("value", "expected"), [(29.9, "green"), (30.0, "amber"), (59.9, "amber"), (60.0, "red")]
)
def test_rising_grades_turn_at_the_thresholds(value: float, expected: str) -> None:
    assert grade_rising(value, (30.0, 60.0)) == expected


@pytest.mark.parametrize(
    ("value", "expected"), [(2000.1, "green"), (2000.0, "amber"), (500.1, "amber"), (500.0, "red")]
)
def test_falling_grades_turn_at_the_thresholds(value: float, expected: str) -> None:
    assert grade_falling(value, (2000.0, 500.0)) == expected


def test_a_healthy_car_is_cleared_with_every_check_green() -> None:
    readiness = assess(healthy_facts(), NOW, LIMITS)
    assert readiness.is_cleared
    assert [check.name for check in readiness.checks] == list(CHECK_NAMES)
    assert {check.level for check in readiness.checks} == {"green"}
    assert readiness.problems == ()


@pytest.mark.parametrize(
    ("age_s", "level"), [(29, "green"), (30, "amber"), (59, "amber"), (60, "red"), (3600, "red")]
)
def test_a_stale_status_turns_amber_then_red_and_blocks_clearance(age_s: int, level: str) -> None:
    status = healthy_status(ts=NOW - timedelta(seconds=age_s))
    readiness = assess(healthy_facts(last_status=status), NOW, LIMITS)
    assert readiness.level_of("status") == level
    assert readiness.is_cleared == (level != "red")


@pytest.mark.parametrize(
    ("change", "check", "level"),
    [
        ({"has_gps_fix": False}, "gps", "red"),
        ({"gps_satellites": 5}, "gps", "amber"),
        ({"gps_satellites": 4}, "gps", "red"),
        ({"is_can_ok": False}, "can", "red"),
        ({"can_msgs_per_s": 150.0}, "can", "amber"),
        ({"can_msgs_per_s": 10.0}, "can", "red"),
        ({"is_acc_available": False}, "acc", "red"),
        ({"is_controller_running": False}, "controller", "red"),
        ({"controller": "simple"}, "controller", "amber"),
        ({"plan_age_s": None}, "plan", "amber"),
        ({"plan_age_s": 95.0}, "plan", "amber"),
        ({"plan_age_s": 200.0}, "plan", "red"),
        ({"spool_backlog": 500}, "spool", "amber"),
        ({"spool_backlog": 5000}, "spool", "red"),
        ({"disk_free_mb": 1500.0}, "disk", "amber"),
        ({"disk_free_mb": 100.0}, "disk", "red"),
        ({"cpu_temp_c": 72.0}, "temperature", "amber"),
        ({"cpu_temp_c": 85.0}, "temperature", "red"),
        ({"is_ups_on_battery": True}, "power", "amber"),
        ({"cpu_temp_c": None}, "temperature", "unknown"),
        ({"agent_version": None}, "agent", "unknown"),
    ],
)
def test_each_check_grades_what_the_car_reported(
    change: dict[str, object], check: str, level: str
) -> None:
    readiness = assess(healthy_facts(last_status=healthy_status(**change)), NOW, LIMITS)
    assert readiness.level_of(check) == level
    others = {c.level for c in readiness.checks if c.name != check}
    assert others == {"green"}
    assert readiness.is_cleared == (level != "red")
    if level == "red":
        assert any(
            problem.startswith(readiness.checks[CHECK_NAMES.index(check)].label)
            for problem in readiness.problems
        )


def test_agent_version_is_amber_only_when_a_version_is_required() -> None:
    facts = healthy_facts(last_status=healthy_status(agent_version="0.9.0"))
    assert assess(facts, NOW, LIMITS).level_of("agent") == "green"
    strict = replace(LIMITS, agent_version="1.0.0")
    assert assess(facts, NOW, strict).level_of("agent") == "amber"


def test_a_car_never_heard_from_is_red_and_not_cleared() -> None:
    readiness = assess(healthy_facts(last_ping=None, last_status=None), NOW, LIMITS)
    assert readiness.verdict == "not cleared"
    assert readiness.level_of("ping") == "red"
    assert readiness.level_of("status") == "red"
    assert readiness.level_of("gps") == "unknown"
    assert len(readiness.problems) == 2


def test_maintenance_and_inactive_cars_are_never_cleared() -> None:
    assert assess(healthy_facts(is_in_maintenance=True), NOW, LIMITS).verdict == "maintenance"
    assert assess(healthy_facts(is_active=False), NOW, LIMITS).verdict == "inactive"


@pytest.mark.parametrize(
    ("seconds", "text"),
    [(5, "5 s"), (119, "119 s"), (600, "10 min"), (10800, "3 h"), (259200, "3 d")],
)
def test_ages_read_well(seconds: float, text: str) -> None:
    assert describe_age(seconds) == text
