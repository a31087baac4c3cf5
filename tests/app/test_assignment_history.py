"""dim_vehicle_assignment: a vehicle's corridor, route and lane over time (SCD type 2).

Every writer of dim_vehicle keeps it (a trigger, migration 0012): the assignment API, the roster
import, the seed, plain SQL. A change opens a row; a write that changes none of corridor, route
and lane adds none.
"""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from importlib import resources
from typing import Any

import httpx
import pytest
from sqlalchemy import Engine, text

from app.core.db import session_scope
from app.motion.fleet import fleet_pings
from app.vehicles.schemas import RosterRow
from app.vehicles.service import parse_roster_csv, upsert_vehicles
from tests.planner.facts import move_to_eastbound, pings
from tests.support.api import ON_CORRIDOR_X_M, ping, serving
from tests.support.servers import live_server
from tests.support.tokens import bearer, issue

NEG_INF = "-infinity"
POS_INF = "infinity"


@pytest.fixture
def operator(seeded_database_url: str, seeded_engine: Engine) -> Iterator[httpx.Client]:
    """A client of the real app with an operator's token."""
    token = issue(seeded_engine, "operator")
    with (
        live_server(seeded_database_url) as base,
        httpx.Client(base_url=base, timeout=30, headers=bearer(token)) as client,
    ):
        yield client


def history(engine: Engine, vehicle_id: str) -> list[dict[str, Any]]:
    """The vehicle's rows in time order; the unbounded ends as text, the others as datetimes."""
    with engine.connect() as connection:
        rows = connection.execute(
            text(
                # psycopg loads no infinite timestamp into a datetime: those come as text
                "SELECT CASE WHEN NOT isfinite(valid_from) THEN valid_from::text END AS from_text,"
                " CASE WHEN isfinite(valid_from) THEN valid_from END AS from_at,"
                " CASE WHEN NOT isfinite(valid_to) THEN valid_to::text END AS to_text,"
                " CASE WHEN isfinite(valid_to) THEN valid_to END AS to_at,"
                " corridor_id, route, assigned_lane "
                "FROM dim_vehicle_assignment WHERE vehicle_id = :vehicle ORDER BY valid_from"
            ),
            {"vehicle": vehicle_id},
        ).mappings()
        return [
            {
                "from": row["from_text"] or row["from_at"],
                "to": row["to_text"] or row["to_at"],
                "assignment": (row["corridor_id"], row["route"], row["assigned_lane"]),
            }
            for row in rows
        ]


def assign(client: httpx.Client, vehicle_id: str, **body: Any) -> dict[str, Any]:
    answer = client.put(
        f"/api/v1/vehicles/{vehicle_id}/assignment",
        json={
            "lane": 2,
            "route": "B",
            "controller": {"name": "microaccel_acc", "params": {}},
            **body,
        },
    )
    assert answer.status_code == 200, answer.text
    result: dict[str, Any] = answer.json()
    return result


def seed_roster() -> list[RosterRow]:
    with resources.as_file(resources.files("seed_data").joinpath("roster.csv")) as roster:
        return parse_roster_csv(roster)


def test_every_seeded_vehicle_has_one_open_assignment_from_the_start_of_time(
    seeded_engine: Engine,
) -> None:
    with seeded_engine.connect() as connection:
        mismatched = connection.execute(
            text(
                "SELECT count(*) FROM dim_vehicle v FULL JOIN dim_vehicle_assignment a "
                "USING (vehicle_id) WHERE a.valid_from IS DISTINCT FROM '-infinity' "
                "OR a.valid_to IS DISTINCT FROM 'infinity' "
                "OR (a.corridor_id, a.route, a.assigned_lane) "
                "   IS DISTINCT FROM (v.corridor_id, v.route, v.assigned_lane)"
            )
        ).scalar_one()
        rows = connection.execute(text("SELECT count(*) FROM dim_vehicle_assignment")).scalar_one()
    assert (mismatched, rows) == (0, 100)


