"""Policy files of a format the agent does not read, which the agent and the server must both
refuse: `acc` files of an earlier speed action, `accel` files of an unknown action."""

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


def accel_policy_bytes(accel_action: str) -> bytes:
    """A one-layer, two-output `accel` policy recording `accel_action`."""
    arrays = {
        "actuation": np.array("accel"),
        "accel_action": np.array(accel_action),
        "layer_0_weight": np.zeros((6, 2)),
        "layer_0_bias": np.zeros(2),
    }
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()
