"""Honest selection: a fold chooses on its training dates and is scored on the others."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from sim.selection import (
    candidate_summary,
    choose,
    cross_validate,
    held_out_summary,
    standing,
)
from tests.sim.test_evaluate import short_drives, write_drive
from tests.support.servers import cli_env, run_cli


def row(candidate: str, drive: str, scenario: str = "shockwave", **values: float) -> dict:
    base = {
        "candidate": candidate,
        "drive": drive,
        "date": drive[:10],
        "scenario": scenario,
        "fuel_saving_pct": 0.0,
        "throughput_change_pct": 0.0,
        "network_speed_change_pct": 0.0,
        "fuel_economy_mpg_change_pct": 0.0,
        "collisions": 0,
        "takeovers": 0,
        "cut_ins": 0,
        "within_bounds_share": 1.0,
        "distance_lost_m": 0.0,
    }
    return base | values


def test_the_aims_bound_the_fuel_saving() -> None:
    rows = [
        # saves the most but loses 3 % of network speed on shockwave drives
        row("slow", "2021-03-08-a", fuel_saving_pct=12.0, network_speed_change_pct=-3.0),
        # saves more than "good" but crashes once
        row("crash", "2021-03-08-a", fuel_saving_pct=11.0, collisions=1),
        row("good", "2021-03-08-a", fuel_saving_pct=8.0, throughput_change_pct=-1.5),
        row("good", "2021-03-09-a", "freeflow", network_speed_change_pct=-0.5),
        row("slow", "2021-03-09-a", "freeflow"),
        row("crash", "2021-03-09-a", "freeflow"),
    ]
    assert choose(rows).candidate == "good"
    # 1 point short on speed; a collision counts 100
    assert standing("slow", [r for r in rows if r["candidate"] == "slow"]).shortfall_pct == 1.0
    assert standing("crash", [r for r in rows if r["candidate"] == "crash"]).shortfall_pct == 100


def test_when_none_meets_the_aims_the_least_short_is_chosen() -> None:
    rows = [
        row("a", "2021-03-08-a", fuel_saving_pct=9.0, throughput_change_pct=-4.0),
        row("b", "2021-03-08-a", fuel_saving_pct=5.0, throughput_change_pct=-2.5),
    ]
    chosen = choose(rows)
    assert chosen.candidate == "b"
    assert not chosen.meets_aims


def test_each_fold_is_scored_on_dates_it_did_not_choose_on() -> None:
    # "tuned" wins on 2021-03-08 only; "steady" is good everywhere
    rows = [
        row("tuned", "2021-03-08-a", fuel_saving_pct=30.0),
        row("tuned", "2021-03-08-b", fuel_saving_pct=30.0),
        row("tuned", "2021-03-12-a", fuel_saving_pct=1.0),
        row("tuned", "2021-03-15-a", fuel_saving_pct=1.0),
        row("steady", "2021-03-08-a", fuel_saving_pct=6.0),
        row("steady", "2021-03-08-b", fuel_saving_pct=6.0),
        row("steady", "2021-03-12-a", fuel_saving_pct=6.0),
        row("steady", "2021-03-15-a", fuel_saving_pct=6.0),
    ]
    choices = cross_validate(rows, folds=3)
    assert [c.held_out_dates for c in choices] == [
        ("2021-03-08",),
        ("2021-03-12",),
        ("2021-03-15",),
    ]
    # without 2021-03-08 "tuned" looks poor; with it, it looks best
    assert [c.chosen.candidate for c in choices] == ["steady", "tuned", "tuned"]
    for choice in choices:
        assert all(r["drive"][:10] in choice.held_out_dates for r in choice.held_out_rows)
    [summary] = held_out_summary(choices)
    # held out: 08-a and 08-b by "steady" (6, 6), 03-12 and 03-15 by "tuned" (1, 1)
    assert summary["drives"] == 4
    assert summary["fuel_saving_pct"] == pytest.approx(3.5)
    # the same rows scored in-sample would claim (30 + 30 + 1 + 1) / 4 = 15.5 for "tuned"


def test_folds_need_enough_dates() -> None:
    with pytest.raises(
        ValueError, match=r"the drives span 2 dates \(2021-03-08, 2021-03-09\), and 3 folds need 3"
    ):
        cross_validate([row("a", "2021-03-08-a"), row("a", "2021-03-09-a")], folds=3)


def test_the_candidate_summary_splits_each_candidate_by_scenario() -> None:
    rows = [
        row("b", "2021-03-08-a", fuel_saving_pct=4.0, distance_lost_m=100.0),
        row("b", "2021-03-09-a", fuel_saving_pct=2.0, distance_lost_m=300.0, takeovers=1),
        row("b", "2021-03-12-a", "freeflow", fuel_saving_pct=-1.0, within_bounds_share=0.5),
        row("a", "2021-03-08-a", throughput_change_pct=-3.0, collisions=1),
    ]
    a, b = candidate_summary(rows)
    assert (a["candidate"], b["candidate"]) == ("a", "b")
    assert b["shockwave_fuel_saving_pct"] == pytest.approx(3.0)
    assert b["freeflow_fuel_saving_pct"] == pytest.approx(-1.0)
    assert b["shockwave_distance_lost_m"] == pytest.approx(200.0)
    # the envelope share and the counts are over all of a candidate's drives
    assert b["within_bounds_share"] == pytest.approx(2.5 / 3)
    assert (b["takeovers"], b["collisions"], a["collisions"]) == (1, 0, 1)
    assert a["shockwave_throughput_change_pct"] == pytest.approx(-3.0)
    # a candidate without freeflow drives has no freeflow figure
    assert math.isnan(a["freeflow_fuel_saving_pct"])


def test_cli_select_reports_the_folds_the_held_out_drives_and_every_candidate(
    shared_dir: Path, tmp_path: Path
) -> None:
    drives = tmp_path / "drives"
    drives.mkdir()
    # a stop-and-go slice of 2021-04-05 and the freeflow drive of 2021-04-07: two dates, two folds
    for drive in short_drives(shared_dir):
        write_drive(drive, drives / f"{drive.name[:19]}.csv")
    out = tmp_path / "out"
    result = run_cli(
        "sim",
        "select",
        "--drives",
        str(drives),
        "--controller",
        "simple:accel",
        "--controller",
        "microaccel:accel",
        "--window",
        "1500",
        "--folds",
        "2",
        "--out",
        str(out),
        env=cli_env(),
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "Every candidate on every drive" in result.stdout
    assert "chosen on every date" in result.stdout
    with (out / "selection.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    # 2 candidates x (the slice as shockwave, the fast drive as freeflow)
    assert len(rows) == 4
    assert sorted({row["candidate"] for row in rows}) == [
        "kernel_smooth x microaccel/accel @ 1500 m",
        "kernel_smooth x simple/accel @ 1500 m",
    ]
    with (out / "held_out.csv").open() as handle:
        held_out = {row["scenario"]: row for row in csv.DictReader(handle)}
    # each drive held out once: the shockwave slice by one fold, the freeflow drive by the other
    assert {scenario: row["drives"] for scenario, row in held_out.items()} == {
        "shockwave": "1",
        "freeflow": "1",
    }
    # three folds of two dates are refused before anything is simulated, naming the dates
    too_many = run_cli(
        "sim", "select", "--drives", str(drives), "--folds", "3", "--out", str(out), env=cli_env()
    )
    assert too_many.returncode != 0
    assert "2 dates (2021-04-05, 2021-04-07): too few for 3 folds" in too_many.stderr
    assert "Traceback" not in too_many.stderr
    # a planner window the planner would refuse, likewise before any simulation
    too_wide = run_cli(
        "sim",
        "select",
        "--drives",
        str(drives),
        "--window",
        "30000",
        "--folds",
        "2",
        "--out",
        str(out),
        env=cli_env(),
    )
    assert too_wide.returncode != 0
    assert "--window: planner parameter window_m" in too_wide.stderr
