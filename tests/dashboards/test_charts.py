"""Chart building blocks: ticks, colour scales, the PNG encoder and the SVG they produce."""

from __future__ import annotations

import struct
import zlib
from datetime import UTC, datetime

import numpy as np
import pytest

from dashboards.charts import (
    NO_DATA_COLOUR,
    Axis,
    Band,
    ColourScale,
    Frame,
    Series,
    bar_chart,
    bounds,
    format_tick,
    heatmap,
    line_chart,
    linear_ticks,
    nice_step,
    png_bytes,
    time_ticks,
)


@pytest.mark.parametrize(
    ("span", "step"), [(10.0, 2.0), (63.0, 20.0), (0.9, 0.2), (1000.0, 200.0), (14.0, 2.5)]
)
def test_ticks_use_round_steps(span: float, step: float) -> None:
    assert nice_step(span, 6) == pytest.approx(step)


def test_linear_ticks_stay_inside_the_range() -> None:
    assert linear_ticks(0.0, 9.06) == [0.0, 2.0, 4.0, 6.0, 8.0]
    assert linear_ticks(-3.0, 3.0) == [-3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0]


def test_time_ticks_fall_on_round_clock_times() -> None:
    start = datetime(2022, 11, 16, 12, 3, 20, tzinfo=UTC).timestamp()
    ticks = time_ticks(start, start + 3600)
    labels = [format_tick(t, "time", 3600) for t in ticks]
    assert labels == ["12:10", "12:20", "12:30", "12:40", "12:50", "13:00"]


def test_a_data_derived_upper_bound_gets_headroom_to_the_next_tick() -> None:
    assert bounds([0.0, 55.9], 0.0, None, headroom=True) == (0.0, 60.0)
    assert bounds([0.0, 55.9], 0.0, None) == (0.0, 55.9)
    assert bounds([], None, None) == (0.0, 1.0)
    assert bounds([3.0, 3.0], None, None) == (3.0, 4.0)


def test_frame_maps_data_onto_the_plot_area_with_y_up() -> None:
    frame = Frame(0.0, 10.0, 0.0, 100.0)
    left, top, width, height = frame.plot
    assert frame.px(0.0) == left
    assert frame.px(10.0) == left + width
    assert frame.py(0.0) == top + height
    assert frame.py(100.0) == top


def test_speed_scale_runs_red_to_green_and_grey_for_no_data() -> None:
    scale = ColourScale(0.0, 70.0, "speed (mph)")
    assert scale.hex(0.0) == "#a50026"
    assert scale.hex(70.0) == "#1a9850"
    assert scale.hex(200.0) == "#1a9850"  # clamped
    assert scale.hex(35.0) == "#fee08b"
    assert scale.hex(float("nan")) == NO_DATA_COLOUR


def test_png_encoder_writes_a_valid_rgb_image() -> None:
    image = np.zeros((2, 3, 3), dtype=np.uint8)
    image[0, 0] = (255, 0, 0)
    data = png_bytes(image)
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    length, kind = struct.unpack(">I4s", data[8:16])
    assert (length, kind) == (13, b"IHDR")
    width, height, depth, colour_type = struct.unpack(">IIBB", data[16:26])
    assert (width, height, depth, colour_type) == (3, 2, 8, 2)
    idat_length = struct.unpack(">I", data[33:37])[0]
    raw = zlib.decompress(data[41 : 41 + idat_length])
    assert raw[:4] == b"\x00\xff\x00\x00"  # filter byte, then the red pixel
    assert len(raw) == 2 * (1 + 3 * 3)


def test_line_chart_has_axis_labels_legend_bands_and_breaks_at_missing_values() -> None:
    svg = str(
        line_chart(
            "demo",
            "Demo",
            [Series("target speed", [0.0, 1.0, 2.0, 3.0], [10.0, None, 30.0, 40.0])],
            Axis("postmile (direction of travel →)"),
            Axis("speed (mph)", lower=0.0),
            bands=[Band(1.0, 2.0)],
            band_label="buffer region",
        )
    )
    assert 'data-chart="demo"' in svg
    assert "postmile (direction of travel →)" in svg
    assert "speed (mph)" in svg
    assert ">buffer region</text>" in svg
    assert ">target speed</text>" in svg
    path = svg.split('data-series="target speed" d="')[1].split('"')[0]
    assert path.count("M") == 2  # the gap at x = 1 lifts the pen


def test_bar_chart_writes_each_value() -> None:
    svg = str(
        bar_chart(
            "share",
            "Share",
            ["11-16", "11-17"],
            [38.0, 78.0],
            "day (UTC)",
            Axis("engaged (%)", lower=0.0, upper=100.0),
            value_format="{:.0f} %",
        )
    )
    assert ">38 %</text>" in svg
    assert ">78 %</text>" in svg
    assert svg.count('class="bar"') == 2


def test_heatmap_embeds_its_cells_and_a_colour_legend() -> None:
    values = np.array([[10.0, np.nan], [30.0, 60.0]])
    svg = str(
        heatmap(
            "field",
            "Field",
            values,
            (0.0, 20.0),
            (0.0, 1.0),
            Axis("time (UTC)", "time"),
            Axis("postmile (direction of travel ↑)"),
            ColourScale(0.0, 60.0, "speed (mph)"),
        )
    )
    assert 'href="data:image/png;base64,' in svg
    assert "speed (mph)" in svg
    assert ">no data</text>" in svg
