"""The planner's database edge on a real PostgreSQL: one transaction per cycle, provenance,
degraded inputs, one publisher per corridor, and replay."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import numpy as np
import pytest
from sqlalchemy import Engine, text
from sqlalchemy.orm import Session

from planner.params import PlannerParams
from planner.warehouse import (
    PLANNER_LOCK_SPACE,
    CycleOutcome,
    UnknownPlan,
    load_grid,
    replay_plan,
    run_cycle,
    store_window_observations,
)
from tests.planner.facts import (
    CORRIDOR,
    INRIX_CODES,
    inrix_snapshot,
    move_to_eastbound,
    pings,
    readings,
    standing_slowdown,
)

NOW = datetime(2026, 11, 24, 13, 0, tzinfo=UTC)
PARAMS = PlannerParams()


def cycle(
    engine: Engine, now: datetime, *, observations: bool = True, **options: object
) -> CycleOutcome:
    """One cycle as the job runs it: publish, then store the window's observations."""
    with Session(engine) as session, session.begin():
        outcome = run_cycle(
            session,
            CORRIDOR,
            algorithm=str(options.pop("algorithm", "kernel_smooth_buffer")),
            params=options.pop("params", PARAMS),
            valid_for_s=180.0,
            now=now,
            **options,  # type: ignore[arg-type]
        )
    if observations:
        with Session(engine) as session, session.begin():
            store_window_observations(session, outcome)
    return outcome


def minutes_of_slowdown(engine: Engine, until: datetime, minutes: int) -> None:
    """INRIX showing the standing slowdown every minute up to three minutes before `until`."""
    for minute in range(minutes, 0, -1):
        inrix_snapshot(engine, until - timedelta(minutes=2 + minute), standing_slowdown())


def test_a_cycle_publishes_every_lane_with_its_provenance(seeded_engine: Engine) -> None:
    minutes_of_slowdown(seeded_engine, NOW, 5)
    # SF-002 (lane 2) crawls through 8.4-8.7 km; SF-001 (lane 1) is off the corridor.
    pings(seeded_engine, "SF-002", NOW, np.linspace(8400, 8700, 60), 5.0)
    pings(seeded_engine, "SF-001", NOW - timedelta(seconds=5), [None] * 30, 30.0)
    outcome = cycle(seeded_engine, NOW)
    assert outcome.status == "published"
    with seeded_engine.connect() as connection:
        run = connection.execute(
            text("SELECT * FROM plan_run WHERE plan_id = :id"), {"id": outcome.plan_id}
        ).one()
        rows = connection.execute(
            text(
                "SELECT lane, count(*) AS cells, min(tse_speed_mps) AS slowest "
                "FROM fact_speed_planner WHERE plan_id = :id GROUP BY lane ORDER BY lane"
            ),
            {"id": outcome.plan_id},
        ).all()
        observations = connection.execute(
            text(
                "SELECT vehicle_id, lane, sum(ping_count) FROM fact_vehicle_observation "
                "GROUP BY vehicle_id, lane"
            )
        ).all()
    assert run.status == "published"
    assert run.algorithm == "kernel_smooth_buffer"
    assert run.params["window_m"] == PARAMS.window_m
    assert run.valid_until - run.published_at == timedelta(seconds=180)
    assert [(row.lane, row.cells) for row in rows] == [(1, 158), (2, 158), (3, 158), (4, 158)]
    assert rows[1].slowest == pytest.approx(5.0)  # lane 2's own observation wins
    assert rows[0].slowest > 5.0  # lane 1 hears of it at half weight only
    # Only SF-002's on-corridor pings became observations, in its assigned lane.
    assert [(row[0], row[1], row[2]) for row in observations] == [("SF-002", 2, 60)]
    inputs = run.inputs
    assert inputs["vehicles"] == 1
    assert inputs["pings"] == 60
    assert inputs["pings_off_corridor"] == 30
    assert inputs["pings_set_aside"] == 0  # the paper's rule fuses every ping
    assert inputs["inrix_age_s"] == 180.0
    assert inputs["inrix_oldest_reading_age_s"] == 180.0  # the snapshot read every segment
    assert inputs["inrix_snapshots"] == 5
    assert inputs["ping_window_end"] == NOW.isoformat()