def test_a_reassignment_closes_the_open_row_and_opens_the_next(
    seeded_engine: Engine, operator: httpx.Client
) -> None:
    # SF-002 is seeded in lane 2, route B
    assert history(seeded_engine, "SF-002") == [
        {"from": NEG_INF, "to": POS_INF, "assignment": ("I-24-WB", "B", 2)}
    ]
    assign(operator, "SF-002", lane=3)
    assign(operator, "SF-002", lane=3, route="C")

    rows = history(seeded_engine, "SF-002")

    assert [row["assignment"] for row in rows] == [
        ("I-24-WB", "B", 2),
        ("I-24-WB", "B", 3),
        ("I-24-WB", "C", 3),
    ]
    # contiguous: each row ends where the next begins, the last is open
    assert rows[0]["from"] == NEG_INF
    assert rows[0]["to"] == rows[1]["from"]
    assert rows[1]["to"] == rows[2]["from"]
    assert isinstance(rows[1]["from"], datetime)
    assert rows[1]["from"] < rows[2]["from"]
    assert rows[2]["to"] == POS_INF


def test_a_reassignment_that_changes_no_lane_or_route_adds_no_row(
    seeded_engine: Engine, operator: httpx.Client
) -> None:
    before = history(seeded_engine, "SF-002")
    # the same lane and route: once exactly as it is, once with another controller
    first = assign(operator, "SF-002", lane=2, route="B")
    second = assign(
        operator, "SF-002", lane=2, route="B", controller={"name": "simple", "params": {"k": 0.4}}
    )

    assert second["config_version"] == first["config_version"] + 1  # the car is told
    assert history(seeded_engine, "SF-002") == before  # its lane history is not touched


def test_the_roster_import_opens_rows_only_for_what_it_changes(seeded_engine: Engine) -> None:
    roster = seed_roster()
    with session_scope(seeded_engine) as session:
        upsert_vehicles(session, roster, update_existing=True)  # the same roster again
    with seeded_engine.connect() as connection:
        rows = connection.execute(text("SELECT count(*) FROM dim_vehicle_assignment")).scalar_one()
    assert rows == 100

    sf001 = next(row for row in roster if row.vehicle_id == "SF-001")
    new = sf001.model_copy(update={"vehicle_id": "SF-900", "vin": "JN8BT3BB3PW900000"})
    with session_scope(seeded_engine) as session:
        upsert_vehicles(
            session, [sf001.model_copy(update={"assigned_lane": 4}), new], update_existing=True
        )

    assert [row["assignment"] for row in history(seeded_engine, "SF-001")] == [
        ("I-24-WB", "A", 1),
        ("I-24-WB", "A", 4),
    ]
    assert history(seeded_engine, "SF-900") == [
        {"from": NEG_INF, "to": POS_INF, "assignment": ("I-24-WB", "A", 1)}
    ]


def test_a_reimport_that_changes_a_vehicle_keeps_the_change_with_its_version(
    seeded_engine: Engine,
) -> None:
    """A re-import bumped the config version but wrote no change row: that version had no
    record, and a controller changed by it was recorded nowhere (this table's history keeps
    corridor, route and lane only)."""
    roster = seed_roster()
    sf001 = next(row for row in roster if row.vehicle_id == "SF-001")
    params = {"base": {"k": 0.4}}
    new = sf001.model_copy(update={"vehicle_id": "SF-900", "vin": "JN8BT3BB3PW900000"})
    with session_scope(seeded_engine) as session:
        upsert_vehicles(session, roster, update_existing=True, label="fleet.csv")  # no change
        upsert_vehicles(
            session,
            [sf001.model_copy(update={"controller_params": params}), new],
            update_existing=True,
            label="fleet.csv",
        )

    with seeded_engine.connect() as connection:
        changes = connection.execute(
            text(
                "SELECT vehicle_id, config_version, changed_by, change, lane, route, "
                "controller_name, controller_params FROM fact_vehicle_change"
            )
        ).all()
        version = connection.execute(
            text("SELECT config_version FROM dim_vehicle WHERE vehicle_id = 'SF-001'")
        ).scalar_one()
    assert version == 2
    # the new vehicle is no change of one, and the unchanged rows are none either
    assert [tuple(change) for change in changes] == [
        ("SF-001", 2, "roster import of fleet.csv", "roster", 1, "A", "microaccel_acc", params)
    ]


