"""Edie's fields of every vehicle MOTION saw, for any window, corridor range, lane and box size.

The paper ("Results") builds, on boxes of h_t x h_x (10 s x 200 m):

    rho = (total time vehicles spent in the box) / (h_t h_x)          density, veh/m
    q   = (total distance travelled in the box)  / (h_t h_x)          flow, veh/s
    f   = (total fuel consumed in the box)       / (h_t h_x)          fuel-rate density, g/(s m)
    u   = q / rho   bulk velocity (m/s),   phi = f / rho   bulk fuel rate (g/s),
    psi = f / q     bulk fuel consumption (g/m).

Each MOTION point carries the step it stands for (app.motion.kinematics), so the totals are sums
over the points whose (t, x) fall in the box: the SQL macro `motion_edie` of app.motion.store,
which analysts call in DuckDB, and which `edie_field` calls here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, date, datetime
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from app.motion.store import CELL_T_S, CELL_X_M, MotionStoreEmpty, connect

# The paper's box ("Results": h_t = 10 s, h_x = 200 m).
H_T_S = 10.0
H_X_M = 200.0


class EdieWindowError(ValueError):
    """A window, range, box or lane that cannot make a field; the message says which."""


@dataclass(frozen=True, slots=True)
class EdieWindow:
    """Where and how finely to build the fields; the bounds are widened to whole boxes."""

    since: datetime
    until: datetime
    x_from_m: float
    x_to_m: float
    h_t_s: float = H_T_S
    h_x_m: float = H_X_M
    lane: int | None = None

    def __post_init__(self) -> None:
        for moment in (self.since, self.until):
            if moment.tzinfo is None:
                raise EdieWindowError(f"{moment.isoformat()} has no time zone (give UTC)")
        if not self.h_t_s > 0 or not self.h_x_m > 0:
            raise EdieWindowError(f"box size must be positive, got {self.h_t_s} s x {self.h_x_m} m")
        if self.until <= self.since:
            raise EdieWindowError(f"until ({self.until}) must be after since ({self.since})")
        if not self.x_to_m > self.x_from_m:
            raise EdieWindowError(
                f"x_to_m ({self.x_to_m}) must be beyond x_from_m ({self.x_from_m})"
            )
        if self.lane is not None and self.lane < 1:
            raise EdieWindowError(f"lanes are numbered from 1, got {self.lane}")

    @property
    def whole_cells(self) -> bool:
        """Whether a box is a whole number of the store's base cells (CELL_T_S x CELL_X_M)."""
        return _multiple(self.h_t_s, CELL_T_S) and _multiple(self.h_x_m, CELL_X_M)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(t0, t1, x0, x1): the window widened to whole boxes (unix s, corridor m)."""
        t0 = math.floor(self.since.timestamp() / self.h_t_s) * self.h_t_s
        t1 = math.ceil(self.until.timestamp() / self.h_t_s) * self.h_t_s
        x0 = math.floor(self.x_from_m / self.h_x_m) * self.h_x_m
        x1 = math.ceil(self.x_to_m / self.h_x_m) * self.h_x_m
        return t0, t1, x0, x1


def edie_field(store: Path, window: EdieWindow) -> pd.DataFrame:
    """One row per box holding MOTION points: totals, rho, q, f, u, phi, psi and counts.

    Boxes of whole cells of the store's base grid are summed from `motion_cells`; others from
    every point (the same sums, a hundred times more rows to read).
    """
    t0, t1, x0, x1 = window.bounds
    macro = "motion_edie_cells" if window.whole_cells else "motion_edie"
    with connect(store) as connection:
        frame = connection.execute(
            f"SELECT * FROM {macro}(?, ?, ?, ?, h_t_s := ?, h_x_m := ?, lane_no := ?) "
            "ORDER BY t_start_s, x_start_m",
            [t0, t1, x0, x1, window.h_t_s, window.h_x_m, window.lane],
        ).df()
    frame.insert(0, "t_start", pd.to_datetime(frame["t_start_s"], unit="s", utc=True))
    return frame


def _multiple(size: float, base: float) -> bool:
    ratio = size / base
    return ratio >= 1 and abs(ratio - round(ratio)) < 1e-9


@dataclass(frozen=True, slots=True)
class EdieGrid:
    """A field on the full grid of boxes (NaN where no vehicle was), for drawing."""

    t_edges_s: NDArray[np.float64]
    x_edges_m: NDArray[np.float64]
    values: NDArray[np.float64]  # [x box, t box]


def to_grid(field: pd.DataFrame, window: EdieWindow, column: str) -> EdieGrid:
    """Spread one column of `edie_field` over the window's whole grid of boxes."""
    t0, t1, x0, x1 = window.bounds
    columns = int(round((t1 - t0) / window.h_t_s))
    rows = int(round((x1 - x0) / window.h_x_m))
    values = np.full((rows, columns), np.nan)
    if len(field):
        t_index = np.round((field["t_start_s"].to_numpy() - t0) / window.h_t_s).astype(int)
        x_index = np.round((field["x_start_m"].to_numpy() - x0) / window.h_x_m).astype(int)
        values[x_index, t_index] = field[column].to_numpy(dtype=np.float64, na_value=np.nan)
    t_edges: NDArray[np.float64] = t0 + window.h_t_s * np.arange(columns + 1, dtype=np.float64)
    x_edges: NDArray[np.float64] = x0 + window.h_x_m * np.arange(rows + 1, dtype=np.float64)
    return EdieGrid(t_edges_s=t_edges, x_edges_m=x_edges, values=values)


def day_window(store: Path, day: date, lane: int | None = None) -> EdieWindow:
    """The extent in time and space of the MOTION trajectories of one UTC day (paper's boxes),
    at least one box each way: a day of one-point fragments spans no time and no road."""
    with connect(store) as connection:
        row = connection.execute(
            "SELECT min(first_t_s), max(last_t_s), min(least(first_x_m, last_x_m)),"
            " max(greatest(first_x_m, last_x_m)) FROM motion_trajectories"
            " WHERE day = CAST(? AS DATE)",
            [day.isoformat()],
        ).fetchone()
    if row is None or row[0] is None:
        raise MotionStoreEmpty(f"no MOTION trajectories imported for {day.isoformat()}")
    first_s, last_s, x_from_m, x_to_m = (float(value) for value in row)
    return EdieWindow(
        since=datetime.fromtimestamp(first_s, UTC),
        until=datetime.fromtimestamp(max(last_s, first_s + H_T_S), UTC),
        x_from_m=x_from_m,
        x_to_m=max(x_to_m, x_from_m + H_X_M),
        lane=lane,
    )
