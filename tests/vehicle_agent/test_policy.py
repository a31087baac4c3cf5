"""The car's RL runtime: features, action decoding, the numpy network and the policy file checks."""

from __future__ import annotations

import io
import math
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from contract.controllers import RlParams
from tests.support.policies import acc_policy_bytes
from vehicle_agent.controllers import AccelCommand, AccSetPoint, Observation, TargetProfile
from vehicle_agent.controllers.base import NonFiniteAction
from vehicle_agent.controllers.policy import (
    ACC_SPEED_ACTION,
    PolicyFileError,
    acc_features,
    accel_features,
    load_policy,
    read_policy,
    requested_accel_mps2,
    requested_gap_setting,
    requested_speed_mph,
    requested_time_margin_s,
    save_policy,
)
from vehicle_agent.controllers.rl_acc import RlAccController
from vehicle_agent.controllers.rl_accel import RlAccelController, bounded_request


def test_acc_features_are_the_papers_list_scaled() -> None:
    # v = 15 m/s, v_s = 24 m/s, 500 m ahead 12 m/s, minicar on, s = 50 mph (22.352 m/s), g = 3.
    features = acc_features(15.0, 24.0, 12.0, True, 50.0, 3)
    np.testing.assert_allclose(features, [0.5, 0.8, 0.4, 1.0, 22.352 / 30.0, 1.0])


def test_accel_features_read_no_leader_as_the_radar_range_and_no_relative_speed() -> None:
    seen = accel_features(30.0, 30.0, 30.0, True, 40.0, -5.0)
    np.testing.assert_allclose(seen, [1.0, 1.0, 1.0, 1.0, 0.4, -0.5])
    unseen = accel_features(30.0, 30.0, 30.0, False, math.inf, 7.0)
    np.testing.assert_allclose(unseen, [1.0, 1.0, 1.0, 0.0, 1.0, 0.0])


def test_a_leader_measured_beyond_the_radar_range_of_training_reads_as_none() -> None:
    """Training's radar sees no leader past 100 m; the RAV4 reports them up to 250 m, and the
    policy, never shown one present that far, asked for twice the acceleration."""
    far = accel_features(30.0, 20.0, 20.0, True, 180.0, -8.0)
    np.testing.assert_allclose(far, accel_features(30.0, 20.0, 20.0, False, math.inf, 0.0))
    edge = accel_features(30.0, 20.0, 20.0, True, 100.0, -8.0)
    np.testing.assert_allclose(edge, [1.0, 2 / 3, 2 / 3, 1.0, 1.0, -0.8])


def test_the_commanded_accel_observation_adds_the_limiters_last_output_over_three() -> None:
    features = accel_features(30.0, 30.0, 30.0, True, 40.0, -5.0, -1.5)
    np.testing.assert_allclose(features, [1.0, 1.0, 1.0, 1.0, 0.4, -0.5, -0.5])
    batch = accel_features([30.0, 12.0], 30.0, 30.0, True, 40.0, -5.0, [0.75, -1.5])
    np.testing.assert_array_equal(batch[1, :6], accel_features(12.0, 30.0, 30.0, True, 40.0, -5.0))
    np.testing.assert_allclose(batch[:, 6], [0.25, -0.5])


def test_one_cars_features_are_its_row_of_a_batch_bit_for_bit() -> None:
    # the car's step builds its one row without broadcasting; the training environment's
    # batches broadcast: the network must see the same numbers from both
    acc_batch = acc_features([15.0, 7.3], 24.1, [12.0, 31.7], [True, False], 50.0, [3, 1])
    np.testing.assert_array_equal(acc_features(7.3, 24.1, 31.7, False, 50.0, 1), acc_batch[1])
    accel_batch = accel_features(
        [30.0, 11.9], [30.0, 8.2], 30.0, [False, True], [math.inf, 37.5], [7.0, -2.6]
    )
    np.testing.assert_array_equal(accel_features(11.9, 8.2, 30.0, True, 37.5, -2.6), accel_batch[1])
    np.testing.assert_array_equal(
        accel_features(30.0, 30.0, 30.0, False, math.inf, 7.0), accel_batch[0]
    )


