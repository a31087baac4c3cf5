"""The leave-one-date-out linear recalibration of INRIX, on readings worked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from sim.inrix_correction import PairedReadings, held_out_corrections


def test_a_map_that_holds_on_every_date_removes_the_error_held_out() -> None:
    # the car drives 2 m/s faster than INRIX reads, plus 10 % of the reading, on every date
    inrix = np.array([5.0, 10.0, 20.0, 26.0, 30.0])
    drives = [
        PairedReadings(date, inrix + shift, 2.0 + 1.1 * (inrix + shift))
        for date, shift in (("2021-03-08", 0.0), ("2021-03-09", 1.0), ("2021-04-07", -1.0))
    ]
    rows = held_out_corrections(drives)
    assert [row.date for row in rows] == ["2021-03-08", "2021-03-09", "2021-04-07"]
    for row in rows:
        assert row.offset_mps == pytest.approx(2.0)
        assert row.gain == pytest.approx(1.1)
        assert row.mae_after_mps == pytest.approx(0.0, abs=1e-9)
    # 2021-03-08: errors -(2 + 0.1 x reading) = -2.5, -3, -4, -4.6, -5
    first = rows[0]
    assert first.seconds == 5
    assert first.bias_before_mps == pytest.approx(-3.82)
    assert first.mae_before_mps == pytest.approx(3.82)
    # on the open road (the car at 25 m/s or more: 30.6 and 35, not 24): -4.6, -5
    assert first.open_road_bias_before_mps == pytest.approx(-4.8)


def test_a_map_fitted_on_other_dates_is_scored_on_the_date_left_out() -> None:
    # two dates disagree: the map fitted on one misreads the other, held out
    reading = np.array([10.0, 20.0, 30.0])
    drives = [
        PairedReadings("2021-03-08", reading, reading + 3.0),
        PairedReadings("2021-04-22", reading, reading - 1.0),
    ]
    rows = held_out_corrections(drives)
    assert rows[0].offset_mps == pytest.approx(-1.0)  # fitted on 2021-04-22 alone
    assert rows[0].mae_before_mps == pytest.approx(3.0)
    assert rows[0].mae_after_mps == pytest.approx(4.0)
    assert rows[1].bias_after_mps == pytest.approx(4.0)


def test_one_date_cannot_be_left_out() -> None:
    reading = np.array([10.0, 20.0])
    with pytest.raises(ValueError, match="at least two dates"):
        held_out_corrections([PairedReadings("2021-03-08", reading, reading)])