def test_pings_count_in_the_lane_and_corridor_assigned_at_their_time(
    seeded_engine: Engine,
) -> None:
    """The cycle read each car's assignment now: a car moved to lane 3 after its pings (sent
    with no lane, as GPS fixes mostly are) had them fused into lane 3, and a car moved to
    another corridor took its last minute of pings there, at positions along this one."""
    minutes_of_slowdown(seeded_engine, NOW, 5)
    pings(seeded_engine, "SF-002", NOW, np.linspace(8400, 8700, 60), 5.0)
    pings(seeded_engine, "SF-001", NOW - timedelta(seconds=5), np.linspace(8000, 8200, 30), 20.0)
    with seeded_engine.begin() as connection:  # after the pings, as the clock goes
        connection.execute(
            text("UPDATE dim_vehicle SET assigned_lane = 3 WHERE vehicle_id = 'SF-002'")
        )
    move_to_eastbound(seeded_engine, "SF-001")

    outcome = cycle(seeded_engine, NOW)

    with seeded_engine.connect() as connection:
        observations = connection.execute(
            text(
                "SELECT vehicle_id, lane, sum(ping_count) FROM fact_vehicle_observation "
                "GROUP BY vehicle_id, lane ORDER BY vehicle_id"
            )
        ).all()
        lane_3 = connection.execute(
            text(
                "SELECT sum(fleet_ping_count) FROM fact_speed_planner "
                "WHERE plan_id = :id AND lane = 3"
            ),
            {"id": outcome.plan_id},
        ).scalar()
    assert [tuple(row) for row in observations] == [("SF-001", 1, 30), ("SF-002", 2, 60)]
    assert lane_3 is None
    assert outcome.inputs["vehicles"] == 2


def test_the_behind_leader_rule_sets_aside_an_engaged_cars_echo_of_the_plan(
    seeded_engine: Engine,
) -> None:
    minutes_of_slowdown(seeded_engine, NOW, 5)
    crawl = np.linspace(8400, 8700, 60)
    # Both cars crawl at 5 m/s under their controllers; only SF-003's radar sees a leader.
    pings(seeded_engine, "SF-002", NOW, crawl, 5.0, lane=2, engaged=True, lead_present=False)
    pings(seeded_engine, "SF-003", NOW, crawl, 5.0, lane=3, engaged=True, lead_present=True)
    # An engaged car whose lead flag did not arrive cannot show traffic bounds it.
    pings(seeded_engine, "SF-004", NOW, [8500.0] * 10, 5.0, lane=4, engaged=True)
    outcome = cycle(seeded_engine, NOW, params=PlannerParams(engaged_pings="behind_leader"))
    assert outcome.status == "published"
    assert (outcome.inputs["vehicles"], outcome.inputs["pings"]) == (1, 60)
    assert outcome.inputs["pings_set_aside"] == 70
    with seeded_engine.connect() as connection:
        slowest = dict(
            connection.execute(
                text(
                    "SELECT lane, min(tse_speed_mps) FROM fact_speed_planner "
                    "WHERE plan_id = :id GROUP BY lane"
                ),
                {"id": outcome.plan_id},
            ).all()
        )
        observed = connection.execute(
            text(
                "SELECT vehicle_id, sum(ping_count) FROM fact_vehicle_observation "
                "GROUP BY vehicle_id ORDER BY vehicle_id"
            )
        ).all()
    assert slowest[3] == pytest.approx(5.0)  # behind a leader: the traffic's speed
    assert slowest[2] > 5.0  # alone on its radar: the plan's own echo, not fused
    # the observation fact keeps every vehicle's speed, whatever the rule fused
    assert [tuple(row) for row in observed] == [("SF-002", 60), ("SF-003", 60), ("SF-004", 10)]
    with Session(seeded_engine) as session:
        assert replay_plan(session, outcome.plan_id or 0).matches


