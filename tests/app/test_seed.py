"""The seed corridor and roster: real geometry, the simulator's recommended controller on the
cars it drives, idempotent loading."""

from __future__ import annotations

import csv
import hashlib
import json

from sqlalchemy import Engine, text

from app.core.db import session_scope
from app.seed import seed, seed_corridor_document
from seed_data.build import ROSTER_FILE, build_roster
from sim.recommended import RECOMMENDED_CONTROLLER
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

TABLES = ("dim_corridor", "dim_inrix_segment", "dim_i24_segment", "dim_vehicle", "dim_policy")
RECOMMENDED_POLICY = BUNDLED_POLICIES / f"{RECOMMENDED_CONTROLLER.controller}.npz"
RECOMMENDED_SHA256 = hashlib.sha256(RECOMMENDED_POLICY.read_bytes()).hexdigest()
# the recommended variant's params, naming the shipped policy the car downloads
RECOMMENDED_PARAMS = {**RECOMMENDED_CONTROLLER.params, "policy_sha256": RECOMMENDED_SHA256}


def counts(engine: Engine) -> dict[str, int]:
    with engine.connect() as connection:
        return {
            table: connection.execute(text(f"SELECT count(*) FROM {table}")).scalar_one()
            for table in TABLES
        }


def test_seeding_twice_leaves_the_same_row_counts(engine: Engine) -> None:
    with session_scope(engine) as session:
        first = seed(session)
    after_first = counts(engine)
    with session_scope(engine) as session:
        second = seed(session)
    assert counts(engine) == after_first
    assert first == second
    # the seed reports the policy it holds for its RAV4s, by the sha256 their rows name
    shipped = hashlib.sha256((BUNDLED_POLICIES / "rl_accel.npz").read_bytes()).hexdigest()
    assert first.policies == {"rl_accel": shipped}
    assert after_first == {
        "dim_corridor": 1,
        "dim_inrix_segment": 18,
        "dim_i24_segment": 158,
        "dim_vehicle": 100,
        "dim_policy": 1,  # the shipped rl_accel the RAV4s run
    }


def test_reseeding_keeps_an_operators_assignment(seeded_engine: Engine) -> None:
    with seeded_engine.begin() as connection:
        connection.execute(
            text("UPDATE dim_vehicle SET assigned_lane = 3 WHERE vehicle_id = 'SF-001'")
        )
    with session_scope(seeded_engine) as session:
        seed(session)
    with seeded_engine.connect() as connection:
        lane = connection.execute(
            text("SELECT assigned_lane FROM dim_vehicle WHERE vehicle_id = 'SF-001'")
        ).scalar_one()
    assert lane == 3


def test_sub_segments_tile_the_corridor_without_gaps() -> None:
    document = seed_corridor_document()
    subs = document["i24_segments"]
    assert subs[0]["start_x_m"] == 0
    assert abs(subs[-1]["end_x_m"] - document["corridor"]["length_m"]) < 0.05
    for before, after in zip(subs, subs[1:], strict=False):
        assert before["end_x_m"] == after["start_x_m"]
        assert 0 < before["end_x_m"] - before["start_x_m"] <= 100.0
    # The corridor is the paper's 14.5 km I-24 test section, in ~0.5 mi INRIX segments.
    assert 14_400 < document["corridor"]["length_m"] < 14_700
    lengths = [s["length_m"] for s in document["inrix_segments"]]
    assert 300 < sum(lengths) / len(lengths) < 1_100


def test_roster_is_mostly_acc_cars_with_a_few_rav4s(seeded_engine: Engine) -> None:
    with seeded_engine.connect() as connection:
        rows = connection.execute(
            text("SELECT make, actuation, count(*) FROM dim_vehicle GROUP BY make, actuation")
        ).all()
        lanes = connection.execute(
            text("SELECT count(DISTINCT assigned_lane), count(DISTINCT route) FROM dim_vehicle")
        ).one()
    fleet = {(row[0], row[1]): row[2] for row in rows}
    assert fleet == {("Nissan", "acc"): 82, ("Cadillac", "acc"): 15, ("Toyota", "accel"): 3}
    assert tuple(lanes) == (4, 2)


def in_control_group(vehicle_id: str) -> bool:
    """One car in ten (SF-010, SF-020, ...) runs the hand-designed `simple` controller."""
    return int(vehicle_id.removeprefix("SF-")) % 10 == 0


def test_the_acceleration_cars_run_the_recommended_controller_on_the_shipped_policy(
    seeded_engine: Engine,
) -> None:
    with seeded_engine.connect() as connection:
        cars = connection.execute(
            text(
                "SELECT vehicle_id, controller_name, controller_params FROM dim_vehicle"
                " WHERE actuation = :actuation"
            ),
            {"actuation": RECOMMENDED_CONTROLLER.actuation},
        ).all()
        held = connection.execute(
            text("SELECT controller, manifest FROM dim_policy WHERE policy_sha256 = :sha256"),
            {"sha256": RECOMMENDED_SHA256},
        ).all()
    running = {
        vehicle_id: (controller, params)
        for vehicle_id, controller, params in cars
        if not in_control_group(vehicle_id)
    }
    assert running  # the roster has acceleration cars outside the control group
    assert running == dict.fromkeys(
        running, (RECOMMENDED_CONTROLLER.controller, RECOMMENDED_PARAMS)
    )
    control_group = {
        controller for vehicle_id, controller, _ in cars if in_control_group(vehicle_id)
    }
    assert control_group <= {"simple"}
    # the server holds the policy the cars are told to download, with its manifest
    manifest = json.loads(RECOMMENDED_POLICY.with_suffix(".json").read_text())
    assert held == [(RECOMMENDED_CONTROLLER.controller, manifest)]


def test_reseeding_keeps_a_shipped_policy_stored_under_another_manifest(
    seeded_engine: Engine,
) -> None:
    """The same bytes stored with an earlier manifest (as rl_acc's changed on 2026-12-01): the
    roster's cars need only the bytes, and a stored manifest never changes."""
    earlier = {"sha256": RECOMMENDED_SHA256, "actuation": "accel", "command": "(earlier)"}
    with seeded_engine.begin() as connection:
        connection.execute(
            text("UPDATE dim_policy SET manifest = CAST(:manifest AS jsonb)"),
            {"manifest": json.dumps(earlier)},
        )
    with session_scope(seeded_engine) as session:
        assert seed(session).vehicles == 100
    with seeded_engine.connect() as connection:
        stored = connection.execute(text("SELECT policy_sha256, manifest FROM dim_policy")).all()
    assert stored == [(RECOMMENDED_SHA256, earlier)]


def test_the_committed_roster_is_the_one_the_build_writes() -> None:
    """`python -m seed_data.build` reproduces roster.csv: a retrained shipped policy (another
    sha256) must be followed by a rebuilt roster, or the seed's cars would name a stale file."""
    with ROSTER_FILE.open(newline="") as handle:
        committed = list(csv.DictReader(handle))
    built = [{name: str(value) for name, value in row.items()} for row in build_roster()]
    assert committed == built