def test_acc_action_is_a_setting_around_the_plans_target_while_a_leader_is_seen() -> None:
    # plan 60 mph: -1 -> 40 mph, 0 -> 60 (the plan), +1 -> 80 (the clip bounds it later);
    # beyond [-1, 1] is clipped
    np.testing.assert_allclose(
        requested_speed_mph(np.array([-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 3.0]), 60.0, True),
        [40.0, 40.0, 50.0, 60.0, 70.0, 80.0, 80.0],
    )
    # no leader detected: the clip's ceiling, whatever the network asks
    np.testing.assert_allclose(
        requested_speed_mph(np.array([-1.0, 0.0, 1.0]), 60.0, np.array([False, True, False])),
        [73.0, 60.0, 73.0],
    )
    np.testing.assert_array_equal(
        requested_gap_setting(np.array([-1.0, -0.34, -0.33, 0.33, 0.34, 1.0])), [1, 1, 2, 2, 3, 3]
    )


def test_accel_action_maps_to_the_limiter_range_with_zero_at_zero() -> None:
    np.testing.assert_allclose(
        requested_accel_mps2(np.array([-5.0, -1.0, -0.5, 0.0, 0.5, 1.0])),
        [-3.0, -3.0, -1.5, 0.0, 0.75, 1.5],
    )


def test_time_margin_maps_minus_one_to_none_and_plus_one_to_one_and_a_half_seconds() -> None:
    np.testing.assert_allclose(
        requested_time_margin_s(np.array([-3.0, -1.0, 0.0, 0.5, 1.0, 4.0])),
        [0.0, 0.0, 0.75, 1.125, 1.5, 1.5],
    )


def two_layer_policy(
    tmp_path: Path, actuation: str, outputs: int, accel_action: str = "request"
) -> Path:
    """Hidden layer: 1 unit reading v only (weight 2); head: `outputs` copies of it."""
    hidden_weight = np.zeros((6, 1))
    hidden_weight[0, 0] = 2.0
    path = tmp_path / f"{actuation}-{accel_action}.npz"
    save_policy(
        path,
        "acc" if actuation == "acc" else "accel",
        [hidden_weight, np.ones((1, outputs))],
        [np.array([-1.0]), np.zeros(outputs)],
        "request_time_margin" if accel_action == "request_time_margin" else "request",
    )
    return path


def test_network_is_a_tanh_mlp_with_a_linear_clipped_head(tmp_path: Path) -> None:
    network = load_policy(two_layer_policy(tmp_path, "accel", 1), "accel")
    # v feature 0.5 -> tanh(2 * 0.5 - 1) = 0; 0.8 -> tanh(0.6) = 0.537; 5 -> tanh(9) ~ 1 -> 1
    batch = np.zeros((3, 6))
    batch[:, 0] = [0.5, 0.8, 5.0]
    np.testing.assert_allclose(network.action(batch)[:, 0], [0.0, math.tanh(0.6), math.tanh(9)])
    assert len(network.sha256) == 64


@pytest.mark.parametrize("lead", [False, True])
def test_a_policy_answering_no_number_fails_its_controller_whatever_it_decodes(
    tmp_path: Path, lead: bool
) -> None:
    """Finite weights of 1e308 load, and the outputs sum to inf - inf. rl_acc with no leader in
    sight reads only the gap output, and read NaN as 3 bars and the speed as the ceiling: the
    bad policy drove on. Any output that is no number is the controller's failure now."""
    hidden = np.zeros((6, 4))
    hidden[0, :] = [10.0, 10.0, -10.0, -10.0]  # tanh: (1, 1, -1, -1) at any speed
    path = tmp_path / "overflowing.npz"
    sha256 = save_policy(path, "acc", [hidden, np.full((4, 2), 1e308)], [np.zeros(4), np.zeros(2)])
    controller = RlAccController("acc", RlParams(policy=str(path), policy_sha256=sha256))
    observation = Observation(
        time_s=0.1,
        speed_mps=25.0,
        target_speed_mps=25.0,
        lead_present=lead,
        acc_speed_setting_mph=56.0,
        acc_gap_setting=2,
    )
    with (
        np.errstate(over="ignore", invalid="ignore"),
        pytest.raises(NonFiniteAction, match="answered"),
    ):
        controller.step(observation)


