"""A trained RL policy on the car: its observation, its action, and its network evaluated in numpy.

Paper section "ACC-Based Controller": the deployed controller is a PPO-trained policy. Training
happens in the simulator (`sim/rl`, which the car never installs); the car only evaluates the
network's mean action, a small multilayer perceptron, exported as a `.npz` of its weights. The
features and the decoding of the action are defined here, once, and the training environment
calls the same functions, so the car feeds the network exactly what it was trained on.

Observation (all makes, the paper's list): ego speed v, the planner's target v_s at the car's
position, the "minicar" flag l, and on `acc` cars the ACC speed setting s and gap setting g.
Added, because the car really holds it: the plan's target `PLAN_LOOKAHEAD_M` ahead (the agent has
the whole lane plan; the anticipation it allows is what smooths a wave before the car meets it).
Added on `accel` cars only (the RAV4 measures them, paper Table 2): the space gap and the leader's
relative speed. Files that record `accel_observation` = `commanded_accel` also read the
acceleration the agent last commanded (its `AccelLimiter`'s reference; at a take-over the car's
measured acceleration): the limiter's jerk limits make that a state of the car the request acts
from, and without it the network cannot tell a request that takes effect at once from one that
needs a second to ramp in. Files without `accel_observation` (the `radar` observation) read six.

Action, in [-1, 1] per component (PPO's Gaussian, clipped):
- `acc`: component 0 is the requested speed setting itself, around the plan's target at the
  car: v_s + 20 mph x a (0 asks for the plan's speed), which the paper's clip then bounds like
  every `acc` request; while no leader is detected (l off) the request is the clip's ceiling
  instead, so the ACC closes up to the leader it lost; component 1 picks the gap bars (thirds of
  [-1, 1] -> 1, 2, 3). Policy files record the speed action they were trained for, and a file
  trained for another is refused: those without `speed_action` (before 2026-12-01) read
  component 0 as a change from the last second's mean speed, and `around_plan` files were trained
  free to fall back out of radar range, which the rule now forbids.
- `accel`: component 0 is an acceleration request, 3 m/s^2 of braking at -1 and 1.5 m/s^2 at +1
  (the agent's AccelLimiter bounds), 0 at 0. Files that record `accel_action` =
  `request_time_margin` have a component 1 too: a time margin h = 0.75 (1 + a) s, in [0, 1.5] s,
  that the safety bound a_safe adds to the gap it keeps (`rl_accel.bounded_request`), so the
  network can move the bound it would otherwise only ride; files without `accel_action` (the
  `request` action) have component 0 alone. The car reads both.
"""

from __future__ import annotations

import hashlib
import io
import math
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from contract.units import MPS_PER_MPH
from vehicle_agent.controllers.acc_clip import MAX_SETTING_MPH
from vehicle_agent.controllers.base import NonFiniteAction

FloatArray = NDArray[np.float64]
PolicyActuation = Literal["acc", "accel"]
AccelAction = Literal["request", "request_time_margin"]
AccelObservation = Literal["radar", "commanded_accel"]
# An `accel` file's recorded variant (its action or its observation).
Variant = TypeVar("Variant", bound=str)

# Speeds enter the network divided by this (m/s; the 73 mph ceiling is 32.6 m/s).
SPEED_SCALE_MPS = 30.0
# The plan is also read this far ahead of the car (m).
PLAN_LOOKAHEAD_M = 500.0
# The cars' radar sees a leader within about 80-100 m (paper Table 2, "minicar"); a gap is
# divided by this, and reads as 1 without a leader.
GAP_SCALE_M = 100.0
# Relative speeds enter divided by this (m/s).
REL_SPEED_SCALE_MPS = 10.0
# `accel` action bounds (m/s^2): the agent's AccelLimiter range.
ACCEL_ACTION_MIN_MPS2 = -3.0
ACCEL_ACTION_MAX_MPS2 = 1.5
# The commanded acceleration enters divided by this (m/s^2): the range's braking end reads -1.
COMMANDED_ACCEL_SCALE_MPS2 = 3.0

# `acc` speed action: the requested setting is the plan's target plus this much times the output
# (mph) while a leader is detected, the clip's ceiling while none is; the name acc policy files
# record it under (`speed_action`).
SPEED_AROUND_PLAN_MPH = 20.0
ACC_SPEED_ACTION = "around_plan_closing_lost_lead"

