"""MOTION documents written by hand for the import and Edie tests."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from contract.units import METRES_PER_FOOT
from sim.motion.frame import EASTBOUND, MotionFrame

# x_m = x_ft * 0.3048: positions in the tests are written in metres.
METRIC_FRAME = MotionFrame(direction=EASTBOUND, anchor_x_ft=0.0, anchor_x_m=0.0)
LANE_Y_FT = {1: -18.0, 2: -30.0, 3: -42.0}  # lane centres on the eastbound side


def document(
    oid: str,
    time_s: Sequence[float],
    x_m: Sequence[float],
    lane: int = 1,
    direction: int = EASTBOUND,
    vehicle_class: int = 1,
    **extra: Any,
) -> dict[str, Any]:
    """A MOTION document with positions given in metres along METRIC_FRAME."""
    return {
        "_id": {"$oid": oid},
        "timestamp": list(time_s),
        "x_position": [x / METRES_PER_FOOT for x in x_m],
        "y_position": [LANE_Y_FT[lane]] * len(time_s),
        "length": 15.0,
        "width": 6.0,
        "height": 5.0,
        "coarse_vehicle_class": vehicle_class,
        "direction": direction,
        **extra,
    }


def write(path: Path, documents: Sequence[object]) -> Path:
    """A MOTION file: a pretty-printed JSON array, like the published ones."""
    path.write_text(json.dumps(list(documents), indent=1))
    return path