def test_policy_files_are_checked_before_use(tmp_path: Path) -> None:
    acc = two_layer_policy(tmp_path, "acc", 2)
    with pytest.raises(PolicyFileError, match="a policy for actuation acc, not accel"):
        load_policy(acc, "accel")
    wrong_outputs = two_layer_policy(tmp_path, "accel", 2)
    with pytest.raises(
        PolicyFileError, match="2 outputs, an accel policy with the .request. action has 1"
    ):
        load_policy(wrong_outputs, "accel")
    one_output_acc = two_layer_policy(tmp_path, "acc", 1)
    with pytest.raises(PolicyFileError, match="1 outputs, an acc policy has 2"):
        load_policy(one_output_acc, "acc")
    with pytest.raises(PolicyFileError, match="No such file"):
        load_policy(tmp_path / "missing.npz", "acc")
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a zip")
    with pytest.raises(PolicyFileError, match="not a policy file"):
        load_policy(garbage, "acc")
    bad = tmp_path / "nan.npz"
    save_policy(bad, "accel", [np.full((6, 1), np.nan)], [np.zeros(1)])
    with pytest.raises(PolicyFileError, match="non-finite weights"):
        load_policy(bad, "accel")
    narrow = tmp_path / "narrow.npz"
    save_policy(narrow, "accel", [np.zeros((5, 1))], [np.zeros(1)])
    with pytest.raises(PolicyFileError, match=r"layer 0 has shape \(5, 1\)"):
        load_policy(narrow, "accel")


def test_accel_files_say_which_action_they_were_trained_for(tmp_path: Path) -> None:
    """A plain request file records no action, so its bytes are those written before the time
    margin existed; a margin file records it and needs its second output; an action this agent
    does not know, or one recorded on an acc file, is refused, saying which."""
    plain = two_layer_policy(tmp_path, "accel", 1)
    with np.load(plain) as archive:
        assert "accel_action" not in archive.files
    assert load_policy(plain, "accel").accel_action == "request"
    margin = two_layer_policy(tmp_path, "accel", 2, "request_time_margin")
    assert load_policy(margin, "accel").accel_action == "request_time_margin"
    short = tmp_path / "short.npz"
    save_policy(short, "accel", [np.zeros((6, 1))], [np.zeros(1)], "request_time_margin")
    with pytest.raises(PolicyFileError, match="1 outputs, .* 'request_time_margin' action has 2"):
        load_policy(short, "accel")
    for actuation, action in (("accel", "time_gap_only"), ("acc", "request_time_margin")):
        arrays = dict(np.load(two_layer_policy(tmp_path, actuation, 2)))
        arrays["accel_action"] = np.array(action)
        odd = tmp_path / f"odd-{actuation}.npz"
        np.savez(odd, **arrays)
        with pytest.raises(PolicyFileError, match=f"accel action '{action}', which this agent"):
            load_policy(odd, actuation)  # type: ignore[arg-type]


def test_rl_acc_requests_the_networks_setting_around_the_plans_target(tmp_path: Path) -> None:
    controller = RlAccController("acc", RlParams(policy=str(two_layer_policy(tmp_path, "acc", 2))))
    # v = 15 m/s -> feature 0.5 -> action (0, 0): the plan's 20 m/s (44.74 mph), the middle gap
    seen = Observation(time_s=0.0, speed_mps=15.0, target_speed_mps=20.0, lead_present=True)
    action = controller.step(seen)
    assert isinstance(action, AccSetPoint)
    assert action.requested_speed_mph == pytest.approx(20.0 / 0.44704)
    assert (action.speed_setting_mph, action.gap_setting) == (45, 2)
    # the leader lost: the clip's ceiling (which the clip then bounds to mean + 5 mph)
    lost = controller.step(Observation(time_s=0.1, speed_mps=15.0, target_speed_mps=20.0))
    assert isinstance(lost, AccSetPoint)
    assert (lost.speed_setting_mph, lost.gap_setting) == (73, 2)


