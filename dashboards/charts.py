"""Charts drawn on the server as SVG: line, bar and heatmap, with axes, units and legends.

Nothing is fetched at run time (no CDN, no JavaScript library): a page carries its charts as
inline SVG, and heatmaps embed their cells as a small PNG made here with numpy and zlib. The
layout and colour functions are pure, so tests check them directly.

Conventions: the x axis of a road chart is postmile increasing to the right (the direction of
travel); a time-space heatmap has time to the right and postmile upward, as in the paper's
figures; speed scales run red (slow, congested) to green (free flow).
"""

from __future__ import annotations

import base64
import math
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from html import escape
from typing import Literal

import numpy as np
from markupsafe import Markup
from numpy.typing import NDArray

WIDTH = 760
HEIGHT = 300
MARGIN_LEFT = 66
MARGIN_RIGHT = 20
MARGIN_TOP = 30
MARGIN_BOTTOM = 46
LEGEND_WIDTH = 96  # colour legend beside a heatmap
MAX_BAR_WIDTH = 60

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

AxisKind = Literal["linear", "time"]


@dataclass(frozen=True)
class Axis:
    """An axis: its label with the unit, linear or time (epoch seconds, shown in UTC)."""

    label: str
    kind: AxisKind = "linear"
    lower: float | None = None
    upper: float | None = None


@dataclass(frozen=True)
class Series:
    """A named line: x and y values (None breaks the line), drawn as a line or a step."""

    name: str
    x: Sequence[float]
    y: Sequence[float | None]
    colour: str = ""
    style: Literal["line", "step", "points"] = "line"
    dashed: bool = False


@dataclass(frozen=True)
class Band:
    """A shaded x range (a buffer region, a time the controller was engaged)."""

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

    def rgb(self, values: NDArray[np.float64]) -> NDArray[np.uint8]:
        """RGB per value (shape + (3,)); NaN gives the no-data grey."""
        positions = np.array([stop[0] for stop in self.stops])
        colours = np.array([hex_rgb(stop[1]) for stop in self.stops], dtype=np.float64)
        span = self.upper - self.lower if self.upper > self.lower else 1.0
        fraction = np.clip((values - self.lower) / span, 0.0, 1.0)
        fraction = np.where(np.isnan(fraction), 0.0, fraction)
        channels = [np.interp(fraction, positions, colours[:, c]) for c in range(3)]
        rgb = np.stack(channels, axis=-1)
        rgb[np.isnan(values)] = hex_rgb(NO_DATA_COLOUR)
        result: NDArray[np.uint8] = np.rint(rgb).astype(np.uint8)
        return result

    def hex(self, value: float) -> str:
        """The colour of one value as #rrggbb."""
        red, green, blue = (int(c) for c in self.rgb(np.array([value], dtype=np.float64))[0])
        return f"#{red:02x}{green:02x}{blue:02x}"


@dataclass(frozen=True)
class Frame:
    """Where the plot area sits in the SVG and how data maps onto it."""

    x_lower: float
    x_upper: float
    y_lower: float
    y_upper: float
    width: int = WIDTH
    height: int = HEIGHT
    right: int = MARGIN_RIGHT
    plot: tuple[float, float, float, float] = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "plot",
            (
                MARGIN_LEFT,
                MARGIN_TOP,
                self.width - MARGIN_LEFT - self.right,
                self.height - MARGIN_TOP - MARGIN_BOTTOM,
            ),
        )

    def px(self, x: float) -> float:
        """SVG x of a data x."""
        left, _, width, _ = self.plot
        span = self.x_upper - self.x_lower or 1.0
        return left + (x - self.x_lower) / span * width

    def py(self, y: float) -> float:
        """SVG y of a data y (up is larger)."""
        _, top, _, height = self.plot
        span = self.y_upper - self.y_lower or 1.0
        return top + height - (y - self.y_lower) / span * height


