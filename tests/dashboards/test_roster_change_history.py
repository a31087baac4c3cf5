"""A roster re-import that changes a vehicle, as its page's change history shows it.

The row showed the lane, route and controller the imported row set ("roster row: lane 3, ..."):
a car moved from lane 1 read as always in lane 3, and a change of only the controller's
parameters read as no change at all.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

from sqlalchemy import Engine, text

from app.core.config import load_settings
from app.vehicles.schemas import RosterRow
from dashboards.rendering import ROSTER_FIELD_WORDS, display_zone, local_time
from tests.dashboards.support import add_users, logged_in
from tests.support.servers import cli_env, live_server, run_cli

SEED_ROSTER = Path(__file__).resolve().parents[2] / "seed_data" / "roster.csv"
SF001_SEEDED = "SF-001,JN8BT3BB3PW906414,Nissan,Rogue,2023,acc,I-24-WB,A,1,microaccel_acc,{}"
# lane 1 -> 3 and new controller parameters; route and controller as they were
SF001_REIMPORTED = (
    'SF-001,JN8BT3BB3PW906414,Nissan,Rogue,2023,acc,I-24-WB,A,3,microaccel_acc,"{""base"": '
    '{""k"": 0.4}}"'
)
CHANGES = re.compile(r'<table class="history" data-field="changes">.*?<tbody>(.*?)</tbody>', re.S)
CELLS = re.compile(r"<td>(.*?)</td>", re.S)


def test_a_reimport_shows_who_when_and_what_it_changed_on_the_vehicle_page(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    add_users(seeded_engine)
    roster = SEED_ROSTER.read_text()
    assert SF001_SEEDED in roster
    fleet_csv = tmp_path / "fleet.csv"
    fleet_csv.write_text(roster.replace(SF001_SEEDED, SF001_REIMPORTED))
    imported = run_cli(
        "vehicles",
        "import",
        str(fleet_csv),
        env=cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url),
    )
    assert imported.returncode == 0, imported.stderr
    with seeded_engine.connect() as connection:
        changed_at = connection.execute(
            text("SELECT changed_at FROM fact_vehicle_change WHERE vehicle_id = 'SF-001'")
        ).scalar_one()

    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        logged_in(base, "viewer") as client,
    ):
        page = client.get("/vehicles/SF-001")
    assert page.status_code == 200

    summary = re.search(r'<details class="changes"><summary>(.*?)</summary>', page.text)
    assert summary is not None
    assert summary.group(1) == "Changes by operators and roster imports (1 newest)"
    table = CHANGES.search(page.text)
    assert table is not None, "no change history on the page"
    rows = [
        [html.unescape(re.sub(r"\s+", " ", cell)).strip() for cell in CELLS.findall(row)]
        for row in table.group(1).split("</tr>")
        if "<td>" in row
    ]
    zone = display_zone(load_settings(database_url=seeded_database_url))
    assert rows == [
        [
            local_time(changed_at, zone),
            "roster import of fleet.csv",
            "v2",
            'roster row: lane 1 → 3; controller parameters {} → {"base": {"k": 0.4}}',
        ]
    ]


def test_every_roster_field_has_words_on_the_vehicle_page() -> None:
    """A roster field without words would be left out of what an import changed."""
    assert list(ROSTER_FIELD_WORDS) == [
        name for name in RosterRow.model_fields if name != "vehicle_id"
    ]
