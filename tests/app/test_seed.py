"""The seed corridor and roster: real geometry, idempotent loading."""

from __future__ import annotations

from sqlalchemy import Engine, text

from app.core.db import session_scope
from app.seed import seed, seed_corridor_document

TABLES = ("dim_corridor", "dim_inrix_segment", "dim_i24_segment", "dim_vehicle")


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
    assert after_first == {
        "dim_corridor": 1,
        "dim_inrix_segment": 18,
        "dim_i24_segment": 158,
        "dim_vehicle": 100,
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
