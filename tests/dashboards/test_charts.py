"""Charts (matplotlib on the server): axes fit their data, time in the readers' zone, legends,
colour scales, and the page's <img>."""

from __future__ import annotations

import asyncio
import base64
import re
import threading
from datetime import UTC, datetime
from zoneinfo import ZoneInfo

import numpy as np
import pytest
from matplotlib.figure import Figure

from dashboards.charts import (
    NO_DATA_COLOUR,
    Axis,
    Band,
    ColourScale,
    Series,
    bar_figure,
    chart,
    drawn,
    fit,
    heatmap_figure,
    line_figure,
    local_time_ticks,
)

CHICAGO = ZoneInfo("America/Chicago")
START = datetime(2022, 11, 16, 12, 7, 30, tzinfo=UTC).timestamp()  # 06:07:30 CST


def test_time_ticks_fall_on_whole_local_minutes() -> None:
    ticks = local_time_ticks(START, START + 3600.0, CHICAGO)
    assert list(ticks.values()) == ["06:10", "06:20", "06:30", "06:40", "06:50", "07:00"]
    overnight = local_time_ticks(START + 17.5 * 3600, START + 19.5 * 3600, CHICAGO)
    assert next(iter(overnight.values())) == "11-16 23:45"  # the date, across midnight


def test_axes_fit_their_data_and_a_lone_point_gets_room() -> None:
    assert fit([3.0, 9.0], None, None) == (3.0, 9.0)
    assert fit([3.0, 9.0], 0.0, None) == (0.0, 9.0)
    assert fit([START], None, None, time=True) == (START - 1800.0, START + 1800.0)
    assert fit([], None, None) == (0.0, 1.0)


def test_speed_scale_runs_red_to_green_and_grey_for_no_data() -> None:
    scale = ColourScale(0.0, 70.0, "speed (mph)")
    assert scale.hex(0.0) == "#a50026"
    assert scale.hex(70.0) == "#1a9850"
    assert scale.hex(200.0) == "#1a9850"  # clamped
    assert scale.hex(35.0) == "#fee08b"
    assert scale.hex(float("nan")) == NO_DATA_COLOUR


def test_a_time_line_chart_spans_its_data_in_local_time_with_legend_and_bands() -> None:
    times = [START + 60.0 * i for i in range(31)]
    figure = line_figure(
        "Speed",
        [
            Series("speed", times, [20.0 + i for i in range(31)]),
            Series("plan target", times, [30.0] * 15 + [None] + [35.0] * 15, style="step"),
        ],
        Axis("time", "time"),
        Axis("speed (mph)", lower=0.0),
        bands=[Band(times[3], times[9])],
        band_label="controller engaged",
        zone=CHICAGO,
    )
    axes = figure.axes[0]
    assert axes.get_xlim() == (times[0], times[-1])  # no empty hour before the data
    assert axes.get_xlabel() == "time (CST)"
    assert [t.get_text() for t in axes.get_xticklabels()][0] == "06:10"
    assert axes.get_ylim()[0] == 0.0
    assert axes.get_ylim()[1] == pytest.approx(50.0 * 1.08)
    legend = [text.get_text() for text in axes.get_legend().get_texts()]
    assert legend == ["controller engaged", "speed", "plan target"]


def test_a_flickering_cars_engaged_stretches_are_shaded_as_one_collection() -> None:
    """Hundreds of engaged stretches were one patch each, which made a flickering car's chart
    five times as costly to draw as a steady car's (`python -m bench.charts`)."""
    times = [START + float(i) for i in range(1_800)]
    stretches = [Band(times[i], times[i + 2], "#bbf7d0") for i in range(0, 1_797, 3)]
    buffers = [Band(times[0], times[5])]  # another colour: a collection of its own
    figure = line_figure(
        "Speed",
        [Series("speed", times, [20.0] * len(times))],
        Axis("time", "time"),
        Axis("speed (mph)", lower=0.0),
        bands=stretches + buffers,
        band_label="controller engaged",
        zone=CHICAGO,
    )
    axes = figure.axes[0]
    assert not axes.patches
    shaded = axes.collections
    assert [len(collection.get_paths()) for collection in shaded] == [len(stretches), 1]
    # every stretch spans the axes' full height whatever the data's range
    assert shaded[0].get_paths()[0].vertices[:, 1].min() == 0.0
    assert shaded[0].get_paths()[0].vertices[:, 1].max() == 1.0
    legend = [text.get_text() for text in axes.get_legend().get_texts()]
    assert legend == ["controller engaged", "speed"]


def test_bar_chart_labels_each_day_once_and_writes_each_value() -> None:
    figure = bar_figure(
        "Share",
        ["11-16", "11-17"],
        [38.0, 78.0],
        "day (UTC)",
        Axis("engaged (%)", lower=0.0, upper=100.0),
        value_format="{:.0f} %",
    )
    axes = figure.axes[0]
    assert [t.get_text() for t in axes.get_xticklabels()] == ["11-16", "11-17"]
    assert sorted(t.get_text() for t in axes.texts) == ["38 %", "78 %"]
    assert axes.get_ylim() == (0.0, 100.0)


def test_a_heatmap_has_its_colour_bar_and_says_grey_is_no_data() -> None:
    figure = heatmap_figure(
        "Field",
        np.array([[10.0, np.nan], [30.0, 60.0]]),
        (START, START + 600.0),
        (0.0, 1.0),
        Axis("time", "time"),
        Axis("postmile (direction of travel ↑)"),
        ColourScale(0.0, 60.0, "speed (mph)"),
        zone=CHICAGO,
    )
    axes, bar = figure.axes
    assert axes.get_ylabel() == "postmile (direction of travel ↑)"
    assert bar.get_ylabel() == "speed (mph)"
    assert bar.get_xlabel() == "grey: no data"


def test_a_chart_is_an_img_carrying_a_png_with_its_id_and_title() -> None:
    html = str(
        chart(
            "demo",
            line_figure(
                "Demo <chart>",
                [Series("a", [0.0, 1.0], [1.0, 2.0])],
                Axis("postmile (direction of travel →)"),
                Axis("speed (mph)"),
            ),
        )
    )
    assert html.startswith('<img class="chart" data-chart="demo" alt="Demo &lt;chart&gt;"')
    found = re.search(r'src="data:image/png;base64,([^"]+)"', html)
    assert found is not None
    assert base64.b64decode(found.group(1))[:8] == b"\x89PNG\r\n\x1a\n"
    assert 'data-chart="share"' in str(
        chart("share", bar_figure("Share", ["11-16"], [38.0], "day", Axis("engaged (%)")))
    )


def test_a_chart_for_a_page_is_drawn_off_the_event_loop() -> None:
    """The dashboard shares its event loop with the ingest API: a chart drawn on it held every
    ping arriving meanwhile (380 ms at the median while /plans refreshed, bench.dashboard)."""
    drawn_on: list[int] = []

    def figure() -> Figure:
        drawn_on.append(threading.get_ident())
        return line_figure(
            "Off the loop", [Series("a", [0.0, 1.0], [1.0, 2.0])], Axis("x"), Axis("y")
        )

    async def page() -> tuple[int, str]:
        return threading.get_ident(), str(await drawn("off-loop", figure))

    loop_thread, html = asyncio.run(page())
    assert html.startswith('<img class="chart" data-chart="off-loop"')
    assert drawn_on
    assert drawn_on[0] != loop_thread