def test_an_acc_policy_of_an_earlier_speed_action_is_refused(tmp_path: Path) -> None:
    """A file without `speed_action` was trained to read its output as a change from the last
    second's mean speed, an `around_plan` file to fall back out of radar range at will: run under
    today's action either would meet what it was not trained for, so it is refused, saying why."""
    earlier = tmp_path / "earlier.npz"
    earlier.write_bytes(acc_policy_bytes(None))
    with pytest.raises(PolicyFileError, match="change from the last second's mean speed"):
        load_policy(earlier, "acc")
    around_plan = tmp_path / "around_plan.npz"
    around_plan.write_bytes(acc_policy_bytes("around_plan"))
    with pytest.raises(PolicyFileError, match="speed action 'around_plan', which"):
        load_policy(around_plan, "acc")


def lead_measured(time_s: float, speed: float, gap: float, rel: float) -> Observation:
    """A RAV4's observation: a leader `gap` m ahead at `rel` m/s, a flat plan at `speed`."""
    return Observation(
        time_s=time_s,
        speed_mps=speed,
        target_speed_mps=speed,
        position_m=0.0,
        target=TargetProfile(np.array([0.0, 1000.0]), np.array([speed, speed])),
        lead_present=True,
        lead_distance_m=gap,
        lead_rel_speed_mps=rel,
    )


def test_rl_accel_request_never_exceeds_the_safety_term(tmp_path: Path) -> None:
    path = two_layer_policy(tmp_path, "accel", 1)
    controller = RlAccelController("accel", RlParams(policy=str(path)))
    free = controller.step(Observation(time_s=0.0, speed_mps=30.0, target_speed_mps=30.0))
    # v feature 1 -> tanh(1) = 0.76 -> 1.14 m/s^2 with no leader measured
    assert free == AccelCommand(pytest.approx(1.5 * math.tanh(1.0)))
    close = controller.step(lead_measured(0.1, 30.0, 10.0, -5.0))
    assert isinstance(close, AccelCommand)
    assert close.accel_mps2 == -3.0  # a_safe far below: the limiter's floor
    # the network's own request is kept beside the command, for the diagnosis of the bound
    assert free.requested_accel_mps2 == pytest.approx(1.5 * math.tanh(1.0))
    assert close.requested_accel_mps2 > close.accel_mps2


def test_a_time_margin_bounds_the_request_by_a_safe_from_further_back() -> None:
    """v = 20 m/s behind a leader at the same speed 60 m ahead (lead accel 0): room = 60 - 8 +
    20^2 / (2 x 5) = 92 m, v_safe = sqrt(2 x 3 x 92) = 23.49 m/s, a_safe = 0.5 (23.49 - 20) =
    +1.75 m/s^2, above a +1 request. A 1 s margin reads the gap as 40 m: room 72 m, v_safe =
    sqrt(432) = 20.78 m/s, a_safe = 0.5 x 0.78 = +0.39 m/s^2, which the command becomes."""
    assert bounded_request(1.0, 20.0, 60.0, 0.0, 0.0) == pytest.approx(1.0)
    assert bounded_request(1.0, 20.0, 60.0, 0.0, 0.0, 0.0) == pytest.approx(1.0)
    expected = 0.5 * (math.sqrt(432.0) - 20.0)
    assert bounded_request(1.0, 20.0, 60.0, 0.0, 0.0, 1.0) == pytest.approx(expected)
    assert expected == pytest.approx(0.392, abs=1e-3)
    # no leader measured: nothing to keep a margin from
    assert bounded_request(1.0, 20.0, None, None, 0.0, 1.5) == 1.0