def hex_rgb(colour: str) -> tuple[int, int, int]:
    """#rrggbb as integers."""
    return int(colour[1:3], 16), int(colour[3:5], 16), int(colour[5:7], 16)


def nice_step(span: float, target_ticks: int = 6) -> float:
    """A 1-2-5 step giving about `target_ticks` ticks over `span`."""
    if span <= 0 or not math.isfinite(span):
        return 1.0
    raw = span / max(1, target_ticks)
    magnitude = 10.0 ** math.floor(math.log10(raw))
    for multiple in (1, 2, 2.5, 5, 10):
        if raw <= multiple * magnitude:
            return multiple * magnitude
    return 10 * magnitude


def linear_ticks(lower: float, upper: float, target_ticks: int = 6) -> list[float]:
    """Tick values at a 1-2-5 step inside [lower, upper]."""
    step = nice_step(upper - lower, target_ticks)
    first = math.ceil(lower / step - 1e-9) * step
    ticks = []
    value = first
    while value <= upper + step * 1e-9:
        ticks.append(round(value, 10))
        value += step
    return ticks


TIME_STEPS_S = (
    1,
    2,
    5,
    10,
    15,
    30,
    60,
    120,
    300,
    600,
    900,
    1800,
    3600,
    7200,
    10800,
    21600,
    43200,
    86400,
    172800,
    604800,
)


def time_ticks(lower: float, upper: float, target_ticks: int = 6) -> list[float]:
    """Tick times (epoch seconds) at a round clock step inside [lower, upper]."""
    span = upper - lower
    step = next((s for s in TIME_STEPS_S if span / s <= target_ticks), TIME_STEPS_S[-1])
    first = math.ceil(lower / step) * step
    return [float(t) for t in range(int(first), int(upper) + 1, step)]


def format_tick(value: float, kind: AxisKind, span: float) -> str:
    """A tick label: clock time (UTC) for time axes, trimmed numbers otherwise."""
    if kind == "time":
        moment = datetime.fromtimestamp(value, UTC)
        if span > 2 * 86400:
            return moment.strftime("%m-%d")
        if span > 600:
            return moment.strftime("%H:%M")
        return moment.strftime("%H:%M:%S")
    if abs(value) >= 1000 or value == int(value):
        return f"{value:,.0f}"
    return f"{value:g}"


def bounds(
    values: Sequence[float | None],
    lower: float | None,
    upper: float | None,
    *,
    headroom: bool = False,
) -> tuple[float, float]:
    """Axis bounds: given ones, else the data's range (a flat range is widened by 1).

    With `headroom`, a data-derived upper bound moves up to the next tick, so the highest value
    is not drawn on the frame.
    """
    finite = [v for v in values if v is not None and math.isfinite(v)]
    low = lower if lower is not None else (min(finite) if finite else 0.0)
    high = upper if upper is not None else (max(finite) if finite else 1.0)
    if high <= low:
        high = low + 1.0
    if headroom and upper is None:
        step = nice_step(high - low, 5)
        high = math.ceil((high + 0.02 * (high - low)) / step) * step
    return low, high


