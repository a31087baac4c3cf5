"""How the fleet's pings become line segments on the figure."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from zoneinfo import ZoneInfo

import numpy as np
import pandas as pd

from app.motion.figure import clock_axis, fleet_lines

T0 = datetime(2022, 11, 16, 13, 0, tzinfo=UTC)


def pings(rows: list[tuple[str, float, float, bool]]) -> pd.DataFrame:
    return pd.DataFrame(
        [(vehicle, T0 + timedelta(seconds=s), x, engaged) for vehicle, s, x, engaged in rows],
        columns=["vehicle_id", "ts", "x_m", "is_controller_engaged"],
    )


def test_segments_join_a_cars_consecutive_pings_coloured_by_the_first() -> None:
    lines = fleet_lines(
        pings(
            [
                ("A", 0, 1000, True),
                ("A", 1, 1025, False),
                ("A", 2, 1050, False),
                ("B", 0, 2000, False),
                ("B", 1, 2020, False),
            ]
        )
    )
    segments = lines.get_segments()
    assert len(segments) == 3  # A: 2, B: 1; never A to B
    start = T0.timestamp()
    assert np.allclose(segments[0], [[start, 1.0], [start + 1, 1.025]])
    assert [tuple(colour) for colour in lines.get_colors()] == [
        (1.0, 0.0, 0.0, 1.0),
        (1.0, 1.0, 1.0, 1.0),
        (1.0, 1.0, 1.0, 1.0),
    ]


def test_silences_and_jumps_break_the_line() -> None:
    # 10 s without pings, then a loop back from 14 km to the start: neither is drawn.
    lines = fleet_lines(
        pings(
            [
                ("A", 0, 13900, True),
                ("A", 1, 13925, True),
                ("A", 11, 14170, True),
                ("A", 12, 14195, True),
                ("A", 13, 20, True),
            ]
        )
    )
    assert len(lines.get_segments()) == 2


def test_the_clock_is_nashvilles_as_in_the_papers_figure() -> None:
    """The axis said 'time [UTC]': the paper's 08:25 wave sat at 14:25 (analytics audit)."""
    start = datetime(2022, 11, 16, 14, 0, tzinfo=UTC).timestamp()
    ticks, labels, axis_label = clock_axis(start, start + 3600.0, ZoneInfo("America/Chicago"))
    assert (ticks[0], labels[0], labels[1]) == (start, "08:00", "08:10")
    assert axis_label == "local time [CST, America/Chicago]"
    _, summer, label = clock_axis(
        start - 200 * 86400, start - 200 * 86400 + 600, ZoneInfo("America/Chicago")
    )
    assert (summer[0], label) == ("09:00", "local time [CDT, America/Chicago]")
