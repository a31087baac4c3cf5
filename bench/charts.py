"""What one dashboard chart costs the server: the vehicle page's speed chart, drawn and encoded.

    .venv/bin/python -m bench.charts [--repeats 15]

The chart of `dashboards/pages/vehicle.py`: half an hour of 1 Hz pings (1,800 points of speed
and of plan target) with the controller's engaged stretches shaded. A car whose engagement
flickers (a sensor dropping in and out, or the bench's own fleet, engaged two seconds in three)
gives hundreds of shaded stretches; a steady one, a few. Each row is the median over
`--repeats` of building the figure and of encoding it as the page's PNG (`charts.chart`).

Baseline, the same run: the same chart with no shaded stretch (the lines, axes and legend).
"""

from __future__ import annotations

import argparse
import statistics
import time
from zoneinfo import ZoneInfo

import numpy as np

from dashboards.charts import Axis, Band, Series, chart, line_figure

POINTS = 1_800  # half an hour of 1 Hz pings (vehicle.TRACE_WINDOW)
START_S = 1_700_000_000.0
ZONE = ZoneInfo("America/Chicago")


def engaged_stretches(count: int) -> list[Band]:
    """`count` equal engaged stretches spread over the half hour, each half its share."""
    if count == 0:
        return []
    share = POINTS / count
    return [
        Band(START_S + i * share, START_S + i * share + share / 2, "#bbf7d0") for i in range(count)
    ]


def time_chart(bands: list[Band], repeats: int) -> tuple[float, float]:
    """Median ms to build the speed chart's figure and to encode it."""
    times = [START_S + i for i in range(POINTS)]
    speed = list(55.0 + 10.0 * np.sin(np.arange(POINTS) / 40.0))
    target = [56.0] * POINTS
    built, encoded = [], []
    for _ in range(repeats):
        started = time.perf_counter()
        figure = line_figure(
            "Speed of SF-001 against its plan's target",
            [
                Series("speed", times, speed, "#2563eb"),
                Series("plan target", times, target, "#dc2626", style="step", dashed=True),
            ],
            Axis("time", "time"),
            Axis("speed (mph)", lower=0.0),
            bands=bands,
            band_label="controller engaged",
            zone=ZONE,
        )
        middle = time.perf_counter()
        chart("vehicle-speed", figure)
        built.append((middle - started) * 1000.0)
        encoded.append((time.perf_counter() - middle) * 1000.0)
    return statistics.median(built), statistics.median(encoded)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print(f"{'speed chart (1,800 points)':<40}{'build ms':>10}{'encode ms':>11}{'total ms':>10}")
    for label, count in (
        ("no engaged stretch (baseline)", 0),
        ("3 engaged stretches (a steady car)", 3),
        ("30 engaged stretches", 30),
        ("300 engaged stretches (flickering)", 300),
        ("600 engaged stretches (2 s in 3)", 600),
    ):
        build, encode = time_chart(engaged_stretches(count), args.repeats)
        print(f"{label:<40}{build:>10.1f}{encode:>11.1f}{build + encode:>10.1f}")


if __name__ == "__main__":
    main()