def _axes(frame: Frame, x_axis: Axis, y_axis: Axis, *, grid: bool = True) -> list[str]:
    left, top, width, height = frame.plot
    parts = [
        f'<rect class="plot-area" x="{left}" y="{top}" width="{width}" height="{height}" '
        'fill="white" stroke="#9ca3af"/>'
    ]
    x_span = frame.x_upper - frame.x_lower
    x_ticks = (
        time_ticks(frame.x_lower, frame.x_upper)
        if x_axis.kind == "time"
        else linear_ticks(frame.x_lower, frame.x_upper)
    )
    for tick in x_ticks:
        x = frame.px(tick)
        if grid:
            parts.append(
                f'<line x1="{x:.1f}" y1="{top}" x2="{x:.1f}" y2="{top + height}" stroke="#e5e7eb"/>'
            )
        parts.append(
            f'<text class="tick x-tick" x="{x:.1f}" y="{top + height + 16}" '
            f'text-anchor="middle">{escape(format_tick(tick, x_axis.kind, x_span))}</text>'
        )
    y_span = frame.y_upper - frame.y_lower
    for tick in linear_ticks(frame.y_lower, frame.y_upper, 5):
        y = frame.py(tick)
        if grid:
            parts.append(
                f'<line x1="{left}" y1="{y:.1f}" x2="{left + width}" y2="{y:.1f}" '
                'stroke="#e5e7eb"/>'
            )
        parts.append(
            f'<text class="tick y-tick" x="{left - 6}" y="{y + 4:.1f}" text-anchor="end">'
            f"{escape(format_tick(tick, y_axis.kind, y_span))}</text>"
        )
    parts.append(
        f'<text class="axis-label x-label" x="{left + width / 2:.1f}" y="{frame.height - 8}" '
        f'text-anchor="middle">{escape(x_axis.label)}</text>'
    )
    parts.append(
        f'<text class="axis-label y-label" transform="translate(16 {top + height / 2:.1f}) '
        f'rotate(-90)" text-anchor="middle">{escape(y_axis.label)}</text>'
    )
    return parts


def _svg(chart_id: str, title: str, frame: Frame, body: list[str]) -> Markup:
    return Markup(
        f'<svg class="chart" data-chart="{escape(chart_id)}" role="img" '
        f'aria-label="{escape(title)}" viewBox="0 0 {frame.width} {frame.height}" '
        f'xmlns="http://www.w3.org/2000/svg"><title>{escape(title)}</title>'
        + "".join(body)
        + "</svg>"
    )


def _legend(items: Sequence[tuple[str, str, bool]], frame: Frame) -> list[str]:
    """Swatches above the plot, right-aligned: (name, colour, is_band)."""
    parts = []
    x = frame.width - frame.right
    for name, colour, is_band in reversed(items):
        text_width = 7 * len(name)
        x -= text_width + 26
        swatch = (
            f'<rect x="{x}" y="9" width="14" height="10" fill="{colour}" opacity="0.6"/>'
            if is_band
            else f'<line x1="{x}" y1="14" x2="{x + 14}" y2="14" stroke="{colour}" '
            'stroke-width="3"/>'
        )
        parts.append(
            f'<g class="legend-item">{swatch}<text x="{x + 18}" y="18">{escape(name)}</text></g>'
        )
    return parts


def _path(series: Series, frame: Frame) -> str:
    commands: list[str] = []
    pen_down = False
    previous_y: float | None = None
    for x, y in zip(series.x, series.y, strict=True):
        if y is None or not math.isfinite(y):
            pen_down = False
            continue
        px, py = frame.px(x), frame.py(y)
        if not pen_down:
            commands.append(f"M{px:.1f},{py:.1f}")
        elif series.style == "step" and previous_y is not None:
            commands.append(f"H{px:.1f}V{py:.1f}")
        else:
            commands.append(f"L{px:.1f},{py:.1f}")
        pen_down = True
        previous_y = py
    return "".join(commands)