def test_two_changes_in_one_transaction_keep_the_history_contiguous(
    seeded_engine: Engine,
) -> None:
    with seeded_engine.begin() as connection:
        for lane in (3, 4, 3):
            connection.execute(
                text("UPDATE dim_vehicle SET assigned_lane = :lane WHERE vehicle_id = 'SF-001'"),
                {"lane": lane},
            )

    rows = history(seeded_engine, "SF-001")

    assert [row["assignment"][2] for row in rows] == [1, 3, 4, 3]
    for earlier, later in zip(rows, rows[1:], strict=False):
        assert earlier["to"] == later["from"]
    assert rows[-1]["to"] == POS_INF


def test_the_motion_figure_draws_a_moved_car_on_the_corridor_it_drove_then(
    seeded_engine: Engine,
) -> None:
    """`smoothfleet motion figure` (app.motion.fleet) reads the fleet's pings on a corridor:
    those of a car since moved elsewhere are still on it for the time before the move."""
    now = datetime.now(UTC).replace(microsecond=0)
    pings(seeded_engine, "SF-001", now - timedelta(minutes=10), [1000.0, 1025.0, 1050.0], 25.0)
    move_to_eastbound(seeded_engine, "SF-001")
    pings(seeded_engine, "SF-001", now + timedelta(minutes=1), [2000.0, 2025.0], 25.0)

    with seeded_engine.connect() as connection:
        west = fleet_pings(
            connection, "I-24-WB", now - timedelta(hours=1), now + timedelta(hours=1)
        )
        east = fleet_pings(
            connection, "I-24-EB", now - timedelta(hours=1), now + timedelta(hours=1)
        )

    assert list(west.pings["x_m"]) == [1000.0, 1025.0, 1050.0]
    assert list(east.pings["x_m"]) == [2000.0, 2025.0]


def open_reversed_corridor(engine: Engine, corridor_id: str, lanes: int) -> float:
    """A corridor on the seed corridor's road driven the other way, with `lanes` lanes and its
    own INRIX and sub-segments (so ingest can map-match on it); returns its length: a point at
    x on the seed corridor is at length - x on this one."""
    with engine.begin() as connection:
        length_m: float = connection.execute(
            text(
                "INSERT INTO dim_corridor (corridor_id, name, direction, lanes, length_m, "
                "speed_limit_mps, min_target_speed_mps) "
                "SELECT :corridor, 'the seed road reversed', 'reversed', :lanes, length_m, "
                "speed_limit_mps, min_target_speed_mps FROM dim_corridor "
                "WHERE corridor_id = 'I-24-WB' RETURNING length_m"
            ),
            {"corridor": corridor_id, "lanes": lanes},
        ).scalar_one()
        reversed_columns = (
            "(SELECT max(seq) + 1 FROM {table} WHERE corridor_id = 'I-24-WB') - seq, "
            ":length - end_x_m, :length - start_x_m, "
            ":length / 1609.344 - end_postmile, :length / 1609.344 - start_postmile, "
            ":lanes, end_lat, end_lon, start_lat, start_lon"
        )
        connection.execute(
            text(
                "INSERT INTO dim_inrix_segment (xd_code, corridor_id, seq, start_x_m, end_x_m, "
                "start_postmile, end_postmile, lanes, start_lat, start_lon, end_lat, end_lon, "
                "length_m) "
                f"SELECT :corridor || xd_code, :corridor, "
                f"{reversed_columns.format(table='dim_inrix_segment')}, length_m "
                "FROM dim_inrix_segment WHERE corridor_id = 'I-24-WB'"
            ),
            {"corridor": corridor_id, "lanes": lanes, "length": length_m},
        )
        connection.execute(
            text(
                "INSERT INTO dim_i24_segment (i24_segment_id, xd_code, corridor_id, seq, "
                "start_x_m, end_x_m, start_postmile, end_postmile, lanes, start_lat, start_lon, "
                "end_lat, end_lon) "
                "SELECT i24_segment_id + 100000, :corridor || xd_code, :corridor, "
                f"{reversed_columns.format(table='dim_i24_segment')} "
                "FROM dim_i24_segment WHERE corridor_id = 'I-24-WB'"
            ),
            {"corridor": corridor_id, "lanes": lanes, "length": length_m},
        )
    return length_m


