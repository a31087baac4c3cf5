"""The TSE on the real drives: prediction beats raw INRIX, fusion improves it further."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.seed import seed_corridor_document
from planner.evaluation import DriveErrors, evaluate_drive
from planner.inputs import CorridorGrid
from planner.recorded import load_recorded_drive
from vehicle_agent.corridor import CorridorGeometry


@pytest.fixture(scope="module")
def drive_errors(shared_dir: Path) -> list[DriveErrors]:
    document = seed_corridor_document()
    grid = CorridorGrid.from_rows(document["corridor"], document["i24_segments"])
    geometry = CorridorGeometry.from_segments(
        grid.corridor_id, grid.lanes, document["i24_segments"]
    )
    inrix = document["inrix_segments"]
    columns = [int(segment["xd_code"].rsplit("-", 1)[1]) for segment in inrix]
    centers = np.array([(segment["start_x_m"] + segment["end_x_m"]) / 2 for segment in inrix])
    folders = sorted((shared_dir / "data/trajectories_with_inrix").iterdir())
    assert len(folders) == 2
    recorded = [load_recorded_drive(folder, geometry, columns, centers) for folder in folders]
    return [evaluate_drive(drive.drive, drive.inrix, grid) for drive in recorded]


def test_each_drive_is_evaluated_minute_after_minute(drive_errors: list[DriveErrors]) -> None:
    for errors in drive_errors:
        assert len(errors.truth_mps) >= 35  # ~8 minutes of decisions every 10 s
        assert np.all(errors.truth_mps > 0)


def test_prediction_beats_raw_inrix_on_every_drive(drive_errors: list[DriveErrors]) -> None:
    for errors in drive_errors:
        assert errors.mean_absolute_error("predicted") < errors.mean_absolute_error("inrix")


def test_fusing_the_cars_own_pings_beats_prediction_alone(drive_errors: list[DriveErrors]) -> None:
    for errors in drive_errors:
        assert errors.mean_absolute_error("fused") < errors.mean_absolute_error("predicted")
