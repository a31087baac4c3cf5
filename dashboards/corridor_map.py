"""The corridor map: the corridor drawn from its own sub-segments' coordinates (no tiles, works
offline), each lane coloured by the current plan's target speed, buffer regions shaded, and every
car at its last ping, coloured by engaged / not engaged / not reporting.

The map is north-up in a local plane (equirectangular about the corridor's middle, metres). The
lanes of a 14 km corridor would be a few hundredths of a pixel apart at true scale, so they are
drawn `LANE_GAP_PX` apart across the line of travel (the legend says so). Pure geometry and SVG:
the page gathers the rows.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from markupsafe import Markup, escape
from numpy.typing import NDArray

from contract.corridor import EARTH_RADIUS_M
from contract.units import MPH_PER_MPS
from dashboards.charts import ColourScale

WIDTH_PX = 1000.0
MAX_HEIGHT_PX = 560.0
MARGIN_PX = 40.0
LANE_GAP_PX = 5.0
LANE_STROKE_PX = 4.0
BUFFER_STROKE_PX = 30.0
CAR_RADIUS_PX = 6.0
NO_PLAN_COLOUR = "#9ca3af"

CarState = Literal["engaged", "not engaged", "not reporting"]
CAR_COLOURS: dict[CarState, tuple[str, str]] = {  # fill, outline
    "engaged": ("#dc2626", "#7f1d1d"),
    "not engaged": ("#ffffff", "#111827"),
    "not reporting": ("#9ca3af", "#4b5563"),
}


@dataclass(frozen=True)
class MapSegment:
    """One sub-segment of the corridor: where it runs, and the plan's target in each lane."""

    start_x_m: float
    end_x_m: float
    start_lat: float
    start_lon: float
    end_lat: float
    end_lon: float
    target_mps: dict[int, float]  # lane -> target speed (m/s); empty without a plan
    is_buffer: bool


@dataclass(frozen=True)
class MapCar:
    """A car at its last ping's position along the corridor."""

    vehicle_id: str
    x_m: float
    lane: int
    state: CarState
    speed_mps: float


def plane_m(
    lat: NDArray[np.float64], lon: NDArray[np.float64], lat0: float, lon0: float
) -> NDArray[np.float64]:
    """East and north (m) of each point from (lat0, lon0), equirectangular (fine over 20 km)."""
    east = np.radians(lon - lon0) * EARTH_RADIUS_M * math.cos(math.radians(lat0))
    north = np.radians(lat - lat0) * EARTH_RADIUS_M
    return np.stack([east, north], axis=-1)


class _Frame:
    """Metres in the plane to SVG pixels (north up), fitted to WIDTH_PX with margins."""

    def __init__(self, points_m: NDArray[np.float64]) -> None:
        low, high = points_m.min(axis=0), points_m.max(axis=0)
        span = np.maximum(high - low, 1.0)
        self.scale = min(
            (WIDTH_PX - 2 * MARGIN_PX) / span[0], (MAX_HEIGHT_PX - 2 * MARGIN_PX) / span[1]
        )
        self.low, self.high = low, high
        self.height = float(span[1] * self.scale + 2 * MARGIN_PX + 40.0)

    def px(self, points_m: NDArray[np.float64]) -> NDArray[np.float64]:
        x = MARGIN_PX + (points_m[..., 0] - self.low[0]) * self.scale
        y = MARGIN_PX + (self.high[1] - points_m[..., 1]) * self.scale
        return np.stack([x, y], axis=-1)


def _lane_offset_px(lane: int, lanes: int) -> float:
    """Across-track offset of a lane (lane 1 the leftmost, as numbered in the plan)."""
    return (lane - (lanes + 1) / 2) * LANE_GAP_PX


