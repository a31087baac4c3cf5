"""Policy files of a format the agent does not read, which the agent and the server must both
refuse (`acc` files of an earlier speed action, `accel` files of an unknown action or
observation), and `accel` files of the formats it reads beside the shipped one."""

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


def accel_policy_bytes(
    accel_action: str | None = None, accel_observation: str | None = None
) -> bytes:
    """A one-layer `accel` policy recording `accel_action` (two outputs; None: no record, one)
    and `accel_observation` (None: no record; seven inputs for `commanded_accel`, else six)."""
    inputs = 7 if accel_observation == "commanded_accel" else 6
    outputs = 1 if accel_action is None else 2
    arrays = {
        "actuation": np.array("accel"),
        "layer_0_weight": np.zeros((inputs, outputs)),
        "layer_0_bias": np.zeros(outputs),
    }
    if accel_action is not None:
        arrays["accel_action"] = np.array(accel_action)
    if accel_observation is not None:
        arrays["accel_observation"] = np.array(accel_observation)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()
