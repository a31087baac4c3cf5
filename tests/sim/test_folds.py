"""Cross-validation folds keep whole dates apart."""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from sim.drives import drive_from_speeds, load_drives
from sim.folds import CORRIDOR_TIMEZONE, date_folds, drive_date
from sim.recorded import load_recorded_drives


def test_every_date_is_held_out_exactly_once_and_never_trained_on() -> None:
    names = [
        "2021-03-08-22-35-14_masterArray_0_5373",
        "2021-03-08-22-35-14_masterArray_1_4961",
        "2021-03-09-13-35-04_masterArray_0_4633",
        "2021-03-12-22-20-57_masterArray_0_7509",
        "2021-04-07-12-33-03_masterArray_0_4031",
        "2021-04-07-21-22-07_masterArray_0_4882",
    ]
    drives = [drive_from_speeds(name, np.full(10, 20.0)) for name in names]
    folds = date_folds(drives, 2)
    # dates sorted: 03-08, 03-09, 03-12, 04-07 -> fold 0 holds out 03-08 and 03-12
    assert folds[0].held_out_dates == ["2021-03-08", "2021-03-12"]
    assert folds[1].held_out_dates == ["2021-03-09", "2021-04-07"]
    for fold in folds:
        assert not set(fold.train_dates) & set(fold.held_out_dates)
        assert len(fold.train) + len(fold.held_out) == len(drives)
    held = [drive.name for fold in folds for drive in fold.held_out]
    assert sorted(held) == sorted(names)
    # both drives of one date stay together (two recordings of 2021-03-08)
    assert {drive_date(drive) for drive in folds[1].train} == {"2021-03-08", "2021-03-12"}


def test_impossible_folds_are_refused() -> None:
    drives = [drive_from_speeds("2021-03-08-x", np.full(10, 20.0))]
    with pytest.raises(ValueError, match="at least 2 folds"):
        date_folds(drives, 1)
    with pytest.raises(
        ValueError, match=r"the drives span 1 date \(2021-03-08\), and 2 folds need 2"
    ):
        date_folds(drives, 2)


def test_a_drive_not_named_by_its_date_is_dated_by_its_first_sample_on_i24() -> None:
    # the 2021-03-08 evening session's second recording starts after midnight UTC
    after_midnight_utc = datetime(2021, 3, 9, 0, 0, 33, tzinfo=UTC).timestamp()
    drive = replace(drive_from_speeds("run_b", np.full(10, 20.0)), start_unix_s=after_midnight_utc)
    assert drive_date(drive) == "2021-03-08"
    # a name that begins with a date says it, whatever the samples
    assert drive_date(replace(drive, name="2021-03-09-13-35-04_masterArray_0_4633")) == "2021-03-09"
    # digits in a date's shape that are no date, or a date run on into more digits: the samples
    assert drive_date(replace(drive, name="2021-13-45_run")) == "2021-03-08"
    assert drive_date(replace(drive, name="2021-03-091_run")) == "2021-03-08"


def test_every_shared_drive_is_named_by_its_first_samples_date_on_i24(shared_dir: Path) -> None:
    """The names' dates (the sessions' UTC stamps) are the traffic days the samples are from, so
    dating by name and by samples puts each drive on the same side of every fold."""
    data = shared_dir / "data"
    drives = [
        *load_drives(data / "trajectories"),
        *(one.drive for one in load_recorded_drives(data / "trajectories_with_inrix")),
    ]
    assert len(drives) == 41
    for drive in drives:
        local = datetime.fromtimestamp(drive.start_unix_s, CORRIDOR_TIMEZONE).date().isoformat()
        assert drive_date(drive) == drive.name[:10] == local, drive.name
