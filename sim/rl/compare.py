"""Held-out figures of trained policies side by side, from their manifests alone.

`smoothfleet sim train` writes every held-out drive's score into the policy's manifest
(`cross_validation.drives`). Comparing two rules of training (or one rule over several seeds)
needs only those rows: each manifest's group means (`sim.rl.scores.summarise`, the groups the
issue names), and, for manifests given in pairs (BASE OTHER ...), the paired differences
OTHER - BASE per pair and their mean, so a change can be read against what a seed alone moves.
Nothing is simulated again.

    python -m sim.rl.compare BASE.json OTHER.json [BASE2.json OTHER2.json ...] --paired
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sim.rl.scores import GROUPS, DriveScore, summarise

# The figures compared per group: fuel saving, then the two changes the issue bounds.
FIGURES = ("fuel_saving_pct", "throughput_change_pct", "network_speed_change_pct")


class ManifestError(ValueError):
    """A file that is not a trained policy's manifest with held-out scores."""


def policy_scores(manifest: Mapping[str, Any], source: str) -> list[DriveScore]:
    """The held-out scores of the manifest's own policy (not the reference controller scored
    beside it)."""
    try:
        rows = manifest["cross_validation"]["drives"]
        controller = f"rl_{manifest['actuation']}"
        scores = [DriveScore(**row) for row in rows]
    except (KeyError, TypeError) as error:
        raise ManifestError(f"{source}: no held-out drive scores ({error})") from None
    own = [score for score in scores if score.controller == controller]
    if not own:
        raise ManifestError(f"{source}: no held-out drive scored for {controller}")
    return own


def group_figures(scores: Sequence[DriveScore]) -> dict[str, dict[str, Any]]:
    """Group name -> its `summarise` row, plus `within_mean`: the mean share of time within the
    gap envelope over every drive."""
    rows = {row["group"]: row for row in summarise(scores)}
    rows["all"] = {"within_mean": float(np.mean([s.gap_within_share for s in scores]))}
    return rows


def paired_differences(
    bases: Sequence[Mapping[str, Mapping[str, Any]]],
    others: Sequence[Mapping[str, Mapping[str, Any]]],
) -> list[dict[str, float]]:
    """(group, figure) -> OTHER - BASE, one mapping per pair, keyed `group figure`."""
    return [
        {
            f"{group} {figure}": float(other[group][figure]) - float(base[group][figure])
            for group in GROUPS
            if group in base and group in other
            for figure in FIGURES
        }
        for base, other in zip(bases, others, strict=True)
    ]


def _row(cells: Sequence[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def _signed(value: float) -> str:
    return "n/a" if math.isnan(value) else f"{value:+.2f}"


def main(argv: Sequence[str] | None = None) -> None:
    """Print the manifests' group means (and, with --paired, the paired differences) as
    Markdown tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("manifests", nargs="+", type=Path, help="rl_acc(el).json manifests")
    parser.add_argument(
        "--paired",
        action="store_true",
        help="the manifests are pairs BASE OTHER: also print OTHER - BASE per pair and the mean",
    )
    args = parser.parse_args(argv)
    say = print  # noqa: T201 (a command-line report)
    if args.paired and len(args.manifests) % 2:
        parser.error(f"--paired takes pairs: {len(args.manifests)} manifests given")
    figures = []
    for path in args.manifests:
        try:
            manifest = json.loads(path.read_text())
            figures.append(
                (
                    manifest.get("sha256", "?")[:12],
                    group_figures(policy_scores(manifest, str(path))),
                )
            )
        except (OSError, json.JSONDecodeError, ManifestError) as error:
            parser.error(str(error))
    columns = [f"{group} {figure}" for group in GROUPS for figure in FIGURES]
    say(_row(["manifest", "sha256", *columns, "least in bounds", "mean in bounds"]))
    say(_row(["---"] * (len(columns) + 4)))
    for path, (sha, groups) in zip(args.manifests, figures, strict=True):
        means = [_signed(groups[g][f]) if g in groups else "-" for g in GROUPS for f in FIGURES]
        least = "/".join(
            f"{100 * groups[g]['min_gap_within_share']:.1f}" for g in GROUPS if g in groups
        )
        within = f"{100 * groups['all']['within_mean']:.2f}"
        say(_row([str(path), sha, *means, least, within]))
    if not args.paired:
        return
    differences = paired_differences(
        [groups for _, groups in figures[0::2]], [groups for _, groups in figures[1::2]]
    )
    say()
    say(_row(["OTHER - BASE", *columns]))
    say(_row(["---"] * (len(columns) + 1)))
    for index, difference in enumerate(differences):
        say(_row([f"pair {index + 1}", *(_signed(difference.get(c, math.nan)) for c in columns)]))
    mean = [float(np.mean([d.get(c, math.nan) for d in differences])) for c in columns]
    say(_row(["mean", *(_signed(value) for value in mean)]))


if __name__ == "__main__":
    main()