def test_a_standing_slowdown_gets_a_buffer_from_the_fourth_cycle(seeded_engine: Engine) -> None:
    minutes_of_slowdown(seeded_engine, NOW + timedelta(minutes=5), 10)
    buffered = []
    for minute in range(5):
        outcome = cycle(seeded_engine, NOW + timedelta(minutes=minute))
        with seeded_engine.connect() as connection:
            buffered.append(
                connection.scalar(
                    text(
                        "SELECT count(*) FROM fact_speed_planner WHERE plan_id = :id "
                        "AND is_buffer AND lane = 1"
                    ),
                    {"id": outcome.plan_id},
                )
            )
    assert buffered[:3] == [0, 0, 0]
    assert buffered[3] > 0
    assert buffered[4] == buffered[3]


def test_no_fresh_inrix_and_no_pings_publishes_nothing_and_says_why(
    seeded_engine: Engine,
) -> None:
    inrix_snapshot(seeded_engine, NOW - timedelta(minutes=11), standing_slowdown())
    outcome = cycle(seeded_engine, NOW)
    assert outcome.status == "skipped"
    assert outcome.reason is not None
    assert "newest INRIX is 660 s old (limit 600 s); 0 pings" in outcome.reason
    with seeded_engine.connect() as connection:
        run = connection.execute(text("SELECT status, reason FROM plan_run")).one()
        assert connection.scalar(text("SELECT count(*) FROM fact_speed_planner")) == 0
    assert run.status == "skipped"
    assert run.reason == outcome.reason


def test_bad_inrix_readings_are_ignored_and_counted(seeded_engine: Engine) -> None:
    speeds = standing_slowdown()
    inrix_snapshot(
        seeded_engine,
        NOW - timedelta(minutes=3),
        speeds,
        **{"SF-I24WB-05": float("nan"), "SF-I24WB-06": 50.0, "SF-I24WB-07": -1.0},
    )
    outcome = cycle(seeded_engine, NOW, algorithm="kernel_smooth")
    assert outcome.status == "published"
    assert outcome.inputs["inrix_ignored"] == {
        "unknown_segment": 0,
        "closed": 0,
        "below_min_score": 0,
        "not_a_number": 1,
        "out_of_range": 2,  # 50 m/s is 112 mph
    }
    with seeded_engine.connect() as connection:
        segment_06 = connection.scalar(
            text(
                "SELECT max(p.tse_speed_mps) FROM fact_speed_planner p "
                "JOIN dim_i24_segment s USING (i24_segment_id) WHERE s.xd_code = 'SF-I24WB-06'"
            )
        )
    assert segment_06 == pytest.approx(29.0)  # filled from its neighbours, not 50 m/s


def _segment_12_speed(engine: Engine, plan_id: int | None) -> float:
    with engine.connect() as connection:
        return float(
            connection.scalar(
                text(
                    "SELECT max(p.tse_speed_mps) FROM fact_speed_planner p "
                    "JOIN dim_i24_segment s USING (i24_segment_id) "
                    "WHERE p.plan_id = :id AND s.xd_code = 'SF-I24WB-12'"
                ),
                {"id": plan_id},
            )
        )


def test_a_reading_from_inrix_history_alone_is_no_measurement_of_now(
    seeded_engine: Engine,
) -> None:
    # The slowdown at 11-14, but INRIX has no probe on 12 and sends its usual free flow there
    # with score 10; its neighbours are measured (score 30).
    inrix_snapshot(
        seeded_engine,
        NOW - timedelta(minutes=3),
        standing_slowdown(),
        scores={"SF-I24WB-11": 30, "SF-I24WB-12": 10, "SF-I24WB-13": 30},
        **{"SF-I24WB-12": 29.0},
    )
    outcome = cycle(seeded_engine, NOW, algorithm="kernel_smooth")
    assert outcome.inputs["inrix_ignored"]["below_min_score"] == 1
    assert _segment_12_speed(seeded_engine, outcome.plan_id) == pytest.approx(7.0)  # neighbours
    with Session(seeded_engine) as session:
        assert replay_plan(session, outcome.plan_id or 0).matches
    # taken at its word when the operator asks for it
    everything = cycle(
        seeded_engine,
        NOW + timedelta(seconds=1),
        algorithm="kernel_smooth",
        params=PlannerParams(min_inrix_score=0),
    )
    assert everything.inputs["inrix_ignored"]["below_min_score"] == 0
    # its free flow shows between the slow neighbours (interpolated towards them)
    assert _segment_12_speed(seeded_engine, everything.plan_id) > 25.0
    # a plan stored before the parameter existed read every score, and replays so
    with seeded_engine.begin() as connection:
        connection.execute(
            text("UPDATE plan_run SET params = params - 'min_inrix_score' WHERE plan_id = :id"),
            {"id": everything.plan_id},
        )
    with Session(seeded_engine) as session:
        assert replay_plan(session, everything.plan_id or 0).matches


