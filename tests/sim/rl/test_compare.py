"""Held-out figures of trained policies compared from their manifests (`sim.rl.compare`)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from sim.rl.compare import (
    ManifestError,
    group_figures,
    main,
    paired_differences,
    policy_scores,
)


def score(
    drive: str, kind: str, stop_and_go: bool, controller: str, fuel: float, within: float = 1.0
) -> dict[str, Any]:
    """A manifest's drive row (`DriveScore.as_dict`); throughput is half the fuel saving and
    network speed a tenth, so every figure of a group follows from its fuel by hand."""
    return {
        "drive": drive,
        "date": drive[:10],
        "kind": kind,
        "stop_and_go": stop_and_go,
        "controller": controller,
        "fuel_saving_pct": fuel,
        "throughput_change_pct": fuel / 2,
        "network_speed_change_pct": fuel / 10,
        "accel_rms_change_pct": 0.0,
        "collisions": 0,
        "gap_within_share": within,
    }


def manifest(sha: str, fuels: tuple[float, float, float]) -> dict[str, Any]:
    """rl_accel on a stop-and-go drive, another shockwave drive and a freeflow one (fuel as
    given), and the reference controller beside it on the first, which must not count."""
    stop, wave, free = fuels
    return {
        "sha256": sha,
        "actuation": "accel",
        "cross_validation": {
            "drives": [
                score("2021-03-15-a", "shockwave", True, "rl_accel", stop, within=0.99),
                score("2021-03-15-a", "shockwave", True, "microaccel", 40.0, within=0.1),
                score("2021-04-05-b", "shockwave", False, "rl_accel", wave),
                score("2021-04-07-c", "freeflow", False, "rl_accel", free, within=0.97),
            ]
        },
    }


def test_group_means_count_only_the_manifests_own_policy() -> None:
    groups = group_figures(policy_scores(manifest("aa", (2.0, 1.0, -0.4)), "m.json"))
    # stop-and-go: the one drive; shockwave: both (2.0 and 1.0); freeflow: the last
    assert groups["stop_and_go"]["fuel_saving_pct"] == pytest.approx(2.0)
    assert groups["shockwave"]["fuel_saving_pct"] == pytest.approx(1.5)
    assert groups["shockwave"]["throughput_change_pct"] == pytest.approx(0.75)
    assert groups["freeflow"]["network_speed_change_pct"] == pytest.approx(-0.04)
    assert groups["shockwave"]["min_gap_within_share"] == pytest.approx(0.99)
    assert groups["all"]["within_mean"] == pytest.approx((0.99 + 1.0 + 0.97) / 3)


def test_a_manifest_written_before_the_reachable_share_reads_it_as_unknown() -> None:
    """Manifests of policies trained before `gap_within_reachable_share` existed (the shipped
    ones) load with it undefined, and a group's worst is undefined with them, never 0 % or
    100 %; one that has it gives its worst drive's."""
    old = group_figures(policy_scores(manifest("aa", (2.0, 1.0, -0.4)), "old.json"))
    assert math.isnan(old["shockwave"]["min_gap_within_reachable_share"])
    new = manifest("bb", (2.0, 1.0, -0.4))
    for row, reachable in zip(
        new["cross_validation"]["drives"], (0.995, 0.2, 1.0, 0.98), strict=True
    ):
        row["gap_within_reachable_share"] = reachable
    groups = group_figures(policy_scores(new, "new.json"))
    assert groups["shockwave"]["min_gap_within_reachable_share"] == pytest.approx(0.995)
    assert groups["freeflow"]["min_gap_within_reachable_share"] == pytest.approx(0.98)


def test_paired_differences_are_other_minus_base_per_pair() -> None:
    base = group_figures(policy_scores(manifest("aa", (2.0, 1.0, -0.4)), "a"))
    other = group_figures(policy_scores(manifest("bb", (1.8, 1.0, -0.2)), "b"))
    [difference] = paired_differences([base], [other])
    assert difference["stop_and_go fuel_saving_pct"] == pytest.approx(-0.2)
    # shockwave: (1.8 + 1.0) / 2 - (2.0 + 1.0) / 2
    assert difference["shockwave fuel_saving_pct"] == pytest.approx(-0.1)
    assert difference["freeflow throughput_change_pct"] == pytest.approx(0.1)


def test_the_command_prints_both_tables(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    paths = []
    for index, fuels in enumerate(
        [(2.0, 1.0, -0.4), (1.8, 1.0, -0.2), (1.0, 1.0, 0.0), (0.6, 1.0, 0.0)]
    ):
        path = tmp_path / f"m{index}.json"
        path.write_text(json.dumps(manifest(f"{index:012d}", fuels)))
        paths.append(str(path))
    main([*paths, "--paired"])
    out = capsys.readouterr().out
    assert "| 000000000000 | +2.00 | +1.00 | +0.20 | +1.50 |" in out
    assert "| 99.0/99.0/97.0 | 98.67 |" in out
    # stop-and-go fuel: -0.2 and -0.4, mean -0.3
    assert "| pair 1 | -0.20 |" in out
    assert "| pair 2 | -0.40 |" in out
    assert "| mean | -0.30 |" in out


def test_a_file_without_held_out_scores_is_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    policy = tmp_path / "policy.json"
    policy.write_text(json.dumps({"sha256": "x", "actuation": "accel"}))
    with pytest.raises(ManifestError, match="no held-out drive scores"):
        policy_scores(json.loads(policy.read_text()), str(policy))
    with pytest.raises(SystemExit) as exit_code:
        main([str(policy)])
    assert exit_code.value.code == 2
    assert f"{policy}: no held-out drive scores" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([str(policy), str(policy), str(policy), "--paired"])
    assert "--paired takes pairs: 3 manifests given" in capsys.readouterr().err