# `accel` time margin (s) at action component 1 = -1 and +1: 0 keeps a_safe's own gap.
TIME_MARGIN_MIN_S = 0.0
TIME_MARGIN_MAX_S = 1.5

# What a policy file may unpack to (bytes): a 64 x 64 network is about 40 kB, and a small
# archive that unpacks to a gigabyte (a zip bomb) must be refused before it is read.
MAX_POLICY_UNPACKED_BYTES = 16 * 1024 * 1024
ACC_FEATURES = 6
ACCEL_FEATURES = 6
# Inputs of an `accel` policy per observation, and outputs of an `acc` policy (speed setting,
# gap bars) and of an `accel` one per action; the first observation and the first action are
# what a file that records none has.
ACCEL_OBSERVATION_SIZES: dict[AccelObservation, int] = {
    "radar": ACCEL_FEATURES,
    "commanded_accel": ACCEL_FEATURES + 1,
}
ACC_ACTION_SIZE = 2
ACCEL_ACTION_SIZES: dict[AccelAction, int] = {"request": 1, "request_time_margin": 2}


class PolicyFileError(ValueError):
    """A policy file that cannot be used: `label` names the file, `reason` says what is wrong."""

    def __init__(self, label: str, reason: str) -> None:
        super().__init__(f"{label}: {reason}")
        self.label = label
        self.reason = reason

    def __reduce__(self) -> tuple[type[PolicyFileError], tuple[str, str]]:
        # rebuilt from its two parts where it crosses a process (sim evaluate's workers)
        return (type(self), (self.label, self.reason))


def acc_features(
    speed_mps: ArrayLike,
    target_mps: ArrayLike,
    target_ahead_mps: ArrayLike,
    lead_present: ArrayLike,
    speed_setting_mph: ArrayLike,
    gap_setting: ArrayLike,
) -> FloatArray:
    """The `acc` observation (last axis: v, v_s, v_s ahead, l, s, g), scaled for the network."""
    setting = np.asarray(speed_setting_mph, dtype=np.float64) * MPS_PER_MPH
    return _feature_columns(
        np.asarray(speed_mps, dtype=np.float64) / SPEED_SCALE_MPS,
        np.asarray(target_mps, dtype=np.float64) / SPEED_SCALE_MPS,
        np.asarray(target_ahead_mps, dtype=np.float64) / SPEED_SCALE_MPS,
        np.asarray(lead_present, dtype=np.float64),
        setting / SPEED_SCALE_MPS,
        np.asarray(gap_setting, dtype=np.float64) - 2.0,
    )


def accel_features(
    speed_mps: ArrayLike,
    target_mps: ArrayLike,
    target_ahead_mps: ArrayLike,
    lead_present: ArrayLike,
    gap_m: ArrayLike,
    rel_speed_mps: ArrayLike,
    commanded_accel_mps2: ArrayLike | None = None,
) -> FloatArray:
    """The `accel` observation (v, v_s, v_s ahead, l, gap, lead - ego speed and, given it, the
    commanded acceleration), scaled: the `radar` observation, or `commanded_accel`'s.

    Without a leader in radar range the gap reads as the range and the relative speed as 0,
    and so does a leader measured beyond it: training's radar sees none past `GAP_SCALE_M`
    (`sim.av.RADAR_RANGE_M`), while the RAV4 reports leaders up to 250 m: the policy was never
    shown "present" with a gap past the range, and its answer there is untrained.
    """
    gap_measured = np.asarray(gap_m, dtype=np.float64)
    present = np.asarray(lead_present, dtype=bool) & (gap_measured <= GAP_SCALE_M)
    measured = np.minimum(gap_measured, GAP_SCALE_M)
    gap = np.where(present, measured, GAP_SCALE_M)
    rel = np.where(present, np.asarray(rel_speed_mps, dtype=np.float64), 0.0)
    columns = [
        np.asarray(speed_mps, dtype=np.float64) / SPEED_SCALE_MPS,
        np.asarray(target_mps, dtype=np.float64) / SPEED_SCALE_MPS,
        np.asarray(target_ahead_mps, dtype=np.float64) / SPEED_SCALE_MPS,
        present.astype(np.float64),
        gap / GAP_SCALE_M,
        rel / REL_SPEED_SCALE_MPS,
    ]
    if commanded_accel_mps2 is not None:
        columns.append(
            np.asarray(commanded_accel_mps2, dtype=np.float64) / COMMANDED_ACCEL_SCALE_MPS2
        )
    return _feature_columns(*columns)


