"""The TSE quality report on the real drives: MAE of INRIX alone, predicted, fused.

    .venv/bin/python -m bench.planner_quality [--shared ../shared] [--latency 180]

(as a module: run as a script, bench/planner.py would shadow the `planner` package)

Prints one row per drive and the pooled mean absolute error (m/s) of each variant against the
probe car's 60 s mean speeds (protocol in planner/evaluation.py; figures in docs/planner.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from app.seed import seed_corridor_document
from planner.evaluation import VARIANTS, evaluate_drive
from planner.pipeline import parse_params
from planner.recorded import CorridorFrame

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    parser.add_argument("--latency", type=float, default=180.0, help="INRIX delay (s)")
    parser.add_argument("--param", action="append", default=[], help="name=value override")
    args = parser.parse_args()
    overrides = dict(item.split("=", 1) for item in args.param)
    params = parse_params(overrides)

    frame = CorridorFrame.of(seed_corridor_document())

    folders = sorted((args.shared / "data/trajectories_with_inrix").iterdir())
    pooled: dict[str, list[float]] = {variant: [] for variant in VARIANTS}
    print(f"latency {args.latency:.0f} s, params {overrides or 'defaults'}")
    print(f"{'drive':58s} " + " ".join(f"{variant:>22s}" for variant in VARIANTS))
    for folder in folders:
        recorded = frame.load(folder)
        errors = evaluate_drive(
            recorded.drive, recorded.inrix, frame.grid, params, latency_s=args.latency
        )
        for variant in VARIANTS:
            pooled[variant].extend(np.abs(errors.estimates_mps[variant] - errors.truth_mps))
        print(
            f"{recorded.name:58s} "
            + " ".join(f"{errors.mean_absolute_error(variant):22.3f}" for variant in VARIANTS)
        )
    print(
        f"{'all decision times':58s} " + " ".join(f"{np.mean(pooled[v]):22.3f}" for v in VARIANTS)
    )


if __name__ == "__main__":
    main()
