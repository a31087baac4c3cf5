"""Figures rendered on the server with matplotlib (a dependency already), served as PNG inside
the page: no script library and no CDN. Figures are drawn on their own `Figure` (never pyplot's
global state), so concurrent requests do not share one. Each figure's axes fit its data; times
are local.

`time_space` is the paper's time-space view (Fig. "Bulk fuel consumption heatmap" with the AV
overlay): postmile against time with a speed field as the heatmap and every fleet car's
trajectory on top, red while its controller was engaged and white while not.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from zoneinfo import ZoneInfo

import numpy as np
from markupsafe import Markup
from matplotlib.collections import LineCollection
from matplotlib.colors import LinearSegmentedColormap
from matplotlib.figure import Figure
from numpy.typing import NDArray

from contract.units import MPH_PER_MPS
from dashboards.charts import SPEED_STOPS, chart, local_time_ticks

ENGAGED_COLOUR = "#e11d48"
NOT_ENGAGED_COLOUR = "#ffffff"
NO_DATA_COLOUR = "#e5e7eb"
SPEED_MAP = LinearSegmentedColormap.from_list("speed", list(SPEED_STOPS)).with_extremes(
    bad=NO_DATA_COLOUR
)


@dataclass(frozen=True)
class Trajectory:
    """One car's path: epoch seconds, postmiles and whether its controller was engaged."""

    vehicle_id: str
    times_s: NDArray[np.float64]
    postmiles: NDArray[np.float64]
    engaged: NDArray[np.bool_]


def trajectory_pieces(
    trajectory: Trajectory, max_gap_s: float
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The line pieces of a trajectory as ((t0, x0), (t1, x1)) pairs and whether each piece was
    engaged (at its start); pieces across a gap in the pings or a jump backwards (a car that
    re-enters the corridor at its start) are left out."""
    t, x = trajectory.times_s, trajectory.postmiles
    if len(t) < 2:
        return np.empty((0, 2, 2)), np.empty(0, dtype=np.bool_)
    keep = (np.diff(t) <= max_gap_s) & (np.diff(x) >= 0.0)
    starts = np.stack([t[:-1], x[:-1]], axis=-1)[keep]
    ends = np.stack([t[1:], x[1:]], axis=-1)[keep]
    return np.stack([starts, ends], axis=1), trajectory.engaged[:-1][keep]


def time_space(
    chart_id: str,
    title: str,
    field_mps: NDArray[np.float64] | None,
    time_range: tuple[datetime, datetime],
    postmile_range: tuple[float, float],
    trajectories: Sequence[Trajectory],
    zone: ZoneInfo,
    speed_upper_mph: float,
    field_label: str,
    max_gap_s: float,
) -> Markup:
    """The time-space view as an <img>; field_mps[row = postmile, column = time] or None."""
    figure = Figure(figsize=(10.0, 4.6), layout="constrained")
    axes = figure.add_subplot()
    start, end = (moment.timestamp() for moment in time_range)
    low, high = postmile_range
    if field_mps is not None:
        image = axes.imshow(
            np.ma.masked_invalid(field_mps * MPH_PER_MPS),
            origin="lower",
            aspect="auto",
            extent=(start, end, low, high),
            cmap=SPEED_MAP,
            vmin=0.0,
            vmax=speed_upper_mph,
            interpolation="nearest",
        )
        figure.colorbar(image, ax=axes, label=f"{field_label} (mph)", pad=0.01)
    else:
        axes.set_facecolor(NO_DATA_COLOUR)
    for trajectory in trajectories:
        pieces, engaged = trajectory_pieces(trajectory, max_gap_s)
        if not len(pieces):
            continue
        colours = np.where(engaged, ENGAGED_COLOUR, NOT_ENGAGED_COLOUR)
        axes.add_collection(LineCollection(list(pieces), colors="#111827", linewidths=2.4))
        axes.add_collection(LineCollection(list(pieces), colors=list(colours), linewidths=1.3))
    axes.set_xlim(start, end)
    axes.set_ylim(low, high)
    ticks = local_time_ticks(start, end, zone)
    axes.set_xticks(list(ticks), list(ticks.values()))
    axes.set_xlabel(f"local time ({time_range[0].astimezone(zone).tzname()})")
    axes.set_ylabel("postmile (direction of travel ↑)")
    axes.set_title(title, fontsize=11)
    return chart(chart_id, figure)
