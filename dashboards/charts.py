"""Charts drawn on the server by matplotlib (a dependency already): line, bar and heatmap, with
axes, units and legends, served inside the page as PNG (no script library, no CDN).

Conventions: the x axis of a road chart is postmile increasing to the right (the direction of
travel); a time-space heatmap has time to the right and postmile upward, as in the paper's
figures; speed scales run red (slow, congested) to green (free flow). Axes fit their data (a
single point gets room on both sides); time axes are labelled in the zone people read
(`dashboard_timezone`). Each chart is drawn on its own `Figure`, never pyplot's global state, so
concurrent requests do not share one.
"""

from __future__ import annotations

import base64
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from datetime import datetime
from typing import Literal
from zoneinfo import ZoneInfo

import numpy as np
from markupsafe import Markup, escape
from matplotlib.axes import Axes
from matplotlib.colors import Colormap, LinearSegmentedColormap
from matplotlib.figure import Figure
from numpy.typing import NDArray
from starlette.concurrency import run_in_threadpool

WIDTH_IN = 7.6
HEIGHT_IN = 3.0
DPI = 100
PALETTE = ("#2563eb", "#dc2626", "#16a34a", "#9333ea", "#ea580c", "#0891b2", "#4b5563")
NO_DATA_COLOUR = "#e5e7eb"

# Red (slow) -> yellow -> green (fast): the usual reading of traffic speed maps.
SPEED_STOPS: tuple[tuple[float, str], ...] = (
    (0.0, "#a50026"),
    (0.25, "#f46d43"),
    (0.5, "#fee08b"),
    (0.75, "#a6d96a"),
    (1.0, "#1a9850"),
)
# Light (low) -> dark (high) for quantities without a "good" direction (density, fuel).
AMOUNT_STOPS: tuple[tuple[float, str], ...] = (
    (0.0, "#fff7ec"),
    (0.33, "#fdbb84"),
    (0.66, "#ef6548"),
    (1.0, "#7f0000"),
)
# A lone point on a time axis gets this much room on each side (s).
LONE_TIME_PAD_S = 1800.0
TICK_STEPS_MIN = (1, 2, 5, 10, 15, 30, 60, 120, 180, 360, 720, 1440)

UTC_ZONE = ZoneInfo("UTC")  # time axes of charts given no zone

AxisKind = Literal["linear", "time"]


@dataclass(frozen=True)
class Axis:
    """An axis: its label (with unit), whether it shows epoch seconds as clock times, bounds."""

    label: str
    kind: AxisKind = "linear"
    lower: float | None = None
    upper: float | None = None


@dataclass(frozen=True)
class Series:
    """A named line of (x, y) points; None in y is a gap."""

    name: str
    x: Sequence[float]
    y: Sequence[float | None]
    colour: str = ""
    style: Literal["line", "step", "points"] = "line"
    dashed: bool = False


@dataclass(frozen=True)
class Band:
    """A shaded x range (engaged time, a buffer region)."""

    start: float
    end: float
    colour: str = "#fde68a"


@dataclass(frozen=True)
class ColourScale:
    """Values from `lower` to `upper` mapped onto colour stops; outside values clamp."""

    lower: float
    upper: float
    label: str
    stops: tuple[tuple[float, str], ...] = SPEED_STOPS

    @property
    def colour_map(self) -> Colormap:
        """The stops as a matplotlib colour map, NaN drawn as "no data" grey."""
        return LinearSegmentedColormap.from_list(self.label, list(self.stops)).with_extremes(
            bad=NO_DATA_COLOUR
        )

    def hex(self, value: float) -> str:
        """The colour of one value as #rrggbb, interpolated between the stops (NaN: no data)."""
        if not math.isfinite(value):
            return NO_DATA_COLOUR
        span = self.upper - self.lower if self.upper > self.lower else 1.0
        fraction = min(max((value - self.lower) / span, 0.0), 1.0)
        positions = [stop[0] for stop in self.stops]
        channels = [
            round(
                float(
                    np.interp(
                        fraction,
                        positions,
                        [int(c[1 + 2 * k : 3 + 2 * k], 16) for _, c in self.stops],
                    )
                )
            )
            for k in range(3)
        ]
        return "#" + "".join(f"{channel:02x}" for channel in channels)


