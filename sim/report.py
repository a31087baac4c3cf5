"""Evaluation outputs: the CSV of every run, the heatmap of KPI changes, the printed table.

The heatmap mirrors the paper's controller-freeze figure: one panel per scenario, Speed Planner
variants across the top, Vehicle Controllers in rows, KPIs in columns; green is better than the
all-human baseline, white neutral, red worse (the colour follows each KPI's good direction, the
number printed is the plain percentage change).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from rich.table import Table

from sim.evaluate import KPI_DIRECTION, Evaluation
from sim.kpi import PAPER_KPIS
from sim.platoon import PlatoonRun

# KPIs drawn in the heatmap: the paper's three and comfort.
HEATMAP_KPIS = (*PAPER_KPIS, "accel_rms_mps2")
KPI_LABELS = {
    "fuel_economy_mpg": "fuel economy",
    "throughput_vph": "throughput",
    "network_speed_mps": "network speed",
    "accel_rms_mps2": "accel RMS",
    "jerk_rms_mps3": "jerk RMS",
    "min_gap_m": "min gap",
    "min_ttc_s": "min TTC",
}
# Changes of this size or more get the strongest colour.
COLOUR_SCALE_PCT = 10.0


def write_csv(evaluation: Evaluation, path: Path) -> None:
    """One row per run, absolute KPIs and changes against its baseline."""
    write_rows(evaluation.rows(), path)


def write_rows(rows: Sequence[Mapping[str, Any]], path: Path) -> None:
    """Rows of one shape as a CSV with a header."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


SUMMARY_COLUMNS = (
    "scenario",
    "planner",
    "controller",
    "AVs",
    "drives",
    "fuel saving",
    "of optimum",
    "throughput",
    "network speed",
    "accel RMS",
    "collisions",
    "takeovers",
    "cut-ins",
    "max AV gap",
    "in bounds",
    "in reachable bounds",
    "distance lost",
)


def _summary_cells(row: dict[str, Any]) -> list[str]:
    optimum = row["optimum_fuel_saving_pct"]
    share = (
        f"{100.0 * row['fuel_saving_pct'] / optimum:.0f} %"
        if math.isfinite(optimum) and optimum > 0
        else "n/a"
    )
    return [
        row["scenario"],
        row["planner"],
        row["controller"] + (" (recommended)" if row["recommended"] else ""),
        str(row["avs"]),
        str(row["cases"]),
        percent_text(row["fuel_saving_pct"]),
        share,
        percent_text(row["throughput_vph_change_pct"]),
        percent_text(row["network_speed_mps_change_pct"]),
        percent_text(row["accel_rms_mps2_change_pct"]),
        str(row["collisions"]),
        str(row["takeovers"]),
        str(row["cut_ins"]),
        f"{row['max_av_gap_m']:.0f} m",
        f"{100.0 * row['within_bounds_share']:.1f} %",
        f"{100.0 * row['within_reachable_bounds_share']:.1f} %",
        f"{row['distance_lost_m']:+.0f} m",
    ]


def summary_table(evaluation: Evaluation) -> Table:
    """Mean changes per scenario x planner x controller x AVs, for the terminal."""
    table = Table(title="KPI change vs all-human baseline (mean over the scenario's drives)")
    for column in SUMMARY_COLUMNS:
        table.add_column(column, justify="left" if column in ("scenario", "planner") else "right")
    for row in evaluation.summary():
        table.add_row(*_summary_cells(row))
    return table


def markdown_table(evaluation: Evaluation) -> str:
    """The same summary as a Markdown table (for docs/simulation.md)."""
    header = (
        "| "
        + " | ".join(SUMMARY_COLUMNS)
        + " |\n|---|---|---|"
        + "---:|" * (len(SUMMARY_COLUMNS) - 3)
        + "\n"
    )
    lines = ["| " + " | ".join(_summary_cells(row)) + " |" for row in evaluation.summary()]
    return header + "\n".join(lines) + "\n"


def percent_text(value: float) -> str:
    """A change in % for people: signed, one decimal; "n/a" where it is undefined."""
    return "n/a" if not math.isfinite(value) else f"{value:+.1f} %"


