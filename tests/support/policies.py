"""Policy files of an earlier `acc` format, which the agent and the server must both refuse."""

from __future__ import annotations

import io

import numpy as np


def acc_policy_bytes(speed_action: str | None) -> bytes:
    """A one-layer `acc` policy recording `speed_action` (None: no record, as before 2026-12-01)."""
    arrays = {
        "actuation": np.array("acc"),
        "layer_0_weight": np.zeros((6, 2)),
        "layer_0_bias": np.zeros(2),
    }
    if speed_action is not None:
        arrays["speed_action"] = np.array(speed_action)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()