def test_only_one_planner_publishes_per_corridor(seeded_engine: Engine) -> None:
    minutes_of_slowdown(seeded_engine, NOW, 3)
    with Session(seeded_engine) as other, other.begin():
        other.execute(
            text("SELECT pg_advisory_xact_lock(:space, hashtext('I-24-WB'))"),
            {"space": PLANNER_LOCK_SPACE},
        )
        assert cycle(seeded_engine, NOW).status == "busy"
    assert cycle(seeded_engine, NOW).status == "published"
    # A replica a few seconds behind finds a fresh plan and leaves it be.
    later = NOW + timedelta(seconds=5)
    assert cycle(seeded_engine, later, min_interval_s=30.0).status == "busy"
    with seeded_engine.connect() as connection:
        assert connection.scalar(text("SELECT count(*) FROM plan_run")) == 1


def test_with_inrix_down_a_second_replica_does_not_store_the_window_again(
    seeded_engine: Engine,
) -> None:
    """A skipped cycle stores its ping window too, but only a published one held the other
    replica off: with no INRIX, two replicas 20 s apart each stored their window, 100
    observations of 60 pings."""
    pings(seeded_engine, "SF-002", NOW, np.linspace(8400, 8700, 60), 5.0)
    first = cycle(seeded_engine, NOW, min_interval_s=30.0)
    second = cycle(seeded_engine, NOW + timedelta(seconds=20), min_interval_s=30.0)
    assert (first.status, second.status) == ("skipped", "busy")
    with seeded_engine.connect() as connection:
        observed = connection.scalar(text("SELECT sum(ping_count) FROM fact_vehicle_observation"))
    assert observed == 60


def test_replay_recomputes_a_plan_from_the_warehouse(seeded_engine: Engine) -> None:
    minutes_of_slowdown(seeded_engine, NOW + timedelta(minutes=4), 9)
    for minute in range(4):
        pings(
            seeded_engine,
            "SF-002",
            NOW + timedelta(minutes=minute),
            np.linspace(8000, 8400, 60),
            9.0,
        )
        outcome = cycle(seeded_engine, NOW + timedelta(minutes=minute))
    # INRIX arriving after the run must not change its replay.
    late = NOW + timedelta(minutes=3)
    inrix_snapshot(seeded_engine, late, [5.0] * 18, received_at=late + timedelta(minutes=5))
    with Session(seeded_engine) as session:
        report = replay_plan(session, outcome.plan_id or 0)
    assert report.matches
    assert report.cells == 4 * 158
    with seeded_engine.begin() as connection:
        connection.execute(
            text(
                "UPDATE fact_speed_planner SET target_speed_mps = target_speed_mps + 0.5 "
                "WHERE plan_id = :id AND lane = 3 AND i24_segment_id = 40"
            ),
            {"id": outcome.plan_id},
        )
    with Session(seeded_engine) as session:
        tampered = replay_plan(session, outcome.plan_id or 0)
    assert not tampered.matches
    assert tampered.max_difference_mps == pytest.approx(0.5, abs=1e-3)


