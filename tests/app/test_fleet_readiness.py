"""Readiness checks: each grade at its thresholds' edges, and the deployment verdict."""

from __future__ import annotations

import random
from dataclasses import replace
from datetime import UTC, datetime, timedelta

import pytest

from app.core.config import load_settings
from app.fleet.readiness import (
    CHECK_NAMES,
    HOLD_PERIODS_REPLAYED,
    CanSchedule,
    LastPing,
    LastStatus,
    Level,
    Thresholds,
    VehicleFacts,
    assess,
    describe_age,
    grade_falling,
    grade_rising,
    hold_levels,
)
from vehicle_agent.cars import STALE_PERIODS

NOW = datetime(2022, 11, 16, 13, 0, 0, tzinfo=UTC)
LIMITS = Thresholds.from_settings(load_settings())


def healthy_status(**changes: object) -> LastStatus:
    status = LastStatus(
        ts=NOW - timedelta(seconds=5),
        received_at=NOW - timedelta(seconds=5),
        agent_version="1.0.0",
        is_can_ok=True,
        can_msgs_per_s=150.0,
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
        make="Nissan",
        model="Rogue",
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


def test_a_car_whose_clock_runs_ahead_ages_from_when_its_messages_arrived() -> None:
    # its clock is 250 s fast; its last ping and status arrived 70 s ago
    ahead = NOW + timedelta(seconds=180)
    arrived = NOW - timedelta(seconds=70)
    facts = healthy_facts(
        last_ping=replace(healthy_facts().last_ping, ts=ahead, received_at=arrived),
        last_status=healthy_status(ts=ahead, received_at=arrived),
    )
    readiness = assess(facts, NOW, LIMITS)
    # before: "-180 s", green, and cleared for 250 s more than a car with a true clock
    assert (readiness.level_of("ping"), readiness.level_of("status")) == ("red", "red")
    assert not readiness.is_cleared


@pytest.mark.parametrize(
    ("sent_s_ago", "plan_age_s", "level", "shown"),
    [(0, 100.0, "amber", "100 s"), (100, 10.0, "amber", "110 s"), (100, 100.0, "red", "200 s")],
)
def test_a_plan_ages_from_when_the_car_reported_it(
    sent_s_ago: int, plan_age_s: float, level: str, shown: str
) -> None:
    """A report sent N s ago that said "plan 10 s old" means a plan 10 + N s old now; read as
    it was sent, a car that fell silent with a fresh plan kept a green plan check for ever."""
    sent = NOW - timedelta(seconds=sent_s_ago)
    status = healthy_status(ts=sent, received_at=sent, plan_age_s=plan_age_s)
    plan = assess(healthy_facts(last_status=status), NOW, LIMITS).checks[CHECK_NAMES.index("plan")]
    assert (plan.level, plan.value, plan.reason) == (level, shown, f"plan {shown} old")


def test_a_car_fallen_silent_shows_its_plan_aged_whatever_its_earlier_reports() -> None:
    """The earlier reports are replayed for hysteresis, and the silence after the latest one
    makes no later report: held back as a flicker, the aged plan never turned red."""
    sent = NOW - timedelta(minutes=10)
    statuses = [
        healthy_status(
            ts=sent - timedelta(seconds=s), received_at=sent - timedelta(seconds=s), plan_age_s=20.0
        )
        for s in range(180, -1, -10)
    ]
    facts = healthy_facts(last_status=statuses[-1], earlier_statuses=tuple(statuses[:-1]))
    plan = assess(facts, NOW, LIMITS).checks[CHECK_NAMES.index("plan")]
    assert (plan.level, plan.value, plan.reason, plan.pending) == (
        "red",
        "10 min",
        "plan 10 min old",
        "",
    )


def test_the_earlier_reports_of_a_car_whose_clock_runs_ahead_keep_their_plan_age() -> None:
    """Replayed for hysteresis, each report is graded as of when it was sent (when it arrived,
    for a clock 250 s ahead), not as of its `ts`, which would age its plan by the clock's lead."""
    lead = timedelta(seconds=250)
    statuses = [
        healthy_status(ts=NOW + lead - timedelta(seconds=s), received_at=NOW - timedelta(seconds=s))
        for s in range(120, -1, -10)
    ]
    facts = healthy_facts(last_status=statuses[-1], earlier_statuses=tuple(statuses[:-1]))
    readiness = assess(facts, NOW, replace(LIMITS, hold_s=60.0))
    assert readiness.level_of("plan") == "green"
    assert readiness.is_cleared


def test_pings_a_full_spool_dropped_are_shown_not_graded() -> None:
    """A car's spool dropped its oldest pings unsent when full, counted only in its own file:
    they were lost without a word. The total is since the spool was made, so a car that lost
    some on an old outage is not held back for it now."""
    readiness = assess(healthy_facts(last_status=healthy_status(spool_dropped=1201)), NOW, LIMITS)
    [spool] = [check for check in readiness.checks if check.name == "spool"]
    assert (spool.level, spool.value) == ("green", "0, 1201 dropped unsent")


@pytest.mark.parametrize(
    ("change", "check", "level"),
    [
        ({"has_gps_fix": False}, "gps", "red"),
        ({"gps_satellites": 5}, "gps", "amber"),
        ({"gps_satellites": 4}, "gps", "red"),
        ({"is_can_ok": False}, "can", "red"),
        # the fleet's 2023 Rogue sends 80/s: amber at half, red at a tenth
        ({"can_msgs_per_s": 40.0}, "can", "amber"),
        ({"can_msgs_per_s": 8.0}, "can", "red"),
        ({"is_acc_available": False}, "acc", "red"),
        ({"is_controller_running": False}, "controller", "amber"),
        ({"controller": "simple"}, "controller", "amber"),
        # the agent built no controller from its assignment (say, a policy it refused)
        ({"controller": None, "is_controller_running": False}, "controller", "red"),
        # a report that leaves out what the car needs to drive clears nothing
        ({"has_gps_fix": None, "gps_satellites": None}, "gps", "red"),
        ({"is_can_ok": None, "can_msgs_per_s": None}, "can", "red"),
        ({"is_acc_available": None}, "acc", "red"),
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
    result = readiness.checks[CHECK_NAMES.index(check)]
    assert (result.reason in readiness.reasons) == (level in ("amber", "red"))
    if level == "red":
        assert readiness.problems == (result.reason,)


def test_a_car_not_engaged_says_why_the_agent_gave() -> None:
    idle = healthy_status(is_controller_running=False)
    readiness = assess(healthy_facts(last_status=idle), NOW, LIMITS)
    assert readiness.reasons == ("controller microaccel_acc not engaged",)
    stalled = replace(idle, engage_reason="button presses not confirmed by the car")
    readiness = assess(healthy_facts(last_status=stalled), NOW, LIMITS)
    assert readiness.level_of("controller") == "amber"
    assert readiness.reasons == (
        "controller microaccel_acc not engaged: button presses not confirmed by the car",
    )
    assert readiness.is_cleared


def test_a_car_still_on_an_earlier_config_is_amber_and_says_which() -> None:
    # the operator moved the car to another policy (v4); its agent still runs v3
    facts = healthy_facts(config_version=4, last_status=healthy_status(config_version=3))
    readiness = assess(facts, NOW, LIMITS)
    assert readiness.level_of("controller") == "amber"
    assert readiness.reasons == ("runs config v3, assigned v4 (not picked up yet?)",)
    assert readiness.is_cleared  # the config it runs was a valid one
    caught_up = healthy_facts(config_version=4, last_status=healthy_status(config_version=4))
    assert assess(caught_up, NOW, LIMITS).level_of("controller") == "green"


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
    [(5, "5 s"), (212, "212 s"), (599, "599 s"), (600, "10 min"), (10800, "3 h"), (259200, "3 d")],
)
def test_ages_read_well(seconds: float, text: str) -> None:
    assert describe_age(seconds) == text


def test_a_rogue_is_graded_against_its_own_can_schedule() -> None:
    # 2023 Rogue: SPEED every 20 ms, CRUISE, WHEEL_BUTTONS and ACC_HUD every 100 ms = 50 + 10 +
    # 10 + 10 = 80 frames/s; amber at half (40), red at a tenth (8).
    assert CanSchedule.of_make("Nissan", "Rogue", 2023) == CanSchedule("Rogue", 80.0)
    assert CanSchedule.of_make("Nissan", "Rogue") == CanSchedule("Rogue", 80.0)  # the fleet's
    readiness = assess(healthy_facts(last_status=healthy_status(can_msgs_per_s=7.0)), NOW, LIMITS)
    assert readiness.problems == ("CAN 7/s ≤ 8/s for Rogue",)
    slow = assess(healthy_facts(last_status=healthy_status(can_msgs_per_s=12.0)), NOW, LIMITS)
    assert slow.level_of("can") == "amber"
    assert slow.reasons == ("CAN 12/s ≤ 40/s for Rogue",)


def test_a_2018_20_rogue_is_graded_against_its_own_frames() -> None:
    # 2 wheel-speed messages every 20 ms, ProPilot and throttle every 50 ms, HUD every 100 ms =
    # 50 + 50 + 20 + 20 + 10 = 150 frames/s; amber at half (75), red at a tenth (15).
    assert CanSchedule.of_make("Nissan", "Rogue", 2019) == CanSchedule("Rogue", 150.0)
    facts = healthy_facts(year=2019, last_status=healthy_status(can_msgs_per_s=12.0))
    assert assess(facts, NOW, LIMITS).problems == ("CAN 12/s ≤ 15/s for Rogue",)
    assert CanSchedule.of_make("Nissan", "Rogue", 2016) is None


def test_each_make_has_its_own_can_thresholds() -> None:
    # XT5: 50 + 20 + 10 + 20 + 20 = 120/s; RAV4: 50 + 30 + 30 + 10 + 40 + 20 = 180/s (the
    # brake module's 40/s since 2026-12-05).
    status = healthy_status(can_msgs_per_s=13.0)
    xt5 = assess(healthy_facts(make="Cadillac", model="XT5", last_status=status), NOW, LIMITS)
    rav4 = assess(healthy_facts(make="Toyota", model="RAV4", last_status=status), NOW, LIMITS)
    assert xt5.level_of("can") == "amber"  # 13 > 12 = 120 / 10
    assert xt5.reasons == ("CAN 13/s ≤ 60/s for XT5",)
    assert rav4.level_of("can") == "red"  # 13 <= 18 = 180 / 10
    assert rav4.problems == ("CAN 13/s ≤ 18/s for RAV4",)


def test_the_red_can_share_is_where_the_agent_calls_its_inputs_stale() -> None:
    assert LIMITS.can_share[1] == pytest.approx(1 / STALE_PERIODS)


def test_a_car_of_an_unknown_make_gets_an_amber_can_check_that_says_so() -> None:
    facts = healthy_facts(make="Ford", model="Focus")
    readiness = assess(facts, NOW, LIMITS)
    assert readiness.level_of("can") == "amber"
    assert readiness.reasons == ("CAN rate unknown for Ford Focus",)


def test_reasons_read_as_words() -> None:
    # sent 5 s ago: the plan is 5 s older now than the car said
    status = healthy_status(plan_age_s=207.0, is_acc_available=False)
    readiness = assess(healthy_facts(last_status=status), NOW, LIMITS)
    assert readiness.problems == ("ACC not available", "plan 212 s old")
    silent = healthy_facts(last_status=healthy_status(ts=NOW - timedelta(minutes=12)))
    assert assess(silent, NOW, LIMITS).problems == ("no status for 12 min", "plan 12 min old")


def reports(*rates: float, every_s: float = 10.0) -> VehicleFacts:
    """A 2018-20 Rogue (150 frames/s: amber at 75, red at 15) whose status reports, every_s
    apart and ending now, gave these CAN rates."""
    statuses = [
        healthy_status(
            ts=NOW - timedelta(seconds=every_s * (len(rates) - 1 - i)), can_msgs_per_s=rate
        )
        for i, rate in enumerate(rates)
    ]
    return healthy_facts(year=2019, last_status=statuses[-1], earlier_statuses=tuple(statuses[:-1]))


HOLD = replace(LIMITS, hold_s=60.0)


def test_one_slow_report_does_not_flip_a_cleared_car() -> None:
    readiness = assess(reports(150, 150, 150, 10), NOW, HOLD)
    assert readiness.is_cleared
    can = readiness.checks[CHECK_NAMES.index("can")]
    assert can.level == "green"
    assert can.value == "10/s"  # the newest report is shown, its level waits
    assert can.pending == "red for 0 s of the 60 s it must hold to change"


def test_a_fault_that_holds_for_the_hold_time_flips_the_car() -> None:
    # red at -60, -50, ..., 0 s: the run spans 60 s
    assert not assess(reports(150, *[10] * 7), NOW, HOLD).is_cleared
    assert assess(reports(150, *[10] * 6), NOW, HOLD).is_cleared  # 50 s: not yet


def test_a_fault_that_falls_through_amber_turns_red_once_red_has_held() -> None:
    """CAN falling to red through one amber report: red from -60 s on has held the hold, but the
    level went to amber when the run spanned 60 s, and the red reports before that were not
    counted towards red: the car stayed cleared up to 50 s longer."""
    can = assess(reports(150, 60, *[10] * 7), NOW, HOLD).checks[CHECK_NAMES.index("can")]
    assert (can.level, can.pending) == ("red", "")
    held = assess(reports(150, 60, *[10] * 6), NOW, HOLD)  # red for 50 s: amber, red pending
    assert held.level_of("can") == "amber"
    assert held.checks[CHECK_NAMES.index("can")].pending.startswith("red for 50 s")


def test_a_car_flickering_between_amber_and_red_settles_at_amber() -> None:
    readiness = assess(reports(150, 10, 60, 10, 60, 10, 60, 10), NOW, HOLD)
    assert readiness.level_of("can") == "amber"
    assert readiness.is_cleared


def test_a_red_car_comes_back_only_after_holding_green() -> None:
    assert not assess(reports(10, 150, 150, 150), NOW, HOLD).is_cleared
    assert assess(reports(10, *[150] * 7), NOW, HOLD).is_cleared


def replayed_verdicts(rates: list[float], every_s: float = 10.0) -> list[str]:
    """The verdict after each report, replayed as the server does: from the reports of the last
    HOLD_PERIODS_REPLAYED hold periods only (app.fleet.service)."""
    window = int(HOLD_PERIODS_REPLAYED * HOLD.hold_s / every_s) + 1
    verdicts = []
    for end in range(1, len(rates) + 1):
        facts = reports(*rates[max(0, end - window) : end], every_s=every_s)
        verdicts.append(assess(facts, NOW, HOLD).verdict)
    return verdicts


def test_reports_that_alternate_settle_at_the_worst_and_never_flip_back() -> None:
    # CAN down on every other report for 10 minutes: no level holds 60 s. The car keeps its
    # level until the flicker has lasted past the two newer hold periods, then shows the worst,
    # whichever report the replayed window begins with
    verdicts = replayed_verdicts([150.0] * 12 + [10.0, 150.0] * 30)
    flipped = verdicts.index("not cleared")
    assert 12 + 12 <= flipped <= 12 + 18
    assert verdicts == ["cleared"] * flipped + ["not cleared"] * (len(verdicts) - flipped)
    verdicts = replayed_verdicts([10.0] * 12 + [150.0, 10.0] * 30)
    assert set(verdicts) == {"not cleared"}


def test_a_flicker_between_amber_and_red_shows_amber_then_settles_at_red() -> None:
    verdicts = replayed_verdicts([150.0] * 12 + [10.0, 60.0] * 30)
    flipped = verdicts.index("not cleared")
    assert flipped >= 12 + 12
    assert verdicts == ["cleared"] * flipped + ["not cleared"] * (len(verdicts) - flipped)


def test_a_lasting_change_flips_the_verdict_once_and_keeps_it() -> None:
    verdicts = replayed_verdicts([150.0] * 30 + [10.0] * 30 + [150.0] * 30)
    assert verdicts == ["cleared"] * 36 + ["not cleared"] * 30 + ["cleared"] * 24


@pytest.mark.parametrize(
    ("levels", "held"),
    [
        (["green"], "green"),
        (["green", "red"], "green"),
        (["green", "red", "green", "red"], "green"),
        (["red", "green", "green", "green"], "green"),  # 0, 30, 60 s later: held 60 s
        (["red", "green", "amber", "green"], "amber"),  # both better than red for 60 s
        (["green", "amber", "red", "red"], "amber"),  # worse for 60 s: at least amber
    ],
)
def test_hold_levels_by_hand(levels: list[Level], held: Level) -> None:
    times = [30.0 * i for i in range(len(levels))]
    assert hold_levels(times, levels, 60.0).level == held


def test_a_level_every_report_of_the_last_hold_shares_is_the_level_held() -> None:
    """Random report sequences (fixed seed): whenever the newest reports all share one level
    over at least the hold, that is the level held, whatever came before."""
    rng = random.Random(1)
    levels: list[Level] = ["green", "unknown", "amber", "red"]
    for _ in range(20_000):
        count = rng.randint(1, 20)
        times = [float(t) for t in sorted(rng.sample(range(200), count))]
        drawn = [rng.choice(levels) for _ in range(count)]
        first = count - 1
        while first > 0 and drawn[first - 1] == drawn[-1]:
            first -= 1
        if times[-1] - times[first] >= 60.0:
            assert hold_levels(times, drawn, 60.0).level == drawn[-1], (times, drawn)


def test_without_a_hold_the_newest_report_decides() -> None:
    assert hold_levels([0.0, 10.0], ["green", "red"], 0.0).level == "red"