def _feature_columns(*columns: FloatArray) -> FloatArray:
    """The features on the last axis. One car's step (every column a scalar, the car's and the
    simulator's case every 0.1 s) is one small array, built without broadcasting, which was
    most of a step's feature time; batches (the training environment's) broadcast."""
    if all(column.ndim == 0 for column in columns):
        return np.array(columns, dtype=np.float64)
    features: FloatArray = np.stack(np.broadcast_arrays(*columns), axis=-1)
    return features


def requested_speed_mph(
    action: ArrayLike, plan_target_mph: ArrayLike, lead_present: ArrayLike
) -> FloatArray:
    """v_action from action component 0: the plan's target v_s + SPEED_AROUND_PLAN_MPH x a
    while the minicar flag l is on; the clip's ceiling (73 mph) while it is off.

    A setting, not a change of speed: a network's bias is a fixed offset from the plan rather
    than a drift that integrates every step. The paper's clip bounds it afterwards, so with no
    leader detected the setting rises to the last second's mean speed + 5 mph and the stock ACC
    closes up to the leader it lost: the AV cannot fall back beyond its radar's range (80-100 m,
    paper Table 2), which is inside the gap envelope's 120 m, whatever the network asks. The car
    senses l on every make, so the rule uses nothing the road could not tell it.
    """
    value = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    around_plan = np.asarray(plan_target_mph, dtype=np.float64) + SPEED_AROUND_PLAN_MPH * value
    requested: FloatArray = np.where(
        np.asarray(lead_present, dtype=bool), around_plan, MAX_SETTING_MPH
    )
    return requested


def requested_gap_setting(action: ArrayLike) -> NDArray[np.int64]:
    """Gap bars from action component 1: [-1, -1/3) -> 1, [-1/3, 1/3) -> 2, [1/3, 1] -> 3."""
    value = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    bars: NDArray[np.int64] = np.where(value < -1.0 / 3.0, 1, np.where(value < 1.0 / 3.0, 2, 3))
    return bars


def requested_accel_mps2(action: ArrayLike) -> FloatArray:
    """The acceleration request: -1 -> -3 m/s^2, 0 -> 0, +1 -> +1.5 m/s^2."""
    value = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    accel: FloatArray = np.where(
        value < 0.0, -ACCEL_ACTION_MIN_MPS2 * value, ACCEL_ACTION_MAX_MPS2 * value
    )
    return accel


def requested_time_margin_s(action: ArrayLike) -> FloatArray:
    """The time margin a_safe adds to its gap: -1 -> 0 s, 0 -> 0.75 s, +1 -> 1.5 s."""
    value = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    margin: FloatArray = TIME_MARGIN_MIN_S + 0.5 * (value + 1.0) * (
        TIME_MARGIN_MAX_S - TIME_MARGIN_MIN_S
    )
    return margin


def observation_size(actuation: PolicyActuation, accel_observation: AccelObservation) -> int:
    """How many inputs a policy of `actuation` (and, for `accel`, `accel_observation`) reads."""
    if actuation == "accel":
        return ACCEL_OBSERVATION_SIZES[accel_observation]
    return ACC_FEATURES


def action_size(actuation: PolicyActuation, accel_action: AccelAction) -> int:
    """How many outputs a policy of `actuation` (and, for `accel`, `accel_action`) has."""
    if actuation == "accel":
        return ACCEL_ACTION_SIZES[accel_action]
    return ACC_ACTION_SIZE


@dataclass(frozen=True)
class PolicyNetwork:
    """A tanh MLP's deterministic action: mean = W_k(... tanh(W_1 x + b_1) ...) + b_k, clipped.

    `weights[i]` has shape (inputs, outputs), so a batch of observations (rows) multiplies on
    the left. `sha256` is the file's digest: what the car reports it runs. `accel_action` says
    how an `accel` policy's outputs are read (`request` for `acc` policies, which have one way),
    `accel_observation` what its inputs are (`radar` for `acc` policies).
    """

    actuation: PolicyActuation
    weights: tuple[FloatArray, ...]
    biases: tuple[FloatArray, ...]
    sha256: str
    accel_action: AccelAction = "request"
    accel_observation: AccelObservation = "radar"

    def action(self, features: FloatArray) -> FloatArray:
        """The mean action for one observation (1-D) or a batch (rows), clipped to [-1, 1];
        `NonFiniteAction` when any output is not a number. A file of finite but huge weights
        (1e308) loads and answers NaN, and each controller decodes only some outputs, each its
        own way: a NaN gap output read as 3 bars, a NaN time margin as none, a NaN speed with no
        leader as the ceiling, and the bad policy drove on instead of handing the car back."""
        hidden = features
        last = len(self.weights) - 1
        for index, (weight, bias) in enumerate(zip(self.weights, self.biases, strict=True)):
            hidden = hidden @ weight + bias
            if index < last:
                hidden = np.tanh(hidden)
        if not np.isfinite(hidden).all():
            raise NonFiniteAction(f"policy {self.sha256[:12]} answered {hidden}")
        # minimum(maximum()) is np.clip without its wrapper's cost
        clipped: FloatArray = np.minimum(np.maximum(hidden, -1.0), 1.0)
        return clipped