def write_heatmap(evaluation: Evaluation, path: Path) -> None:
    """PNG: one panel per scenario, controllers x (planner, KPI), green better / red worse."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import TwoSlopeNorm

    summary = evaluation.summary()
    scenarios = evaluation.scenarios()
    planners = list(dict.fromkeys(p for p, _, _ in evaluation.variants()))
    several = len({avs for _, _, avs in evaluation.variants()}) > 1
    controllers = list(
        dict.fromkeys(_row_label(c, avs, several) for _, c, avs in evaluation.variants())
    )
    columns = [(p, k) for p in planners for k in HEATMAP_KPIS]
    figure, axes = plt.subplots(
        len(scenarios),
        1,
        figsize=(1.3 * len(columns) + 3.0, 0.55 * len(controllers) * len(scenarios) + 2.2),
        squeeze=False,
    )
    norm = TwoSlopeNorm(vcenter=0.0, vmin=-COLOUR_SCALE_PCT, vmax=COLOUR_SCALE_PCT)
    for axis, scenario in zip(axes[:, 0], scenarios, strict=True):
        values = np.full((len(controllers), len(columns)), np.nan)
        for row in summary:
            if row["scenario"] != scenario:
                continue
            i = controllers.index(_row_label(row["controller"], row["avs"], several))
            for j, (planner, kpi) in enumerate(columns):
                if planner == row["planner"]:
                    values[i, j] = row[f"{kpi}_change_pct"]
        direction = np.array([KPI_DIRECTION[k] for _, k in columns], dtype=float)
        axis.imshow(values * direction, cmap="RdYlGn", norm=norm, aspect="auto")
        for i in range(len(controllers)):
            for j in range(len(columns)):
                text = "n/a" if np.isnan(values[i, j]) else f"{values[i, j]:+.1f}%"
                axis.text(j, i, text, ha="center", va="center", fontsize=8)
        axis.set_title(scenario)
        axis.set_yticks(range(len(controllers)), controllers, fontsize=8)
        axis.set_xticks(
            range(len(columns)),
            [f"{planner}\n{KPI_LABELS[kpi]}" for planner, kpi in columns],
            fontsize=7,
        )
    figure.suptitle("KPI change vs all-human baseline (green better, red worse)")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _row_label(controller: str, avs: int, several: bool) -> str:
    return f"{controller} x{avs} AVs" if several else controller


# The aims for the best pair on shockwave drives: throughput and network speed within
# -2 % of the all-human baseline, and no collision.
MAX_LOSS_PCT = -2.0


def best_pair(evaluation: Evaluation, scenario: str = "shockwave") -> dict[str, Any] | None:
    """The planner x controller with the largest fuel saving on `scenario` among those with no
    collision and throughput and network speed no worse than MAX_LOSS_PCT."""
    candidates = [
        row
        for row in evaluation.summary()
        if row["scenario"] == scenario
        and row["collisions"] == 0
        and row["throughput_vph_change_pct"] >= MAX_LOSS_PCT
        and row["network_speed_mps_change_pct"] >= MAX_LOSS_PCT
        and math.isfinite(row["fuel_saving_pct"])  # a saving no drive measured ranks nowhere
    ]
    return max(candidates, key=lambda row: row["fuel_saving_pct"], default=None)


def write_time_space(
    runs: Sequence[tuple[str, PlatoonRun]], path: Path, title: str, speed_max_mps: float = 35.0
) -> None:
    """PNG: one time-space panel per run (position vs time of every vehicle, coloured by
    speed); AV trajectories drawn thicker and outlined, cars that merged in dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize

    figure, axes = plt.subplots(
        1, len(runs), figsize=(6.5 * len(runs), 5.5), sharey=True, squeeze=False
    )
    norm = Normalize(0.0, speed_max_mps)
    image = None
    for axis, (label, run) in zip(axes[0], runs, strict=True):
        time_s = run.time_s
        tracks = [
            (run.position_m[:, i], run.speed_mps[:, i], bool(run.is_av[i]), False)
            for i in range(run.position_m.shape[1])
        ]
        if run.cut_in_position_m is not None and run.cut_in_speed_mps is not None:
            tracks += [
                (run.cut_in_position_m[:, i], run.cut_in_speed_mps[:, i], False, True)
                for i in range(run.cut_ins)
            ]
        for position, speed, is_av, merged in tracks:
            present = np.isfinite(position)
            points = np.column_stack([time_s[present], position[present] / 1000.0])
            segments = np.stack([points[:-1], points[1:]], axis=1)
            if is_av:
                axis.plot(points[:, 0], points[:, 1], color="black", linewidth=3.0, zorder=2)
            lines = LineCollection(
                list(segments),
                cmap="RdYlGn",
                norm=norm,
                linewidths=1.8 if is_av else 0.7,
                linestyles="dashed" if merged else "solid",
                zorder=3 if is_av else 1,
            )
            lines.set_array(speed[present][:-1])
            image = axis.add_collection(lines)
        axis.set_xlim(0.0, float(time_s[-1]))
        axis.set_ylim(
            float(np.nanmin(run.position_m)) / 1000.0, float(np.nanmax(run.position_m)) / 1000.0
        )
        axis.set_title(label)
        axis.set_xlabel("time since the drive's start (s)")
    axes[0][0].set_ylabel("position along the drive (km)")
    if image is not None:
        figure.colorbar(image, ax=axes[0].tolist(), label="speed (m/s)")
    figure.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