def test_rl_accel_with_a_time_margin_policy_adds_its_margin_to_the_bound(tmp_path: Path) -> None:
    path = two_layer_policy(tmp_path, "accel", 2, "request_time_margin")
    controller = RlAccelController("accel", RlParams(policy=str(path)))
    # v = 15 m/s -> feature 0.5 -> both outputs 0: request 0 m/s^2, margin 0.75 s (11.25 m)
    command = controller.step(lead_measured(0.0, 15.0, 20.0, 0.0))
    assert isinstance(command, AccelCommand)
    assert command.time_margin_s == pytest.approx(0.75)
    assert command.requested_accel_mps2 == pytest.approx(0.0)
    assert command.accel_mps2 == pytest.approx(bounded_request(0.0, 15.0, 20.0, 0.0, 0.0, 0.75))
    assert command.accel_mps2 < bounded_request(0.0, 15.0, 20.0, 0.0, 0.0) - 0.1


def commanded_accel_policy(tmp_path: Path, inputs: int = 7) -> Path:
    """One linear layer reading the commanded acceleration only: action = 2 x its feature."""
    weight = np.zeros((inputs, 1))
    weight[-1, 0] = 2.0
    path = tmp_path / f"commanded-{inputs}.npz"
    save_policy(path, "accel", [weight], [np.zeros(1)], accel_observation="commanded_accel")
    return path


def test_accel_files_say_what_they_observe(tmp_path: Path) -> None:
    """A radar file records no observation (the bytes written before the commanded
    acceleration existed) and has six inputs; a commanded_accel file records it and needs a
    seventh; one this agent does not build, or one recorded on an acc file, is refused."""
    radar = two_layer_policy(tmp_path, "accel", 1)
    with np.load(radar) as archive:
        assert "accel_observation" not in archive.files
    assert load_policy(radar, "accel").accel_observation == "radar"
    network = load_policy(commanded_accel_policy(tmp_path), "accel")
    assert network.accel_observation == "commanded_accel"
    with pytest.raises(PolicyFileError, match=r"layer 0 has shape \(6, 1\) .* expected \(7, n\)"):
        load_policy(commanded_accel_policy(tmp_path, inputs=6), "accel")
    for actuation, observation in (("accel", "lidar"), ("acc", "commanded_accel")):
        arrays = dict(np.load(two_layer_policy(tmp_path, actuation, 2)))
        arrays["accel_observation"] = np.array(observation)
        odd = tmp_path / f"odd-observation-{actuation}.npz"
        np.savez(odd, **arrays)
        with pytest.raises(
            PolicyFileError, match=f"observation '{observation}', which this agent does not build"
        ):
            load_policy(odd, actuation)  # type: ignore[arg-type]


def test_rl_accel_feeds_a_commanded_accel_policy_what_the_limiter_let_through(
    tmp_path: Path,
) -> None:
    """-1.5 m/s^2 let through reads -0.5, the network asks -1 (-3 m/s^2); +0.75 reads +0.25,
    it asks +0.5 (+0.75 m/s^2). Without the figure the controller fails, so the agent hands
    the car back rather than guess it."""
    path = commanded_accel_policy(tmp_path)
    controller = RlAccelController("accel", RlParams(policy=str(path)))
    braking = controller.step(
        Observation(time_s=0.0, speed_mps=20.0, target_speed_mps=20.0, commanded_accel_mps2=-1.5)
    )
    assert braking == AccelCommand(pytest.approx(-3.0))
    easing = controller.step(
        Observation(time_s=0.1, speed_mps=20.0, target_speed_mps=20.0, commanded_accel_mps2=0.75)
    )
    assert easing == AccelCommand(pytest.approx(0.75))
    with pytest.raises(ValueError, match="reads the commanded acceleration"):
        controller.step(Observation(time_s=0.2, speed_mps=20.0, target_speed_mps=20.0))


@given(
    request=st.floats(-10, 10),
    speed=st.floats(0, 40),
    gap=st.floats(0, 200),
    rel=st.floats(-20, 20),
)
def test_bounded_request_stays_within_the_limiter_range(
    request: float, speed: float, gap: float, rel: float
) -> None:
    command = bounded_request(request, speed, gap, rel, 0.0)
    assert -3.0 <= command <= 1.5
    assert command <= max(request, -3.0)


