"""The paper's bulk-fuel figure: psi(t, x) of every vehicle, the fleet's trajectories on top.

Paper, "Results" (figure "Bulk fuel consumption heatmap"): psi = f / q on 10 s x 200 m boxes
from I-24 MOTION, westbound, all lanes, with the AVs' trajectories drawn red where the controller
was engaged and white where it was not; the day's engagement share is printed on it. A second
panel shows the bulk velocity u = q / rho, where the waves read most easily.
"""

from __future__ import annotations

import io
from datetime import date, datetime

import matplotlib

matplotlib.use("Agg")

from pathlib import Path  # noqa: E402
from zoneinfo import ZoneInfo  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from sqlalchemy import Connection  # noqa: E402

from app.motion.edie import EdieGrid, EdieWindow, day_window, edie_field, to_grid  # noqa: E402
from app.motion.fleet import TRACE_GAP_S, FleetDay, fleet_pings  # noqa: E402

ENGAGED_COLOUR = "red"
NOT_ENGAGED_COLOUR = "white"
G_PER_KM_PER_G_PER_M = 1000.0
# Colour ranges: the fuel model (sim.energy.RAV4_2019) gives psi = f(v, 0) / v of 28-50 g/km
# for a car at a steady 15-35 m/s and 85-160 g/km for one crawling at 2-1 m/s, more while it
# accelerates out of a wave; u from standstill to 35 m/s (78 mph).
PSI_RANGE_G_PER_KM = (0.0, 200.0)
# No car on the corridor covers ground faster than this (134 mph).
MAX_TRACE_SPEED_MPS = 60.0
SPEED_RANGE_MPS = (0.0, 35.0)


def day_figure(
    store: Path, connection: Connection, day: date, corridor_id: str, zone: ZoneInfo
) -> bytes:
    """The figure of one UTC day: all MOTION data of the day, all lanes, and the fleet's pings;
    clock times in `zone`."""
    window = day_window(store, day)
    field = edie_field(store, window)
    fleet = fleet_pings(connection, corridor_id, window.since, window.until)
    return window_figure(window, field, fleet, corridor_id, zone)


def window_figure(
    window: EdieWindow, field: pd.DataFrame, fleet: FleetDay, corridor_id: str, zone: ZoneInfo
) -> bytes:
    """The figure of a window's Edie field (from `edie_field`) and the fleet's pings in it."""
    title = (
        f"{corridor_id}, UTC day {window.since:%Y-%m-%d}: Edie fields of every vehicle I-24 "
        f"MOTION tracked ({window.h_t_s:g} s x {window.h_x_m:g} m boxes, all lanes)"
    )
    return bulk_fuel_figure(
        to_grid(field, window, "fuel_per_distance_g_per_m"),
        to_grid(field, window, "speed_mps"),
        fleet,
        title,
        zone,
    )


def bulk_fuel_figure(
    psi: EdieGrid, speed: EdieGrid, fleet: FleetDay, title: str, zone: ZoneInfo
) -> bytes:
    """The two panels as a PNG: psi (g/km) and u (m/s) over time and corridor position.

    The clock is `zone`'s, as in the paper's figure, whose times are Nashville's (the morning
    rush, "around time 08:25:00"): in UTC the same waves sit six hours later."""
    figure, axes = plt.subplots(2, 1, figsize=(12, 8), sharex=True, constrained_layout=True)
    panels = (
        (
            axes[0],
            psi,
            psi.values * G_PER_KM_PER_G_PER_M,
            "magma",
            PSI_RANGE_G_PER_KM,
            "bulk fuel consumption ψ = f/q [g/km]",
        ),
        (axes[1], speed, speed.values, "RdYlGn", SPEED_RANGE_MPS, "bulk velocity u = q/ρ [m/s]"),
    )
    for axis, grid, values, colours, (low, high), label in panels:
        mesh = axis.pcolormesh(
            grid.t_edges_s,
            grid.x_edges_m / 1000.0,
            np.ma.masked_invalid(values),
            cmap=colours,
            vmin=low,
            vmax=high,
            shading="flat",
        )
        figure.colorbar(mesh, ax=axis, label=label)
        axis.set_facecolor("0.85")
        axis.set_ylabel("corridor position x [km]")
        axis.set_ylim(grid.x_edges_m[0] / 1000.0, grid.x_edges_m[-1] / 1000.0)
        axis.add_collection(fleet_lines(fleet.pings), autolim=False)
    ticks, labels, axis_label = clock_axis(float(psi.t_edges_s[0]), float(psi.t_edges_s[-1]), zone)
    axes[1].set_xticks(ticks, labels)
    axes[1].set_xlim(float(psi.t_edges_s[0]), float(psi.t_edges_s[-1]))
    axes[1].set_xlabel(axis_label)
    share = (
        "no fleet pings on the corridor that day"
        if fleet.engagement_share is None
        else f"controllers engaged {100 * fleet.engagement_share:.0f} % of the fleet's pings"
    )
    axes[0].set_title(f"{title}\n{share} (red: engaged, white: not engaged)")
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=100)
    plt.close(figure)
    return buffer.getvalue()


def clock_axis(first_s: float, last_s: float, zone: ZoneInfo) -> tuple[list[float], list[str], str]:
    """The time axis between two unix times: round ticks, their clock times in `zone`, and the
    axis's label naming the zone."""
    ticks = _clock_ticks(first_s, last_s)
    clock = "%H:%M" if len(ticks) < 2 or ticks[1] - ticks[0] >= 60 else "%H:%M:%S"
    labels = [datetime.fromtimestamp(t, zone).strftime(clock) for t in ticks]
    first = datetime.fromtimestamp(first_s, zone)
    return ticks, labels, f"local time [{first.tzname()}, {zone.key}]"


def _clock_ticks(first_s: float, last_s: float) -> list[float]:
    """Round clock times (every 10 s to 1 h) for at most eight ticks."""
    for step in (10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 900.0, 1800.0, 3600.0):
        if (last_s - first_s) / step <= 8:
            break
    first_tick = -(-first_s // step) * step
    return [float(t) for t in np.arange(first_tick, last_s + 1e-9, step)]


def fleet_lines(pings: pd.DataFrame) -> LineCollection:
    """Each car's consecutive pings joined, coloured by the engagement at the segment's start."""
    if pings.empty:
        return LineCollection([])
    x_km = pings["x_m"].to_numpy(dtype=np.float64) / 1000.0
    vehicle = pings["vehicle_id"].to_numpy()
    engaged = pings["is_controller_engaged"].to_numpy(dtype=bool)
    since_epoch = pd.to_datetime(pings["ts"], utc=True) - pd.Timestamp(0, tz="UTC")
    times = since_epoch.dt.total_seconds().to_numpy(dtype=np.float64)
    gap_s, advance_m = np.diff(times), np.diff(x_km) * 1000.0
    # A car is joined to its next ping unless it was silent too long or "moved" faster than a
    # car can (a loop back to the corridor's start, a fix on another road).
    joined = (
        (vehicle[1:] == vehicle[:-1])
        & (gap_s <= TRACE_GAP_S)
        & (np.abs(advance_m) <= MAX_TRACE_SPEED_MPS * gap_s)
    )
    starts = np.flatnonzero(joined)
    segments = np.stack(
        [
            np.column_stack([times[starts], x_km[starts]]),
            np.column_stack([times[starts + 1], x_km[starts + 1]]),
        ],
        axis=1,
    )
    colours = np.where(engaged[starts], ENGAGED_COLOUR, NOT_ENGAGED_COLOUR)
    return LineCollection(list(segments), colors=list(colours), linewidths=0.8)
