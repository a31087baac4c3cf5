"""Plans as the agent receives them: refused when unusable, looked up with the wave shift."""

from __future__ import annotations

import json
from datetime import UTC, datetime, timedelta

import pytest

from vehicle_agent.plan import LanePlan, PlanError, parse_plan

PUBLISHED = datetime(2024, 5, 1, 12, 0, tzinfo=UTC)


def body(**lane: object) -> str:
    lane_body = {
        "lane": 2,
        "x_m": [0.0, 100.0, 200.0],
        "end_x_m": [100.0, 200.0, 300.0],
        "target_speed_mps": [30.0, 20.0, 10.0],
        "buffers": [],
    } | lane
    return json.dumps(
        {
            "plan_id": 7,
            "corridor": "I-24-WB",
            "published_at": PUBLISHED.isoformat(),
            "valid_until": (PUBLISHED + timedelta(minutes=3)).isoformat(),
            "algorithm": "x",
            "params": {},
            "inputs": {},
            "lanes": [lane_body],
        }
    )


@pytest.mark.parametrize(
    ("lane", "message"),
    [
        ({"target_speed_mps": [30.0, -1.0, 10.0]}, "target speed -1.0 m/s is not usable"),
        ({"target_speed_mps": [30.0, 20.0]}, "3 positions but 2 speeds"),
        ({"x_m": [0.0, 200.0, 100.0]}, "positions do not increase"),
        ({"end_x_m": [100.0, 150.0, 10.0]}, "a sub-segment ends before it starts"),
    ],
)
def test_unusable_plans_are_refused_with_the_reason(lane: dict[str, object], message: str) -> None:
    with pytest.raises(PlanError, match=message):
        parse_plan(body(**lane))


def test_non_finite_speeds_and_missing_lanes_are_refused() -> None:
    with pytest.raises(PlanError, match="lanes"):
        parse_plan(
            json.dumps(
                {
                    "plan_id": 1,
                    "corridor": "I-24-WB",
                    "published_at": PUBLISHED.isoformat(),
                    "valid_until": (PUBLISHED + timedelta(minutes=3)).isoformat(),
                    "lanes": [],
                }
            )
        )
    with pytest.raises(PlanError):
        parse_plan(body().replace("10.0]", "NaN]"))
    # the contract's document: a plan without its lifetime or a lane without its ends is not one
    without_lifetime = json.loads(body())
    del without_lifetime["valid_until"]
    with pytest.raises(PlanError, match="valid_until: Field required"):
        parse_plan(json.dumps(without_lifetime))
    with pytest.raises(PlanError, match="end_x_m: Field required"):
        parse_plan(body(end_x_m=None).replace('"end_x_m": null, ', ""))
    with pytest.raises(PlanError, match="has no lane 3"):
        LanePlan(parse_plan(body()), 3, None)


def test_targets_hold_over_each_sub_segment_and_move_downstream_with_age() -> None:
    lane = LanePlan(parse_plan(body()), 2, '"abc"')
    fresh = lane.profile(PUBLISHED, wave_speed_mps=-5.0)
    assert fresh.at(50.0) == 30.0
    assert fresh.at(150.0) == 20.0
    assert fresh.at(250.0) == 10.0
    # 20 s later, waves have moved 100 m upstream: the target at 50 m is the published one at
    # 150 m.
    assert lane.profile(PUBLISHED + timedelta(seconds=20), -5.0).at(50.0) == 20.0


def test_freshness_is_the_plans_own_age_and_validity() -> None:
    lane = LanePlan(parse_plan(body()), 2, None)
    assert lane.is_fresh(PUBLISHED + timedelta(seconds=60), stale_after_s=120.0)
    assert not lane.is_fresh(PUBLISHED + timedelta(seconds=121), stale_after_s=120.0)
    # valid_until (published + 180 s) ends it even when stale_plan_after_s would not
    assert lane.is_fresh(PUBLISHED + timedelta(seconds=180), stale_after_s=600.0)
    assert not lane.is_fresh(PUBLISHED + timedelta(seconds=181), stale_after_s=600.0)


def test_a_car_clock_behind_the_servers_cannot_make_an_old_plan_young() -> None:
    """A Pi without a real-time clock can boot minutes behind: by its wall clock a plan it has
    held for 9 minutes would be 'published a minute from now'. Its age is at least the time
    since it arrived, on the car's steady clock."""
    lane = LanePlan(parse_plan(body()), 2, None, received_s=1000.0)
    behind = PUBLISHED - timedelta(minutes=1)  # the car's wall clock, 10 min slow, 9 min on
    assert lane.age_s(behind) == -60.0
    assert lane.age_s(behind, now_s=1000.0 + 540.0) == 540.0
    assert lane.is_fresh(behind, 120.0, now_s=1000.0 + 60.0)
    assert not lane.is_fresh(behind, 120.0, now_s=1000.0 + 540.0)
    # and the lookup shifts by that age, not by none
    assert lane.profile(behind, -4.0, now_s=1000.0 + 10.0).shift_m == 40.0