def save_policy(
    path: Path,
    actuation: PolicyActuation,
    weights: list[FloatArray],
    biases: list[FloatArray],
    accel_action: AccelAction = "request",
    accel_observation: AccelObservation = "radar",
) -> str:
    """Write a policy `.npz` (layer_i_weight / layer_i_bias, the actuation and, for `acc`, the
    speed action it was trained with, for `accel` any action but the plain request and any
    observation but `radar`); its sha256.

    A `request` file records no `accel_action` and a `radar` one no `accel_observation`, so such
    a file has the bytes (and sha256) it had before either existed."""
    arrays: dict[str, FloatArray | NDArray[np.str_]] = {"actuation": np.array(actuation)}
    if actuation == "acc":
        arrays["speed_action"] = np.array(ACC_SPEED_ACTION)
    else:
        if accel_action != "request":
            arrays["accel_action"] = np.array(accel_action)
        if accel_observation != "radar":
            arrays["accel_observation"] = np.array(accel_observation)
    for index, (weight, bias) in enumerate(zip(weights, biases, strict=True)):
        arrays[f"layer_{index}_weight"] = np.asarray(weight, dtype=np.float64)
        arrays[f"layer_{index}_bias"] = np.asarray(bias, dtype=np.float64)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as handle:
        np.savez(handle, **arrays)  # type: ignore[arg-type]
    return hashlib.sha256(path.read_bytes()).hexdigest()


def load_policy(path: Path, actuation: PolicyActuation) -> PolicyNetwork:
    """Read a policy `.npz` and check it drives `actuation` with the right shapes."""
    try:
        content = path.read_bytes()
    except OSError as error:
        raise PolicyFileError(str(path), f"{error.strerror or error}") from None
    return read_policy(content, actuation, str(path))


def _accel_variant(
    label: str,
    actuation: PolicyActuation,
    stored: str,
    known: Mapping[Variant, int],
    trained: str,
    verb: str,
) -> Variant:
    """The variant of `known` a file records (`stored`): any of them on an `accel` file, only
    the first (the one a file without the record has) on an `acc` file; else the refusal."""
    for variant in known:
        if stored == variant and (actuation == "accel" or variant == next(iter(known))):
            return variant
    raise PolicyFileError(
        label,
        f"an {actuation} policy trained {trained} {stored!r}, which this agent does "
        f"not {verb} (accel policies: one of {', '.join(known)}; acc policies: none)",
    )


def _check_declared_size(listing: zipfile.ZipFile, member: zipfile.ZipInfo, label: str) -> None:
    """Refuse an array whose header declares more data than its member holds: numpy allocates
    what the header declares before reading, so a 567-byte file declaring (2**40,) floats asked
    for 8 TiB (a MemoryError, which was the server's 500, on the loop that takes pings)."""
    if not member.filename.endswith(".npy"):
        return
    with listing.open(member) as stream:
        version = np.lib.format.read_magic(stream)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(stream)
        elif version == (2, 0):
            shape, _, dtype = np.lib.format.read_array_header_2_0(stream)
        else:
            raise PolicyFileError(label, f"{member.filename} is an .npy of version {version}")
    declared = math.prod(shape) * dtype.itemsize
    if declared > member.file_size:
        raise PolicyFileError(
            label,
            f"{member.filename} declares {shape} of {dtype}, {declared} bytes, in "
            f"{member.file_size}",
        )