def test_a_late_ping_is_checked_and_placed_on_the_corridor_assigned_at_its_ts(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """A car spools its pings while offline. Moved meanwhile from the 4-lane seed corridor to a
    3-lane one, its spool sent afterwards holds pings from both sides of the move: those from
    before count on the corridor it drove then (its lane 4 is no error, its x_m is on that
    road), those from after on the new one."""
    length_m = open_reversed_corridor(seeded_engine, "I-24-EB", lanes=3)
    (sf001,) = [row for row in seed_roster() if row.vehicle_id == "SF-001"]
    with session_scope(seeded_engine) as session:  # the roster import: an operator's move
        upsert_vehicles(
            session, [sf001.model_copy(update={"corridor_id": "I-24-EB"})], update_existing=True
        )
    moved_at = history(seeded_engine, "SF-001")[-1]["from"]
    before = ping(ts=moved_at - timedelta(minutes=5), lane=4, heading_deg=323.0)
    after_lane_4 = ping(ts=moved_at + timedelta(seconds=1), lane=4, heading_deg=143.0)
    after = ping(ts=moved_at + timedelta(seconds=2), lane=3, heading_deg=143.0)
    car = bearer(issue(seeded_engine, "vehicle", "SF-001"))

    with serving(seeded_database_url) as api:
        answer = api.post(
            "/api/v1/pings", json={"pings": [before, after_lane_4, after]}, headers=car
        )

    assert answer.status_code == 200, answer.text
    assert answer.json() == {
        "accepted": 2,
        "duplicates": 0,
        "conflicts": 0,
        "rejected": [
            {"index": 1, "error": "lane 4 is outside the 3 lanes of I-24-EB", "retryable": False}
        ],
    }
    with seeded_engine.connect() as connection:
        stored = dict(
            connection.execute(
                text("SELECT ts, x_m FROM fact_vehicle_ping WHERE vehicle_id = 'SF-001'")
            ).all()
        )
    # the same point of the road, at its x_m on each corridor, driven each corridor's way
    assert stored[moved_at - timedelta(minutes=5)] == pytest.approx(ON_CORRIDOR_X_M, abs=0.5)
    assert stored[moved_at + timedelta(seconds=2)] == pytest.approx(
        length_m - ON_CORRIDOR_X_M, abs=0.5
    )


def test_a_ping_from_a_newer_assignment_than_ingest_holds_is_judged_on_it(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """Ingest keeps the fleet's corridors for `roster_cache_ttl_s` (30 s). A car moved within
    that time fetches its new config and sends pings on the new corridor: judged on the held,
    older one, their lane was refused for good (the car dropped them) or their position put on
    the wrong road. A ping names the config version it was taken under, and one newer than
    ingest holds makes ingest load the roster again first."""
    length_m = open_reversed_corridor(seeded_engine, "I-24-EB", lanes=4)
    (sf001,) = [row for row in seed_roster() if row.vehicle_id == "SF-001"]
    car = bearer(issue(seeded_engine, "vehicle", "SF-001"))

    with serving(seeded_database_url) as api:
        first = api.post("/api/v1/pings", json=ping(heading_deg=323.0), headers=car)
        assert first.status_code == 200, first.text  # ingest now holds the roster
        with session_scope(seeded_engine) as session:  # the operator's move
            upsert_vehicles(
                session, [sf001.model_copy(update={"corridor_id": "I-24-EB"})], update_existing=True
            )
        with seeded_engine.connect() as connection:
            version = connection.execute(
                text("SELECT config_version FROM dim_vehicle WHERE vehicle_id = 'SF-001'")
            ).scalar_one()
        moved_at = history(seeded_engine, "SF-001")[-1]["from"]
        after = ping(
            ts=moved_at + timedelta(seconds=2), lane=4, heading_deg=143.0, config_version=version
        )
        answer = api.post("/api/v1/pings", json=after, headers=car)

    assert answer.status_code == 200, answer.text
    assert answer.json() == {"accepted": 1, "duplicates": 0, "conflicts": 0, "rejected": []}
    with seeded_engine.connect() as connection:
        x_m = connection.execute(
            text("SELECT x_m FROM fact_vehicle_ping WHERE vehicle_id = 'SF-001' AND ts = :ts"),
            {"ts": moved_at + timedelta(seconds=2)},
        ).scalar_one()
    assert x_m == pytest.approx(length_m - ON_CORRIDOR_X_M, abs=0.5)
