"""Fingerprints of simulated runs, so a change made for speed can show it changed no result.

    .venv/bin/python -m bench.run_fingerprints OUT.json [--compare BEFORE.json]

(as a module, like the other benches)

Every registered controller and the all-human baseline, with 1 and with 4 AVs, under the
recommended planner, on two cases of each scenario (its first and its middle drive): 140 runs.
Each run's fingerprint is the sha256 of every vehicle's final position (one difference in any
step of any car moves them) and the repr of its KPIs. Run it at the commit before a change and
at the change, then `--compare` the two files: a speed-up is only one if they are equal. A run
takes about 4 minutes on two idle cores.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.drives import load_drives, shared_data_dir
from sim.evaluate import run_case
from sim.recommended import registered_variants
from sim.recorded import load_recorded_drives
from sim.scenarios import SCENARIOS, Case, scenario_cases

PLATOON = 25
AV_COUNTS = (1, 4)


def chosen_cases() -> list[Case]:
    """The first and the middle case of every scenario on the shared data."""
    data = shared_data_dir()
    cases = scenario_cases(
        list(SCENARIOS),
        load_drives(data / "trajectories"),
        load_recorded_drives(data / "trajectories_with_inrix"),
    )
    by_scenario: dict[str, list[Case]] = {}
    for case in cases:
        by_scenario.setdefault(case.scenario, []).append(case)
    return [runs[i] for runs in by_scenario.values() for i in sorted({0, len(runs) // 2})]


def fingerprints() -> dict[str, list[str]]:
    """`case|AVs|controller` -> [sha256 of the final positions (16 hex), repr of the KPIs]."""
    found: dict[str, list[str]] = {}
    for case in chosen_cases():
        for avs in AV_COUNTS:
            for variant in [None, *registered_variants()]:
                result = run_case(
                    case,
                    RECOMMENDED_PLANNER,
                    variant,
                    humans=PLATOON - avs,
                    avs=avs,
                    planner_params=RECOMMENDED_PLANNER_PARAMS,
                )
                positions = np.asarray(result.final_position_m, dtype=np.float64).tobytes()
                name = "baseline" if variant is None else variant.name
                found[f"{case.name}|{avs}|{name}"] = [
                    hashlib.sha256(positions).hexdigest()[:16],
                    repr(result.kpis),
                ]
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="where to write this commit's fingerprints")
    parser.add_argument("--compare", type=Path, help="fingerprints of the commit before")
    args = parser.parse_args()
    found = fingerprints()
    args.out.write_text(json.dumps(found, indent=0))
    print(f"{len(found)} runs fingerprinted into {args.out}")
    if args.compare is not None:
        before = json.loads(args.compare.read_text())
        differing = sorted(
            key for key in before.keys() | found.keys() if before.get(key) != found.get(key)
        )
        for key in differing:
            print(f"differs: {key}")
        print(f"{len(before)} runs before, {len(found)} now, {len(differing)} differ")
        if differing:
            sys.exit(1)


if __name__ == "__main__":
    main()
