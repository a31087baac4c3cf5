"""Simulated trajectories written as I-24 MOTION trajectory documents (a JSON array).

The documents carry the fields of the real record in ../shared/data/i24motion (`_id`,
`timestamp`, `x_position`, `y_position`, dimensions, `coarse_vehicle_class`, `direction`, scores,
...), positions in feet through `MotionFrame`, so a simulated hour goes through the same importer
as a real day. A fleet car's document adds `smoothfleet_fleet: true` (MOTION has no such field;
the importer keeps it so the generated fleet can be told apart).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import orjson

from sim.motion.frame import MotionFrame
from sim.motion.traffic import SimulatedTrajectory

# Positions to 0.01 ft (3 mm) and times to 0.1 ms keep the files half the size of full doubles.
POSITION_DECIMALS = 2
TIME_DECIMALS = 4


def motion_document(
    trajectory: SimulatedTrajectory, frame: MotionFrame, run_id: int
) -> dict[str, Any]:
    """One MOTION trajectory document for a simulated vehicle."""
    x_ft = np.round(frame.x_ft(trajectory.x_m), POSITION_DECIMALS)
    y_ft = np.full(len(x_ft), round(float(frame.y_ft(trajectory.lane)), POSITION_DECIMALS))
    times = np.round(trajectory.timestamps, TIME_DECIMALS)
    object_id = f"{run_id & 0xFFFFFFFF:08x}{trajectory.vehicle_index:016x}"
    document: dict[str, Any] = {
        "_id": {"$oid": object_id},
        "timestamp": times,
        "x_position": x_ft,
        "y_position": y_ft,
        "road_segment_ids": [-1],
        "flags": [],
        "length": trajectory.length_ft,
        "width": trajectory.width_ft,
        "height": trajectory.height_ft,
        "merged_ids": [],
        "fragment_ids": [{"$oid": object_id}],
        "coarse_vehicle_class": trajectory.vehicle_class,
        "fine_vehicle_class": -1,
        "direction": frame.direction,
        "compute_node_id": "smoothfleet-sim",
        "local_fragment_id": [[trajectory.vehicle_index]],
        "starting_x": float(x_ft[0]),
        "first_timestamp": float(times[0]),
        "configuration_id": -1,
        "ending_x": float(x_ft[-1]),
        "last_timestamp": float(times[-1]),
        "x_score": 0.0,
        "y_score": 0.0,
    }
    if trajectory.is_fleet:
        document["smoothfleet_fleet"] = True
    return document


def write_motion_json(
    path: Path, trajectories: Iterable[SimulatedTrajectory], frame: MotionFrame, run_id: int
) -> tuple[int, int]:
    """Stream trajectories into one MOTION JSON file; return (documents, points) written."""
    documents = points = 0
    with path.open("wb") as out:
        out.write(b"[\n")
        for trajectory in trajectories:
            if documents:
                out.write(b",\n")
            document = motion_document(trajectory, frame, run_id)
            out.write(orjson.dumps(document, option=orjson.OPT_SERIALIZE_NUMPY))
            documents += 1
            points += len(trajectory.x_m)
        out.write(b"\n]\n")
    return documents, points