def local_time_ticks(start_s: float, end_s: float, zone: ZoneInfo) -> dict[float, str]:
    """Ticks on whole local minutes, 4 to 8 of them, labelled HH:MM in `zone` (with the date
    when the span crosses midnight)."""
    span_min = max((end_s - start_s) / 60.0, 1.0)
    step = next((s for s in TICK_STEPS_MIN if span_min / s <= 8), TICK_STEPS_MIN[-1])
    offset = datetime.fromtimestamp(start_s, zone).utcoffset()
    shift = 0.0 if offset is None else offset.total_seconds()
    # local minutes since the epoch, rounded up to the step (zones shift by whole minutes)
    tick = math.ceil((start_s + shift) / 60.0 / step) * step * 60.0 - shift
    days = {datetime.fromtimestamp(t, zone).date() for t in (start_s, end_s)}
    shape = "%m-%d %H:%M" if len(days) > 1 else "%H:%M"
    ticks = {}
    while tick <= end_s:
        ticks[tick] = datetime.fromtimestamp(tick, zone).strftime(shape)
        tick += step * 60.0
    return ticks


def fit(
    values: Sequence[float], lower: float | None, upper: float | None, *, time: bool = False
) -> tuple[float, float]:
    """Axis bounds that hold the data (given bounds win); a lone value gets room both sides."""
    finite = [v for v in values if v is not None and math.isfinite(v)]
    low = lower if lower is not None else (min(finite) if finite else 0.0)
    high = upper if upper is not None else (max(finite) if finite else 1.0)
    if high <= low:
        pad = LONE_TIME_PAD_S if time else max(abs(low) * 0.1, 0.5)
        low, high = (low - pad if lower is None else low), high + pad
    return low, high


def _figure(height_in: float = HEIGHT_IN) -> tuple[Figure, Axes]:
    figure = Figure(figsize=(WIDTH_IN, height_in), dpi=DPI, layout="constrained")
    return figure, figure.add_subplot()


def _label_x(axes: Axes, axis: Axis, low: float, high: float, zone: ZoneInfo) -> None:
    axes.set_xlim(low, high)
    if axis.kind == "time":
        ticks = local_time_ticks(low, high, zone)
        axes.set_xticks(list(ticks), list(ticks.values()))
        axes.set_xlabel(f"{axis.label} ({datetime.fromtimestamp(low, zone).tzname()})")
    else:
        axes.set_xlabel(axis.label)


async def drawn(chart_id: str, figure: Callable[[], Figure]) -> Markup:
    """`chart` of the figure `figure()` builds, both on a worker thread: matplotlib holds the
    CPU for about 0.1 s a figure (`python -m bench.charts`), and on the event loop, which the
    dashboard shares with the ingest API, every ping arriving meanwhile would wait for it
    (`python -m bench.dashboard`, its last table)."""
    return await run_in_threadpool(lambda: chart(chart_id, figure()))


def chart(chart_id: str, figure: Figure) -> Markup:
    """The figure as an <img> carrying its PNG, its id, and its title as alternative text."""
    title = "; ".join(axes.get_title() for axes in figure.axes if axes.get_title())
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=DPI)
    encoded = base64.b64encode(buffer.getvalue()).decode("ascii")
    return Markup(
        f'<img class="chart" data-chart="{escape(chart_id)}" alt="{escape(title)}" '
        f'title="{escape(title)}" src="data:image/png;base64,{encoded}">'
    )