def line_chart(
    chart_id: str,
    title: str,
    series: Sequence[Series],
    x_axis: Axis,
    y_axis: Axis,
    *,
    bands: Sequence[Band] = (),
    band_label: str = "",
    width: int = WIDTH,
    height: int = HEIGHT,
) -> Markup:
    """Lines (or steps, or points) over a shared x axis, with shaded bands and a legend."""
    xs = [x for s in series for x in s.x] + [b.start for b in bands] + [b.end for b in bands]
    ys = [y for s in series for y in s.y]
    x_lower, x_upper = bounds(xs, x_axis.lower, x_axis.upper)
    y_lower, y_upper = bounds(ys, y_axis.lower, y_axis.upper, headroom=True)
    frame = Frame(x_lower, x_upper, y_lower, y_upper, width, height)
    left, top, plot_width, plot_height = frame.plot
    body = _axes(frame, x_axis, y_axis)
    for band in bands:
        start, end = max(band.start, x_lower), min(band.end, x_upper)
        if end > start:
            body.append(
                f'<rect class="band" x="{frame.px(start):.1f}" y="{top}" '
                f'width="{frame.px(end) - frame.px(start):.1f}" height="{plot_height}" '
                f'fill="{band.colour}" opacity="0.45"/>'
            )
    legend: list[tuple[str, str, bool]] = []
    if bands and band_label:
        legend.append((band_label, bands[0].colour, True))
    for index, one in enumerate(series):
        colour = one.colour or PALETTE[index % len(PALETTE)]
        legend.append((one.name, colour, False))
        if one.style == "points":
            for x, y in zip(one.x, one.y, strict=True):
                if y is not None and math.isfinite(y):
                    body.append(
                        f'<circle cx="{frame.px(x):.1f}" cy="{frame.py(y):.1f}" r="2.5" '
                        f'fill="{colour}"/>'
                    )
            continue
        dash = ' stroke-dasharray="6 4"' if one.dashed else ""
        body.append(
            f'<path class="series" data-series="{escape(one.name)}" d="{_path(one, frame)}" '
            f'fill="none" stroke="{colour}" stroke-width="2"{dash}/>'
        )
    body.extend(_legend(legend, frame))
    return _svg(chart_id, title, frame, body)


def bar_chart(
    chart_id: str,
    title: str,
    labels: Sequence[str],
    values: Sequence[float | None],
    x_label: str,
    y_axis: Axis,
    *,
    value_format: str = "{:.0f}",
    colour: str = PALETTE[0],
    width: int = WIDTH,
    height: int = HEIGHT,
) -> Markup:
    """One bar per label, each with its value written above it."""
    y_lower, y_upper = bounds([0.0, *values], y_axis.lower, y_axis.upper, headroom=True)
    frame = Frame(0.0, float(max(1, len(labels))), y_lower, y_upper, width, height)
    left, top, plot_width, plot_height = frame.plot
    body = [
        f'<rect class="plot-area" x="{left}" y="{top}" width="{plot_width}" '
        f'height="{plot_height}" fill="white" stroke="#9ca3af"/>'
    ]
    for tick in linear_ticks(y_lower, y_upper, 5):
        y = frame.py(tick)
        body.append(
            f'<line x1="{left}" y1="{y:.1f}" x2="{left + plot_width}" y2="{y:.1f}" '
            'stroke="#e5e7eb"/>'
            f'<text class="tick y-tick" x="{left - 6}" y="{y + 4:.1f}" text-anchor="end">'
            f"{escape(format_tick(tick, 'linear', y_upper - y_lower))}</text>"
        )
    slot = plot_width / max(1, len(labels))
    bar_width = min(slot * 0.7, MAX_BAR_WIDTH)
    label_every = max(1, math.ceil(len(labels) * 60 / plot_width))
    for index, (label, value) in enumerate(zip(labels, values, strict=True)):
        centre = left + slot * (index + 0.5)
        if value is not None and math.isfinite(value):
            y = frame.py(value)
            body.append(
                f'<rect class="bar" x="{centre - bar_width / 2:.1f}" y="{y:.1f}" '
                f'width="{bar_width:.1f}" height="{frame.py(y_lower) - y:.1f}" fill="{colour}">'
                f"<title>{escape(label)}: {escape(value_format.format(value))}</title></rect>"
            )
            if len(labels) <= 31:
                body.append(
                    f'<text class="bar-value" x="{centre:.1f}" y="{y - 4:.1f}" '
                    f'text-anchor="middle">{escape(value_format.format(value))}</text>'
                )
        if index % label_every == 0:
            body.append(
                f'<text class="tick x-tick" x="{centre:.1f}" y="{top + plot_height + 16}" '
                f'text-anchor="middle">{escape(label)}</text>'
            )
    body.append(
        f'<text class="axis-label x-label" x="{left + plot_width / 2:.1f}" y="{height - 8}" '
        f'text-anchor="middle">{escape(x_label)}</text>'
        f'<text class="axis-label y-label" transform="translate(16 {top + plot_height / 2:.1f}) '
        f'rotate(-90)" text-anchor="middle">{escape(y_axis.label)}</text>'
    )
    return _svg(chart_id, title, frame, body)