def read_policy(content: bytes, actuation: PolicyActuation, label: str) -> PolicyNetwork:
    """A policy from the bytes of its `.npz` (`label` names it in errors): the server checks an
    upload and the agent a download with this before either is kept."""
    if not zipfile.is_zipfile(io.BytesIO(content)):
        raise PolicyFileError(label, "not a policy file (not an .npz archive)")
    try:
        with zipfile.ZipFile(io.BytesIO(content)) as listing:
            unpacked = sum(member.file_size for member in listing.infolist())
            if unpacked > MAX_POLICY_UNPACKED_BYTES:
                raise PolicyFileError(
                    label,
                    f"unpacks to {unpacked} bytes, more than a policy's "
                    f"{MAX_POLICY_UNPACKED_BYTES}",
                )
            for member in listing.infolist():
                _check_declared_size(listing, member, label)
    # NotImplementedError: a member needing a newer zip version than zipfile reads (its
    # "version needed to extract"), raised while the directory is read
    # RuntimeError: an encrypted member, opened without its password
    except (
        OSError,
        ValueError,
        zipfile.BadZipFile,
        NotImplementedError,
        zlib.error,
        RuntimeError,
    ) as error:
        raise PolicyFileError(label, f"not a policy file ({error})") from None
    try:
        with np.load(io.BytesIO(content), allow_pickle=False) as archive:
            stored = str(archive["actuation"])
            speed_action = str(archive["speed_action"]) if "speed_action" in archive.files else None
            stored_accel_action = (
                str(archive["accel_action"]) if "accel_action" in archive.files else "request"
            )
            stored_observation = (
                str(archive["accel_observation"])
                if "accel_observation" in archive.files
                else "radar"
            )
            layers = sum(1 for name in archive.files if name.endswith("_weight"))
            weights = tuple(
                np.asarray(archive[f"layer_{i}_weight"], dtype=np.float64) for i in range(layers)
            )
            biases = tuple(
                np.asarray(archive[f"layer_{i}_bias"], dtype=np.float64) for i in range(layers)
            )
    except (
        OSError,
        ValueError,
        KeyError,
        EOFError,
        zipfile.BadZipFile,
        zlib.error,
        # zipfile: a member compressed by a method it does not read (Deflate64), or encrypted
        NotImplementedError,
        RuntimeError,
        # numpy: an array of a structured dtype, which is no weight matrix
        TypeError,
    ) as error:
        raise PolicyFileError(label, f"not a policy file ({error})") from None
    if stored != actuation:
        raise PolicyFileError(label, f"a policy for actuation {stored}, not {actuation}")
    if actuation == "acc" and speed_action != ACC_SPEED_ACTION:
        trained_for = (
            "a change from the last second's mean speed (before 2026-12-01)"
            if speed_action is None
            else repr(speed_action)
        )
        raise PolicyFileError(
            label,
            f"an acc policy trained for the speed action {trained_for}, which this "
            f"agent does not read ({ACC_SPEED_ACTION!r}: the plan's target +/- "
            f"{SPEED_AROUND_PLAN_MPH:.0f} mph, the clip's ceiling with no leader detected): "
            "retrain it",
        )
    accel_action = _accel_variant(
        label, actuation, stored_accel_action, ACCEL_ACTION_SIZES, "for the accel action", "read"
    )
    accel_observation = _accel_variant(
        label, actuation, stored_observation, ACCEL_OBSERVATION_SIZES, "on the observation", "build"
    )
    if not weights:
        raise PolicyFileError(label, "no layers")
    inputs = observation_size(actuation, accel_observation)
    for index, (weight, bias) in enumerate(zip(weights, biases, strict=True)):
        if weight.ndim != 2 or weight.shape[0] != inputs or bias.shape != (weight.shape[1],):
            raise PolicyFileError(
                label,
                f"layer {index} has shape {weight.shape} and bias {bias.shape}, "
                f"expected ({inputs}, n) and (n,)",
            )
        if not (np.all(np.isfinite(weight)) and np.all(np.isfinite(bias))):
            raise PolicyFileError(label, f"layer {index} holds non-finite weights")
        inputs = weight.shape[1]
    outputs = action_size(actuation, accel_action)
    if inputs != outputs:
        kind = (
            f"an accel policy with the {accel_action!r} action"
            if actuation == "accel"
            else "an acc policy"
        )
        raise PolicyFileError(label, f"{inputs} outputs, {kind} has {outputs}")
    return PolicyNetwork(
        actuation,
        weights,
        biases,
        hashlib.sha256(content).hexdigest(),
        accel_action,
        accel_observation,
    )