def line_figure(
    title: str,
    series: Sequence[Series],
    x_axis: Axis,
    y_axis: Axis,
    *,
    bands: Sequence[Band] = (),
    band_label: str = "",
    zone: ZoneInfo = UTC_ZONE,
    height: int = 300,
) -> Figure:
    """Lines (or steps, or points) over a shared x axis, with shaded bands and a legend."""
    figure, axes = _figure(height / DPI)
    xs = [x for s in series for x in s.x]
    ys = [y for s in series for y in s.y if y is not None]
    x_low, x_high = fit(xs, x_axis.lower, x_axis.upper, time=x_axis.kind == "time")
    y_low, y_high = fit(ys, y_axis.lower, y_axis.upper)
    if y_axis.upper is None:
        y_high = y_low + (y_high - y_low) * 1.08
    # One collection per colour, however many bands: a car whose engagement flickers shades
    # hundreds of stretches, and with one patch each the speed chart took 483-598 ms for 600
    # stretches against 92-113 ms for none (`python -m bench.charts`, docs/performance.md).
    for index, colour in enumerate(dict.fromkeys(band.colour for band in bands)):
        axes.broken_barh(
            [(band.start, band.end - band.start) for band in bands if band.colour == colour],
            (0.0, 1.0),
            transform=axes.get_xaxis_transform(),  # x in data, y the axes' full height
            color=colour,
            alpha=0.45,
            linewidth=0,
            label=band_label if index == 0 and band_label else None,
        )
    for index, one in enumerate(series):
        colour = one.colour or PALETTE[index % len(PALETTE)]
        y = np.array([np.nan if v is None else v for v in one.y], dtype=np.float64)
        if one.style == "points":
            axes.plot(one.x, y, "o", color=colour, markersize=4, label=one.name)
        else:
            axes.plot(
                one.x,
                y,
                color=colour,
                linewidth=1.8,
                linestyle="--" if one.dashed else "-",
                drawstyle="steps-post" if one.style == "step" else "default",
                label=one.name,
            )
    _label_x(axes, x_axis, x_low, x_high, zone)
    axes.set_ylim(y_low, y_high)
    axes.set_ylabel(y_axis.label)
    axes.set_title(title, fontsize=10)
    axes.grid(alpha=0.3)
    # Beside the axes, where it hides no data; "best" inside them searches every point and
    # band for a free corner on each draw (bench.charts).
    axes.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return figure


def over_time_figure(
    title: str,
    series: Series,
    x_axis: Axis,
    y_axis: Axis,
    *,
    zone: ZoneInfo = UTC_ZONE,
    height: int = 240,
) -> Figure:
    """One quantity over time, drawn as points while there are fewer than three of them (a
    line through one or two values hides them)."""
    style: Literal["points", "line"] = "points" if len(series.x) < 3 else "line"
    return line_figure(
        title, [replace(series, style=style)], x_axis, y_axis, height=height, zone=zone
    )


def bar_figure(
    title: str,
    labels: Sequence[str],
    values: Sequence[float | None],
    x_label: str,
    y_axis: Axis,
    *,
    value_format: str = "{:.0f}",
    colour: str = PALETTE[0],
    height: int = 300,
) -> Figure:
    """One bar per label (each label once), each with its value written above it."""
    figure, axes = _figure(height / DPI)
    heights = [0.0 if v is None or not math.isfinite(v) else v for v in values]
    positions = np.arange(len(labels))
    bars = axes.bar(positions, heights, width=0.7, color=colour)
    if len(labels) <= 31:
        axes.bar_label(
            bars,
            labels=[
                "" if v is None or not math.isfinite(v) else value_format.format(v) for v in values
            ],
            fontsize=8,
        )
    every = max(1, math.ceil(len(labels) / 15))
    axes.set_xticks(positions[::every], list(labels)[::every])
    axes.set_xlim(-0.6, len(labels) - 0.4)
    low, high = fit([0.0, *heights], y_axis.lower, y_axis.upper)
    axes.set_ylim(low, high if y_axis.upper is not None else low + (high - low) * 1.12)
    axes.set_xlabel(x_label)
    axes.set_ylabel(y_axis.label)
    # Room above the axes for a value label at a fixed top (100 %), which wrote over the title.
    axes.set_title(title, fontsize=10, pad=14)
    axes.grid(axis="y", alpha=0.3)
    return figure


def heatmap_figure(
    title: str,
    values: NDArray[np.float64],
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    x_axis: Axis,
    y_axis: Axis,
    scale: ColourScale,
    *,
    zone: ZoneInfo = UTC_ZONE,
    height: int = 340,
) -> Figure:
    """A regular grid of cells (values[row, column], row 0 at the bottom) with a colour bar.

    NaN cells are "no data" (grey, and said so under the colour bar).
    """
    figure, axes = _figure(height / DPI)
    image = axes.imshow(
        np.ma.masked_invalid(values),
        origin="lower",
        aspect="auto",
        extent=(x_range[0], x_range[1], y_range[0], y_range[1]),
        cmap=scale.colour_map,
        vmin=scale.lower,
        vmax=scale.upper,
        interpolation="nearest",
    )
    bar = figure.colorbar(image, ax=axes, pad=0.01)
    bar.set_label(scale.label)
    if np.isnan(values).any():
        bar.ax.set_xlabel("grey: no data", fontsize=7)
    _label_x(axes, x_axis, x_range[0], x_range[1], zone)
    axes.set_ylabel(y_axis.label)
    axes.set_title(title, fontsize=10)
    return figure