def png_bytes(rgb: NDArray[np.uint8]) -> bytes:
    """An RGB image (rows top to bottom) as a PNG file."""
    height, width, _ = rgb.shape

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data))
            + kind
            + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
        )

    rows = np.concatenate([np.zeros((height, 1), dtype=np.uint8), rgb.reshape(height, -1)], axis=1)
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)  # 8-bit RGB
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6))
        + chunk(b"IEND", b"")
    )


def heatmap(
    chart_id: str,
    title: str,
    values: NDArray[np.float64],
    x_range: tuple[float, float],
    y_range: tuple[float, float],
    x_axis: Axis,
    y_axis: Axis,
    scale: ColourScale,
    *,
    width: int = WIDTH,
    height: int = 340,
) -> Markup:
    """A regular grid of cells (values[row, column], row 0 at the bottom) with a colour legend.

    NaN cells are "no data" (grey, and named in the legend).
    """
    frame = Frame(x_range[0], x_range[1], y_range[0], y_range[1], width, height, LEGEND_WIDTH)
    left, top, plot_width, plot_height = frame.plot
    image = base64.b64encode(png_bytes(scale.rgb(values[::-1]))).decode("ascii")
    body = [
        f'<image class="cells" x="{left}" y="{top}" width="{plot_width}" height="{plot_height}" '
        f'preserveAspectRatio="none" style="image-rendering:pixelated" '
        f'href="data:image/png;base64,{image}"/>'
    ]
    axes = _axes(frame, x_axis, y_axis, grid=False)
    axes[0] = (
        f'<rect class="plot-area" x="{left}" y="{top}" width="{plot_width}" '
        f'height="{plot_height}" fill="none" stroke="#9ca3af"/>'
    )
    body.extend(axes)
    body.extend(_colour_legend(scale, frame))
    return _svg(chart_id, title, frame, body)


def _colour_legend(scale: ColourScale, frame: Frame) -> list[str]:
    left, top, plot_width, plot_height = frame.plot
    x = left + plot_width + 18
    gradient = f"legend-{abs(hash((scale.lower, scale.upper, scale.label))) % 10**8}"
    stops = "".join(
        f'<stop offset="{position:.2f}" stop-color="{colour}"/>' for position, colour in scale.stops
    )
    parts = [
        f'<defs><linearGradient id="{gradient}" x1="0" y1="1" x2="0" y2="0">{stops}'
        "</linearGradient></defs>",
        f'<g class="colour-legend"><rect x="{x}" y="{top}" width="14" height="{plot_height - 30}" '
        f'fill="url(#{gradient})" stroke="#9ca3af"/>',
    ]
    bar_height = plot_height - 30
    for tick in linear_ticks(scale.lower, scale.upper, 5):
        y = top + bar_height - (tick - scale.lower) / (scale.upper - scale.lower) * bar_height
        parts.append(
            f'<text class="tick legend-tick" x="{x + 18}" y="{y + 4:.1f}">'
            f"{escape(format_tick(tick, 'linear', scale.upper - scale.lower))}</text>"
        )
    parts.append(
        f'<rect x="{x}" y="{top + plot_height - 16}" width="14" height="12" '
        f'fill="{NO_DATA_COLOUR}" stroke="#9ca3af"/>'
        f'<text class="tick" x="{x + 18}" y="{top + plot_height - 6}">no data</text>'
        f'<text class="axis-label legend-label" transform="translate({x + 74} '
        f'{top + plot_height / 2:.1f}) rotate(-90)" text-anchor="middle">'
        f"{escape(scale.label)}</text></g>"
    )
    return parts