def test_replay_is_exact_although_pings_and_inrix_of_the_window_arrive_after_the_read(
    seeded_engine: Engine,
) -> None:
    minutes_of_slowdown(seeded_engine, NOW + timedelta(minutes=2), 7)
    for minute in range(3):
        pings(
            seeded_engine,
            "SF-002",
            NOW + timedelta(minutes=minute),
            np.linspace(8000, 8400, 60),
            9.0,
        )
        outcome = cycle(seeded_engine, NOW + timedelta(minutes=minute))
    end = NOW + timedelta(minutes=2)
    # After the cycle read its window: a car's spool uploaded late, pings of two more cars, and
    # an INRIX snapshot of the window whose transaction committed after the read although its
    # received_at (the request's arrival) was before it.
    pings(seeded_engine, "SF-003", end, np.linspace(8100, 8500, 60), 3.7, lane=2)
    pings(seeded_engine, "SF-004", end - timedelta(seconds=7), np.linspace(9000, 9200, 40), 21.3)
    inrix_snapshot(
        seeded_engine,
        end - timedelta(seconds=30),
        [4.0] * 18,
        received_at=end - timedelta(seconds=1),
    )
    with Session(seeded_engine) as session:
        report = replay_plan(session, outcome.plan_id or 0)
    assert report.cells == 4 * 158
    assert report.max_difference_mps == 0.0  # bit for bit, not within a tolerance
    assert report.buffer_cells_differing == 0


def test_replay_reads_only_the_inrix_the_cycle_could_have_read(seeded_engine: Engine) -> None:
    """A snapshot the cycle read in part: its other segments' readings were received before the
    read, in a transaction that committed after it. The replay read them as well (the cycle had
    recorded which snapshots it read, not which of their segments) and planned a slowdown the
    cycle never saw. A backlog the poller fetched before the cycle and stored after it was not
    there to read either: a reading counts by when it was stored, not fetched."""
    minutes_of_slowdown(seeded_engine, NOW, 3)
    minute = NOW - timedelta(seconds=60)
    first, rest = INRIX_CODES[:9], INRIX_CODES[9:]
    readings(seeded_engine, minute, dict.fromkeys(first, 29.0), NOW - timedelta(seconds=50))
    outcome = cycle(seeded_engine, NOW, algorithm="kernel_smooth")
    assert outcome.inputs["inrix_segments_unread"] == {minute.isoformat(): rest}
    # After the read: the rest of that minute, received 10 s before it, and a whole snapshot
    # fetched 35 s before it but stored 20 s after it.
    readings(seeded_engine, minute, dict.fromkeys(rest, 4.0), NOW - timedelta(seconds=10))
    inrix_snapshot(
        seeded_engine,
        NOW - timedelta(seconds=30),
        [4.0] * len(INRIX_CODES),
        received_at=NOW + timedelta(seconds=20),
        fetched_at=NOW - timedelta(seconds=35),
    )
    with Session(seeded_engine) as session:
        report = replay_plan(session, outcome.plan_id or 0)
    assert report.cells == 4 * 158
    assert report.max_difference_mps == 0.0


def test_replay_without_stored_observations_pools_the_pings(seeded_engine: Engine) -> None:
    minutes_of_slowdown(seeded_engine, NOW, 3)
    pings(seeded_engine, "SF-003", NOW, np.linspace(8000, 8400, 60), 9.0)
    outcome = cycle(seeded_engine, NOW, observations=False)
    with seeded_engine.connect() as connection:
        assert connection.scalar(text("SELECT count(*) FROM fact_vehicle_observation")) == 0
    with Session(seeded_engine) as session:
        assert replay_plan(session, outcome.plan_id or 0).matches


def test_replay_of_a_plan_that_was_not_published_says_so(seeded_engine: Engine) -> None:
    skipped = cycle(seeded_engine, NOW)
    with Session(seeded_engine) as session:
        with pytest.raises(UnknownPlan, match="was skipped"):
            replay_plan(session, skipped.plan_id or 0)
        with pytest.raises(UnknownPlan, match="no plan 999"):
            replay_plan(session, 999)


def test_the_grid_is_the_seed_corridor(seeded_engine: Engine) -> None:
    with Session(seeded_engine) as session:
        grid = load_grid(session, CORRIDOR)
    assert (grid.lanes, grid.cells) == (4, 158)
    assert grid.end_x_m[-1] == pytest.approx(14585.72)