def test_a_car_clock_behind_the_servers_cannot_keep_a_plan_past_its_validity() -> None:
    """The plan holds for 180 s (valid_until less published_at). With the car's wall clock an
    hour behind, valid_until never came by that clock: the plan was followed for as long as
    stale_plan_after_s allowed (audit). Its age, at least the time since it arrived, ends it."""
    lane = LanePlan(parse_plan(body()), 2, None, received_s=1000.0)
    behind = PUBLISHED - timedelta(hours=1)
    assert lane.is_fresh(behind, 600.0, now_s=1000.0 + 180.0)
    assert not lane.is_fresh(behind, 600.0, now_s=1000.0 + 181.0)


def test_a_plan_served_old_to_a_car_clock_behind_keeps_the_age_it_had_when_served() -> None:
    """The server sent the plan 150 s after publishing it (its answer's Date). Counted from its
    arrival alone, its age lost those 150 s on a car whose clock is an hour behind: followed
    150 s past its validity, its targets read 625 m short at -4 m/s (audit)."""
    served = PUBLISHED + timedelta(seconds=150)
    lane = LanePlan(parse_plan(body()), 2, None, received_s=1000.0, served_at=served)
    behind = PUBLISHED - timedelta(hours=1)
    assert lane.age_s(behind, now_s=1000.0 + 31.0) == 181.0
    assert lane.is_fresh(behind, 600.0, now_s=1000.0 + 30.0)
    assert not lane.is_fresh(behind, 600.0, now_s=1000.0 + 31.0)
    assert lane.profile(behind, -4.0, now_s=1000.0).shift_m == 600.0
    # a Date before publishing (the server's clock stepped back): no age at arrival, not less
    early = LanePlan(
        parse_plan(body()), 2, None, received_s=1000.0, served_at=PUBLISHED - timedelta(hours=1)
    )
    assert early.age_s(behind, now_s=1000.0 + 31.0) == 31.0


def test_the_plan_reaches_the_car_where_its_target_is_read_not_where_it_is() -> None:
    """The lane's targets run to 300 m (its last sub-segment ends there), read 50 m downstream
    of the car (a 12.5 s old plan at -4 m/s): a car at 290 m reads its target at 340 m, within
    the 50 m tolerance of the end; one at 310 m reads it at 360 m, past it, where the lookup
    would hold the end's target flat; a car 60 m upstream of the first point reads it at
    -10 m, inside."""
    lane = LanePlan(parse_plan(body()), 2, None)
    shift = lane.lookup_shift_m(PUBLISHED + timedelta(seconds=12.5), -4.0)
    assert shift == 50.0
    assert lane.reaches(290.0, shift)
    assert not lane.reaches(310.0, shift)
    assert lane.reaches(310.0)  # where the car itself is, the lane covers it
    assert lane.reaches(-60.0, shift)
    assert not lane.reaches(-60.0)


def test_a_car_clock_ahead_of_publishing_reads_the_plan_where_it_was_published() -> None:
    """A wall clock a minute behind the plan's publishing, and no steady clock to age it by:
    its age reads -60 s, and the lookup must not move upstream by it (250 m at -4 m/s)."""
    lane = LanePlan(parse_plan(body()), 2, None)
    behind = PUBLISHED - timedelta(minutes=1)
    profile = lane.profile(behind, -4.0)
    assert profile.shift_m == 0.0
    assert profile.at(150.0) == 20.0


def test_a_sub_segment_whose_end_overlaps_the_next_holds_only_until_the_next_starts() -> None:
    """A plan whose first sub-segment is drawn to 1500 m while the second starts at 1000 m is
    valid; the first target holds up to 1000 m, the second from there (drawn past the next
    start, the lookup's positions would not increase and np.interp's answer is undefined)."""
    lane = LanePlan(
        parse_plan(
            body(x_m=[0.0, 1000.0], end_x_m=[1500.0, 2000.0], target_speed_mps=[30.0, 10.0])
        ),
        2,
        None,
    )
    profile = lane.profile(PUBLISHED, -4.0)
    assert profile.at(900.0) == 30.0
    assert profile.at(1200.0) == 10.0
    assert profile.at(1900.0) == 10.0