def _left_normal(start: NDArray[np.float64], end: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit normal to the left of travel in SVG pixels (y down)."""
    dx, dy = end - start
    length = math.hypot(dx, dy) or 1.0
    return np.array([dy / length, -dx / length])


def corridor_map(
    chart_id: str,
    segments: Sequence[MapSegment],
    lanes: int,
    cars: Sequence[MapCar],
    speed_upper_mph: float,
) -> Markup:
    """The map as inline SVG; each car links to its page."""
    ordered = sorted(segments, key=lambda segment: segment.start_x_m)
    starts = np.array([[s.start_lat, s.start_lon] for s in ordered], dtype=np.float64)
    ends = np.array([[s.end_lat, s.end_lon] for s in ordered], dtype=np.float64)
    lat0 = float(np.mean(starts[:, 0]))
    lon0 = float(np.mean(starts[:, 1]))
    start_m = plane_m(starts[:, 0], starts[:, 1], lat0, lon0)
    end_m = plane_m(ends[:, 0], ends[:, 1], lat0, lon0)
    frame = _Frame(np.concatenate([start_m, end_m]))
    start_px, end_px = frame.px(start_m), frame.px(end_m)
    scale = ColourScale(0.0, speed_upper_mph, "target speed (mph)")
    body: list[str] = []
    for index, segment in enumerate(ordered):
        if segment.is_buffer:
            a, b = start_px[index], end_px[index]
            body.append(
                f'<line class="buffer" x1="{a[0]:.1f}" y1="{a[1]:.1f}" x2="{b[0]:.1f}" '
                f'y2="{b[1]:.1f}" stroke="#f59e0b" stroke-opacity="0.3" '
                f'stroke-width="{BUFFER_STROKE_PX}" stroke-linecap="butt"/>'
            )
    for lane in range(1, lanes + 1):
        for index, segment in enumerate(ordered):
            a, b = start_px[index], end_px[index]
            shift = _left_normal(a, b) * -_lane_offset_px(lane, lanes)
            target = segment.target_mps.get(lane)
            colour = NO_PLAN_COLOUR if target is None else scale.hex(target * MPH_PER_MPS)
            shown = "no plan" if target is None else f"{target * MPH_PER_MPS:.0f} mph"
            body.append(
                f'<line class="lane" data-lane="{lane}" x1="{a[0] + shift[0]:.1f}" '
                f'y1="{a[1] + shift[1]:.1f}" x2="{b[0] + shift[0]:.1f}" '
                f'y2="{b[1] + shift[1]:.1f}" stroke="{colour}" '
                f'stroke-width="{LANE_STROKE_PX}"><title>lane {lane}: {shown}</title></line>'
            )
    starts_x = np.array([s.start_x_m for s in ordered])
    for car in cars:
        index = int(
            np.clip(np.searchsorted(starts_x, car.x_m, side="right") - 1, 0, len(ordered) - 1)
        )
        segment = ordered[index]
        length = max(segment.end_x_m - segment.start_x_m, 1e-6)
        along = min(max((car.x_m - segment.start_x_m) / length, 0.0), 1.0)
        a, b = start_px[index], end_px[index]
        lane = min(max(car.lane, 1), lanes)
        point = a + (b - a) * along + _left_normal(a, b) * -_lane_offset_px(lane, lanes)
        fill, outline = CAR_COLOURS[car.state]
        vehicle_id = escape(car.vehicle_id)
        body.append(
            f'<a href="/vehicles/{vehicle_id}" data-vehicle="{vehicle_id}" '
            f'data-state="{car.state}"><circle cx="{point[0]:.1f}" cy="{point[1]:.1f}" '
            f'r="{CAR_RADIUS_PX}" fill="{fill}" stroke="{outline}" stroke-width="1.5">'
            f"<title>{vehicle_id}: {car.state}, lane {car.lane}, "
            f"{car.speed_mps * MPH_PER_MPS:.0f} mph</title></circle></a>"
        )
    body.extend(_legend(frame, scale, speed_upper_mph))
    height = frame.height
    return Markup(
        f'<svg class="chart map" data-chart="{escape(chart_id)}" viewBox="0 0 {WIDTH_PX:.0f} '
        f'{height:.0f}" role="img" aria-label="corridor map" xmlns="http://www.w3.org/2000/svg">'
        + "".join(body)
        + "</svg>"
    )


def _legend(frame: _Frame, scale: ColourScale, upper_mph: float) -> list[str]:
    y = frame.height - 22.0
    parts = ['<g class="legend">']
    x = MARGIN_PX
    for state, (fill, outline) in CAR_COLOURS.items():
        parts.append(
            f'<circle cx="{x:.0f}" cy="{y:.0f}" r="{CAR_RADIUS_PX}" fill="{fill}" '
            f'stroke="{outline}"/><text x="{x + 10:.0f}" y="{y + 4:.0f}">{state}</text>'
        )
        x += 120
    parts.append(
        f'<rect x="{x:.0f}" y="{y - 8:.0f}" width="24" height="16" fill="#f59e0b" '
        f'fill-opacity="0.3"/><text x="{x + 30:.0f}" y="{y + 4:.0f}">buffer</text>'
    )
    x += 90
    for step in range(6):
        mph = upper_mph * step / 5
        parts.append(
            f'<rect x="{x + step * 34:.0f}" y="{y - 8:.0f}" width="34" height="16" '
            f'fill="{scale.hex(mph)}"/>'
            f'<text x="{x + step * 34 + 4:.0f}" y="{y + 22:.0f}">{mph:.0f}</text>'
        )
    x += 6 * 34 + 8
    parts.append(f'<text x="{x:.0f}" y="{y + 4:.0f}">target (mph)</text></g>')
    return parts