@given(
    request=st.floats(-3, 1.5),
    speed=st.floats(0, 40),
    gap=st.floats(0, 200),
    rel=st.floats(-20, 20),
    margin=st.floats(0, 1.5),
)
def test_a_time_margin_never_loosens_the_bound(
    request: float, speed: float, gap: float, rel: float, margin: float
) -> None:
    assert bounded_request(request, speed, gap, rel, 0.0, margin) <= bounded_request(
        request, speed, gap, rel, 0.0
    )


def zip_with_header_field(content: bytes, local_offset: int, value: int) -> bytes:
    """`content` (a zip archive) with one 2-byte field of every member's headers set: at
    `local_offset` in each local header, 2 bytes further on in each central one."""
    data = bytearray(content)
    for signature, offset in ((b"PK\x03\x04", local_offset), (b"PK\x01\x02", local_offset + 2)):
        found = data.find(signature)
        while found >= 0:
            data[found + offset : found + offset + 2] = value.to_bytes(2, "little")
            found = data.find(signature, found + 4)
    return bytes(data)


def test_archives_no_policy_could_be_are_refused_as_policy_files(tmp_path: Path) -> None:
    """Each once escaped as another error: a 500 on upload, a crashed download on the car."""
    good = acc_policy_bytes(ACC_SPEED_ACTION)
    read_policy(good, "acc", "good")  # itself a policy
    deflate64 = zip_with_header_field(good, 8, 9)  # compression method 9: Deflate64
    encrypted = zip_with_header_field(good, 6, 1)  # general-purpose flag bit 0: encrypted
    newer_zip = zip_with_header_field(good, 4, 84)  # version needed to extract: 8.4
    bomb = tmp_path / "bomb.npz"
    np.savez_compressed(bomb, actuation=np.array("acc"), layer_0_weight=np.zeros((4096, 1024)))
    structured = tmp_path / "structured.npz"
    np.savez(
        structured,
        actuation=np.array("acc"),
        speed_action=np.array(ACC_SPEED_ACTION),
        layer_0_weight=np.zeros(6, dtype=[("a", "f8"), ("b", "f8")]),
        layer_0_bias=np.zeros(2),
    )
    assert bomb.stat().st_size < 100_000  # 32 MiB of zeros, packed small
    # an array header declaring (2**40,) floats over no data: numpy allocated 8 TiB to read it
    declares_more = io.BytesIO()
    with zipfile.ZipFile(declares_more, "w") as archive:
        archive.writestr("actuation.npy", npy_bytes(np.array("acc")))
        header = npy_bytes(np.zeros(64)).replace(b"(64,)", b"(1099511627776,)")
        archive.writestr("layer_0_weight.npy", header[: header.index(b"\n") + 1])
    cases = {
        "deflate64": (deflate64, "not a policy file"),
        "encrypted": (encrypted, "not a policy file"),
        "newer zip": (newer_zip, "not a policy file .zip file version 8.4"),
        "bomb": (bomb.read_bytes(), "unpacks to 33554[0-9]+ bytes, more than a policy's"),
        "structured": (structured.read_bytes(), "not a policy file"),
        "declares more": (declares_more.getvalue(), r"declares \(1099511627776,\) of float64"),
    }
    for name, (content, message) in cases.items():
        with pytest.raises(PolicyFileError, match=message):
            read_policy(content, "acc", name)


def npy_bytes(array: np.ndarray) -> bytes:
    """`array` as the bytes of an .npy file."""
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def test_a_policy_error_crosses_a_process_with_its_reason() -> None:
    """Raised in one of `sim evaluate`'s workers, an error that cannot be rebuilt broke the
    pool ("A result has failed to un-pickle") instead of naming the policy's fault."""
    error = pickle.loads(pickle.dumps(PolicyFileError("policy abc", "no layers")))
    assert (error.label, error.reason, str(error)) == (
        "policy abc",
        "no layers",
        "policy abc: no layers",
    )
