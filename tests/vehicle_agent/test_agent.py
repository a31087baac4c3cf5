"""The agent's control loop against the car emulator on a virtual bus, in simulated time:
taking over, reaching set points, handing back within one control period, bad input."""

from __future__ import annotations

import itertools
import math
from contextlib import AbstractContextManager
from dataclasses import replace
from datetime import datetime, timedelta
from pathlib import Path

import can
import numpy as np
import pytest

from contract.corridor import CorridorGeometry
from contract.units import MPS_PER_MPH
from sim.emulator.leaders import ConstantSpeedLeader, SpeedProfileLeader
from sim.emulator.rig import Rig, rig, seed_corridor_document, uniform_plan
from vehicle_agent.agent import FAULT_HOLDS_S, GPS_MAX_AGE_S
from vehicle_agent.cars import CarReading, CruiseButton
from vehicle_agent.controllers import AccelCommand, Action, Observation
from vehicle_agent.controllers.microaccel import MicroAccelController
from vehicle_agent.controllers.policy import save_policy
from vehicle_agent.engage import CHECKS, Mode
from vehicle_agent.gps import GpsFix
from vehicle_agent.plan import Plan
from vehicle_agent.ports import GpioButtonBoard
from vehicle_agent.safety import SafetyLayer, SafetyLimits
from vehicle_agent.spool import PingSpool

CONTROL_PERIOD_S = 0.1


def engaged(r: Rig) -> bool:
    return r.agent.state.mode is Mode.ENGAGED


def engage_and_settle(r: Rig, set_speed_mph: int = 50) -> None:
    r.emulator.driver_engage(set_speed_mph=set_speed_mph)
    r.run(5.0, until=lambda: engaged(r))
    assert engaged(r), r.agent.state.reason


def test_sequencer_reaches_the_requested_set_speed_and_gap_and_stops(
    tmp_path: Path, dbc_cache: Path
) -> None:
    # simple on a 2018-20 Rogue (button frames on CAN; the 2023 car's board has its own test
    # in test_nissan_rogue_2023.py): target 60 mph (26.82 m/s), gap 1 bar; the clip lets the
    # setting rise at most 5 mph above the last second's mean speed, so the setting climbs
    # with the car.
    with rig(
        "nissan_rogue_2018",
        tmp_path,
        dbc_cache,
        controller="simple",
        params={"gap_setting": 1},
        speed_mps=22.352,
    ) as r:
        engage_and_settle(r, 50)
        r.run(
            60.0,
            until=lambda: r.emulator.acc.set_speed_mph == 60 and r.emulator.acc.gap_setting == 1,
        )
        assert r.emulator.acc.set_speed_mph == 60
        assert r.emulator.acc.gap_setting == 1
        frames = r.emulator.agent_frames
        presses = r.agent.sequencer.presses
        r.run(10.0)
        assert r.agent.sequencer.presses == presses
        assert r.emulator.agent_frames <= frames + 3  # at most the trailing release frames
        assert r.emulator.acc.set_speed_mph == 60
        assert engaged(r)
        assert not r.agent.sequencer.stalled
        assert r.agent.safety.refused == {}


@pytest.mark.parametrize("key", ["nissan_rogue", "cadillac_xt5"])
def test_microaccel_acc_drives_each_button_car(key: str, tmp_path: Path, dbc_cache: Path) -> None:
    with rig(key, tmp_path, dbc_cache, controller="microaccel_acc", speed_mps=22.352) as r:
        engage_and_settle(r, 50)
        r.run(30.0)
        assert engaged(r)
        assert r.emulator.acc.set_speed_mph is not None
        assert r.emulator.acc.set_speed_mph > 55
        assert r.agent.sequencer.presses > 3
        assert r.emulator.agent_bad_frames == 0
        assert r.agent.reader.stats.errors == {}


def hand_back_time(r: Rig, cause_at: float) -> float:
    r.run(3.0, until=lambda: not engaged(r))
    assert not engaged(r)
    return r.clock.monotonic() - cause_at


def test_stale_plan_hands_back_within_one_period(tmp_path: Path, dbc_cache: Path) -> None:
    with rig(
        "nissan_rogue",
        tmp_path,
        dbc_cache,
        controller="simple",
        config_fields={"stale_plan_after_s": 5.0},
    ) as r:
        engage_and_settle(r)
        plan = r.agent.lane_plan
        assert plan is not None
        # stale 5 s after it was published, whenever it was last confirmed
        age_s = (r.clock.now() - plan.plan.published_at).total_seconds()
        stale_at = r.clock.monotonic() - age_s + 5.0
        r.run(stale_at - r.clock.monotonic() - 0.01)
        assert engaged(r)
        assert hand_back_time(r, stale_at) <= CONTROL_PERIOD_S
        assert r.agent.state.reason == "no fresh plan"


def test_can_loss_hands_back_within_one_period(tmp_path: Path, dbc_cache: Path) -> None:
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        r.emulator.muted = set(r.emulator.frames)
        muted_at = r.clock.monotonic()
        # SPEED (20 ms) is invalid 10 periods after its last frame.
        assert hand_back_time(r, muted_at + 0.2) <= CONTROL_PERIOD_S
        assert r.agent.state.reason == "CAN inputs not healthy"
        sent = r.emulator.agent_frames
        r.run(1.0)
        assert r.emulator.agent_frames == sent  # no more requests: the stock ACC drives


def test_frames_queued_across_a_stalled_pass_are_dated_by_their_receipt(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """A pass 0.3 s late (the Pi busy elsewhere) found the car's frames queued: they were dated
    by the pass reading them, so a car gone silent at the start of the stall read as healthy
    for 10 periods more. Dated by their receipt, the late pass sees them as they are: the newest
    fresh while the car talks, 0.3 s old (15 of SPEED's 20 ms periods) once it has stopped."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)

        def stalled_pass(seconds: float) -> None:
            r.clock.advance(seconds)
            r.emulator.step(r.clock.monotonic())
            r.agent.tick()

        stalled_pass(0.3)  # the car went on sending through the stall
        assert engaged(r), r.agent.state.reason
        r.clock.advance(CONTROL_PERIOD_S)
        r.emulator.step(r.clock.monotonic())  # the car's last frames, queued: the pass stalls
        r.emulator.muted = set(r.emulator.frames)
        stalled_pass(0.3)
        assert not engaged(r)
        assert r.agent.state.reason == "CAN inputs not healthy"


def test_a_control_pass_follows_the_plan_it_checked_not_one_replaced_meanwhile(
    tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The pass checked the freshness of the plan held, then read `lane_plan` again for the
    controller: a plan the network thread put in between (here, an expired one the server
    answered) was followed unchecked."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        fresh = r.agent.lane_plan
        assert fresh is not None
        published = r.clock.now() - timedelta(hours=1)  # valid_until 50 min ago
        assert r.agent.accept_plan(uniform_plan(5.0, plan_id=2, published=published))
        expired = r.agent.lane_plan
        r.agent.lane_plan = fresh
        # the network thread swaps the plans inside every pass: the fresh one is held when
        # the pass checks it (after reading GPS), the expired one from the stopping check on
        latest_fix, needs_hand_back = r.gps.latest, r.agent.stopping.needs_hand_back

        def fix_then_fresh_plan() -> GpsFix | None:
            r.agent.lane_plan = fresh
            return latest_fix()

        def expired_plan_then_check(time_s: float, reading: CarReading | None) -> bool:
            r.agent.lane_plan = expired
            return needs_hand_back(time_s, reading)

        monkeypatch.setattr(r.gps, "latest", fix_then_fresh_plan)
        monkeypatch.setattr(r.agent.stopping, "needs_hand_back", expired_plan_then_check)
        assignment = r.agent.assignment
        assert assignment is not None
        step = assignment.controller.step
        targets: list[float] = []

        def recorded(observation: Observation) -> Action:
            targets.append(observation.target_speed_mps)
            return step(observation)

        monkeypatch.setattr(assignment.controller, "step", recorded)
        r.run(1.0)
        assert engaged(r), r.agent.state.reason
        assert targets
        assert set(targets) == {26.8224}  # the fresh plan's target, never the expired 5 m/s


def test_every_fault_hold_holds_an_engage_check() -> None:
    assert set(FAULT_HOLDS_S) <= {name for name, _ in CHECKS}


@pytest.mark.parametrize("fault", ["raises", "asks for NaN"])
def test_a_failing_controller_hands_back_within_one_period_and_says_so(
    fault: str, tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        assignment = r.agent.assignment
        assert assignment is not None

        failures: list[float] = []

        def fails(observation: object) -> AccelCommand:
            failures.append(r.clock.monotonic())
            if fault == "raises":
                raise IndexError("index 64 is out of bounds for axis 0 with size 64")
            # before, the limiter made NaN a 0 m/s^2 request and the car stayed commanded
            return AccelCommand(math.nan)

        # a fault inside the real controller, as a bug in its code would make it
        monkeypatch.setattr(assignment.controller, "step", fails)
        r.run(CONTROL_PERIOD_S, until=lambda: bool(failures))
        assert failures
        assert hand_back_time(r, failures[0]) <= CONTROL_PERIOD_S
        assert r.agent.state.reason == "controller failed"
        assert r.agent.stats.controller_errors == 1
        assert r.agent.stats.handbacks["controller failed"] == 1
        sent = r.emulator.agent_frames
        r.run(1.0)
        assert r.emulator.agent_frames == sent  # the stock ACC drives
        # still failing: retried after the hold, handed back again, never left engaged
        r.run(5.0)
        assert r.agent.stats.controller_errors > 1
        assert not engaged(r)
        # working again: the agent takes over by itself
        monkeypatch.undo()
        r.run(5.0, until=lambda: engaged(r))
        assert engaged(r), r.agent.state.reason


def test_a_pass_that_stalls_after_reading_the_car_sends_nothing_and_hands_back(
    tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        assignment = r.agent.assignment
        assert assignment is not None
        step = assignment.controller.step
        stalled: list[int] = []

        def slow(observation: Observation) -> Action:
            # the car was read at the start of this pass; the decision takes 0.3 s
            stalled.append(r.agent.safety.sent)
            r.clock.advance(0.3)
            monkeypatch.setattr(assignment.controller, "step", step)
            return step(observation)

        monkeypatch.setattr(assignment.controller, "step", slow)
        refused = r.agent.safety.refused["car state"]
        r.run(CONTROL_PERIOD_S, until=lambda: bool(stalled))
        assert stalled
        stalled_at = r.clock.monotonic()
        # before, the layer judged the state's age at the pass's start: 0 s, always fresh
        assert r.agent.safety.refused["car state"] == refused + 1
        assert hand_back_time(r, stalled_at) <= CONTROL_PERIOD_S
        assert r.agent.safety.sent == stalled[0]  # nothing left after the stall
        assert r.agent.state.reason == "actuator refused by the safety layer"


@pytest.mark.parametrize(
    ("key", "controller"), [("toyota_rav4", "microaccel"), ("nissan_rogue_2018", "simple")]
)
def test_commands_the_bus_will_not_send_hand_back_and_say_so(
    key: str, controller: str, tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with rig(key, tmp_path, dbc_cache, controller=controller) as r:
        # the Rogue's agent sends only to press a button: set 50 mph under a faster plan
        engage_and_settle(r, set_speed_mph=50)
        refused_before = sum(r.agent.safety.refused.values())
        failures: list[float] = []

        def full(frame: can.Message, timeout: float | None = None) -> None:
            failures.append(r.clock.monotonic())
            raise can.CanOperationError("Transmit buffer full")

        # the agent's real bus, refusing to transmit as a SocketCAN interface with a full
        # queue (or a bus-off controller) does
        monkeypatch.setattr(r.agent_bus, "send", full)
        r.run(3.0, until=lambda: bool(failures))
        assert failures
        assert hand_back_time(r, failures[0]) <= CONTROL_PERIOD_S
        assert r.agent.state.reason == "commands not reaching the CAN bus"
        # (a button car also tries to send the release, which fails as well)
        assert r.agent.sender.send_errors >= 1
        assert sum(r.agent.safety.refused.values()) == refused_before  # not a safety refusal
        # the bus sends again: the agent takes over by itself
        monkeypatch.undo()
        r.run(5.0, until=lambda: engaged(r))
        assert engaged(r), r.agent.state.reason


def network_down(timeout: float | None = None) -> None:
    raise can.CanOperationError("Network is down")


def test_a_can_interface_going_down_hands_back_at_once(
    tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        # the agent's real bus, its interface gone (`ip link set can0 down`, an adapter pulled)
        monkeypatch.setattr(r.agent_bus, "recv", network_down)
        with pytest.raises(can.CanOperationError):
            r.run(CONTROL_PERIOD_S)
        assert not engaged(r)
        assert r.agent.state.reason == "agent step failed"
        assert r.agent.stats.handbacks["agent step failed"] == 1
        # what the car reports says so too, though no pass renews its snapshot
        status = r.agent.status_report()
        assert status["controller_running"] is False
        assert status["engage_reason"] == "agent step failed"
        r.clock.advance(1.0)
        ping = r.agent.ping()
        assert ping is not None
        assert ping["controller_engaged"] is False
        # every pass fails while it is down: the agent stays off
        for _ in range(20):
            with pytest.raises(can.CanOperationError):
                r.run(CONTROL_PERIOD_S)
        assert not engaged(r)
        # no pass renews the position: once older than a fix may be, it is no longer pinged
        r.clock.advance(GPS_MAX_AGE_S)
        assert r.agent.ping() is None
        status = r.agent.status_report()
        assert status["gps_fix"] is False
        # and the status names the cause, not only the time since the last good pass
        assert status["engage_reason"].endswith(
            "every pass fails (CanOperationError: Network is down)"
        )
        # up again: the agent takes over by itself
        monkeypatch.undo()
        r.run(5.0, until=lambda: engaged(r))
        assert engaged(r), r.agent.state.reason


def test_a_failed_pass_does_not_cut_short_the_hold_off_after_a_driver_override(
    tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The fail-safe set the mode to STOCK, so a pass failing just after the driver let go of
    the gas made the agent take over after the 1 s engage wait instead of the 3 s hold-off."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        r.emulator.driver_gas(True)
        r.run(1.0, until=lambda: r.agent.state.mode is Mode.OVERRIDDEN)
        assert r.agent.state.mode is Mode.OVERRIDDEN
        r.emulator.driver_gas(False)
        r.run(1.0, until=lambda: r.agent.state.since_s < r.clock.monotonic())
        assert r.agent.state.mode is Mode.OVERRIDDEN
        touched_last = r.agent.state.since_s  # the last pass that saw the gas pressed
        monkeypatch.setattr(r.agent_bus, "recv", network_down)
        with pytest.raises(can.CanOperationError):
            r.run(CONTROL_PERIOD_S)
        monkeypatch.undo()
        r.run(10.0, until=lambda: engaged(r))
        assert engaged(r), r.agent.state.reason
        policy = r.agent.engage_policy
        waited = r.clock.monotonic() - touched_last
        assert waited >= policy.override_holdoff_s + policy.engage_after_s - 1e-9


def gpio_rig(
    tmp_path: Path, dbc_cache: Path, levels: dict[int, bool]
) -> AbstractContextManager[Rig]:
    """A Rogue whose buttons are pressed by a GPIO board; `levels` records each line's level."""
    lines = {CruiseButton.PLUS: 17, CruiseButton.MINUS: 27, CruiseButton.GAP: 22}

    def board(safety: SafetyLayer) -> GpioButtonBoard:
        return GpioButtonBoard(lines, levels.__setitem__, safety)

    return rig("nissan_rogue", tmp_path, dbc_cache, controller="simple", button_port=board)


def test_a_failed_pass_lets_go_of_the_button_a_gpio_board_holds(
    tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A GPIO line stays high until written low: without the release, a failing control loop
    would hold the button for good (SET- walking the set speed down to the car's minimum)."""
    levels: dict[int, bool] = {}
    with gpio_rig(tmp_path, dbc_cache, levels) as r:
        # set at 50 mph under a 60 mph plan: the agent presses to raise it
        engage_and_settle(r, set_speed_mph=50)
        r.run(2.0, until=lambda: any(levels.values()))
        assert any(levels.values()), "no button held"
        monkeypatch.setattr(r.agent_bus, "recv", network_down)
        with pytest.raises(can.CanOperationError):
            r.run(CONTROL_PERIOD_S)
        assert not any(levels.values())
        assert not engaged(r)
        assert r.agent.state.reason == "agent step failed"


def test_stopping_the_agent_lets_go_of_the_button_a_gpio_board_holds(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The line would stay high after the process exits: a + held for good walks the set speed
    up to the car's maximum with nobody pressing."""
    levels: dict[int, bool] = {}
    with gpio_rig(tmp_path, dbc_cache, levels) as r:
        engage_and_settle(r, set_speed_mph=50)
        r.run(2.0, until=lambda: any(levels.values()))
        assert any(levels.values()), "no button held"
        r.agent.shutdown()
        assert not any(levels.values())
        assert r.agent.state.reason == "stopped"
        assert isinstance(r.agent.buttons, GpioButtonBoard)
        assert r.agent.buttons.deadman_releases == 0  # let go by the shutdown, not the timer


@pytest.mark.parametrize("after_periods", [0.0, 0.5, 1.0])
def test_stopping_the_agent_mid_press_sends_the_release_through_the_safety_layer(
    tmp_path: Path, dbc_cache: Path, after_periods: float
) -> None:
    """The agent stopped with a press in its last frame and sent nothing more: the module
    reading the buttons went on seeing the press (here, the emulated car echoes it in its own
    button frames until its command timeout). However soon after the last frame it stops (the
    fleet worker's clock has not moved; a late control tick), the release gets through."""
    with rig("nissan_rogue_2018", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r, set_speed_mph=50)  # under a 60 mph plan: the agent presses +
        r.run(2.0, until=lambda: r.agent.sequencer.button is not None)
        assert r.agent.sequencer.button is CruiseButton.PLUS, "no button held"
        sent = r.agent.safety.sent
        r.clock.advance(after_periods * r.agent.command_period_s)
        r.agent.shutdown()
        r.clock.advance(r.agent.command_period_s)  # the car's next own frame echoes what it read
        r.emulator.step(r.clock.monotonic())
        car = r.agent.car
        echoed = [
            car.pressed_buttons(r.agent.codec.decode(frame.arbitration_id, frame.data)[1])
            for frame in iter(lambda: r.agent_bus.recv(timeout=0), None)
            if frame.arbitration_id == r.agent.codec.frame_id(car.command_message)
        ]
        assert echoed, "the car sent no button frame"
        assert echoed[-1] == frozenset()
        assert r.agent.safety.sent == sent + 1  # the release passed the safety layer


def test_a_nissan_press_copies_no_car_frame_older_than_two_periods(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The Rogue's button frame copies the car's latest CRUISE_THROTTLE, gas pedal and brake
    included, and the car state stays valid on one 10 periods (0.5 s) old: with the car's
    frames no longer reaching the agent, it went on pressing + and telling the car the gas was
    released while the driver held it. A press copies a frame read at most 2 periods before,
    and the refusal hands back."""
    with rig("nissan_rogue_2018", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r, set_speed_mph=50)  # under a 60 mph plan: the agent holds + 0.9 s
        r.run(2.0, until=lambda: r.agent.sequencer.button is not None)
        assert r.agent.sequencer.button is CruiseButton.PLUS, "no button held"
        car, codec = r.agent.car, r.agent.codec
        command_id = codec.frame_id(car.command_message)
        period = car.command_period_s
        spy = can.Bus(interface="virtual", channel=r.agent_bus.channel_id)
        try:
            r.emulator.muted.add("CRUISE_THROTTLE")
            r.emulator.driver_gas(True)
            muted_at = r.clock.monotonic()  # the car's last CRUISE_THROTTLE: no later
            pressed_at = []
            for _ in range(8):  # 0.4 s: the car state stays valid throughout
                r.run(period)
                for frame in iter(lambda: spy.recv(timeout=0), None):
                    if frame.arbitration_id != command_id:
                        continue
                    _, signals = codec.decode(frame.arbitration_id, frame.data)
                    if car.pressed_buttons(signals):
                        assert signals["GAS_PEDAL"] == 0  # the copy: the gas released
                        pressed_at.append(r.clock.monotonic())
            assert r.agent.reader.snapshot(r.clock.monotonic()).valid
        finally:
            spy.shutdown()
        assert pressed_at, "no press went out before the car's frames stopped"
        assert max(pressed_at) - muted_at <= 2 * period + 1e-9
        assert r.agent.safety.refused["copy"] == 1
        assert not engaged(r)
        assert r.agent.state.reason == "actuator refused by the safety layer"


def test_presses_the_car_does_not_take_hand_back_and_say_so(
    tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    with rig("nissan_rogue_2018", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r, set_speed_mph=50)  # under a 60 mph plan: the agent presses

        def lost(frame: can.Message, timeout: float | None = None) -> None:
            """A broken button wire: the frame leaves without error and never arrives."""

        monkeypatch.setattr(r.agent_bus, "send", lost)
        r.run(10.0, until=lambda: not engaged(r))
        assert not engaged(r)
        assert r.agent.state.reason == "button presses not confirmed by the car"
        # the status report says why, for the operator's dashboard
        status = r.agent.status_report()
        assert status["controller_running"] is False
        assert status["engage_reason"] == "button presses not confirmed by the car"
        # held off, not re-engaging at the engage wait's rate
        r.run(5.0)
        assert not engaged(r)
        # the wire mended: after the hold the agent takes over and presses again
        monkeypatch.undo()
        r.run(15.0, until=lambda: engaged(r))
        assert engaged(r), r.agent.state.reason


def test_a_silent_gps_receiver_is_no_fix_in_pings_or_status(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """A receiver gone quiet leaves its last fix the latest: that position is not where the car
    is, so after GPS_MAX_AGE_S it is neither pinged nor reported as a fix (which keeps a car
    cleared for deployment)."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        r.run(2.0)
        assert r.agent.status_report()["gps_fix"] is True
        r.gps.silent = True
        quiet_at = r.clock.now()
        r.run(GPS_MAX_AGE_S + CONTROL_PERIOD_S)
        assert not engaged(r)
        assert r.agent.state.reason == "no GPS fix"
        spooled = r.agent.stats.pings_spooled
        r.run(5.0)
        assert r.agent.stats.pings_spooled == spooled
        last_ping = r.agent.spool.oldest(100)[-1][1]
        assert datetime.fromisoformat(last_ping["ts"]) <= quiet_at + timedelta(
            seconds=GPS_MAX_AGE_S
        )
        status = r.agent.status_report()
        assert status["gps_fix"] is False
        assert "gps_satellites" not in status
        # fixes again: pinged and engaged once more
        r.gps.silent = False
        r.run(5.0, until=lambda: engaged(r))
        assert engaged(r), r.agent.state.reason
        assert r.agent.ping() is not None
        assert r.agent.status_report()["gps_fix"] is True


def test_a_control_loop_that_stopped_is_not_reported_driving(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The status report read the control loop's last snapshot however old it was: with the
    loop stuck in a call (no pass renewing it, none failing to hand back), the car went on
    being reported with the controller running, its CAN read, its ACC available and its plan
    as young as at the last pass, while nothing commanded or read the car."""
    with rig("nissan_rogue", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r)
        status = r.agent.status_report()
        assert status["controller_running"] is True
        assert status["can_ok"] is True
        assert status["acc_available"] is True
        plan_age_s = status["plan_age_s"]
        r.clock.advance(5.0)  # the network thread reports on; no control pass runs
        status = r.agent.status_report()
        assert status["controller_running"] is False
        assert status["can_ok"] is False
        assert "acc_available" not in status
        assert status["engage_reason"] == "no control pass for 5 s"
        assert status["controller"] == "simple"  # the assignment it holds
        assert status["plan_age_s"] == pytest.approx(plan_age_s + 5.0, abs=0.11)


@pytest.mark.parametrize("action", ["brake", "gas", "button"])
def test_driver_override_hands_back_within_one_period(
    action: str, tmp_path: Path, dbc_cache: Path
) -> None:
    with rig("cadillac_xt5", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r)
        touched_at = r.clock.monotonic()
        if action == "brake":
            r.emulator.driver_brake(True)
        elif action == "gas":
            r.emulator.driver_gas(True)
        else:
            r.emulator.driver_buttons(CruiseButton.CANCEL)
        # The driver's input reaches the agent with the car's next frame (<= 50 ms).
        assert hand_back_time(r, touched_at) <= 0.05 + CONTROL_PERIOD_S
        assert r.agent.state.mode is Mode.OVERRIDDEN


def test_a_rav4_driver_stepping_the_set_speed_holds_the_agent_off_until_the_last_step(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """docs/agent.md: a changed set point on a RAV4 holds the agent off "3 s after the last
    touch". Changes counted only while the agent commanded, so the hold-off ran from the first:
    the agent took the car back 0.2 s after a later step, and handed it back at the next."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        r.emulator.driver_engage(set_speed_mph=50)
        r.run(5.0, until=lambda: r.agent.state.mode is Mode.ENGAGED)
        assert r.agent.state.mode is Mode.ENGAGED
        start = r.clock.monotonic()
        modes = []
        for step in range(1, 9):  # the driver steps down 1 mph every 0.5 s for 4 s
            r.emulator.acc.set_speed_mph = 50 - step
            r.run(0.5)
            modes.append(r.agent.state.mode)
        last_step = start + 3.5
        assert modes == [Mode.OVERRIDDEN] * 8
        r.run(last_step + 3.0 - r.clock.monotonic() - 0.2)
        assert r.agent.state.mode is Mode.OVERRIDDEN  # 2.8 s after the last step
        r.run(3.0, until=lambda: r.agent.state.mode is Mode.ENGAGED)
        assert r.agent.state.mode is Mode.ENGAGED


def play_the_pcm(
    r: Rig, listener: can.BusABC, seconds: float, cruise_state: int | None
) -> list[dict[str, float]]:
    """Drive for `seconds`, the test playing the RAV4's PCM (the emulator's own PCM_CRUISE
    muted): a PCM_CRUISE in `cruise_state` every command period, or none (None). Returns the
    agent's ACC_CONTROL requests meanwhile, as `listener` read them."""
    codec = r.agent.codec
    end = r.clock.monotonic() + seconds
    while r.clock.monotonic() < end - 1e-9:
        r.clock.advance(r.agent.command_period_s)
        r.emulator.step(r.clock.monotonic())
        if cruise_state is not None:
            pcm = {"CRUISE_ACTIVE": 1, "GAS_RELEASED": 1, "CRUISE_STATE": cruise_state}
            r.emulator.send_raw(
                can.Message(
                    arbitration_id=codec.frame_id("PCM_CRUISE"),
                    data=codec.encode("PCM_CRUISE", pcm),
                    is_extended_id=False,
                )
            )
        r.agent.tick()
    return [
        codec.decode(frame.arbitration_id, frame.data)[1]
        for frame in iter(lambda: listener.recv(timeout=0), None)
        if frame.arbitration_id == codec.frame_id("ACC_CONTROL")
    ]


def test_the_agent_never_releases_a_standstill_the_rav4s_pcm_holds(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """ACC_CONTROL always carried RELEASE_STANDSTILL 1: at the PCM's standstill (CRUISE_STATE
    7, where the stock ACC waits for the driver's RES or gas) it released the hold, and the
    agent's request to speed up drove the car off with nobody resuming."""
    with (
        rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel", speed_mps=0.0) as r,
        can.Bus(interface="virtual", channel=r.agent_bus.channel_id) as listener,
    ):
        r.emulator.muted = {"PCM_CRUISE"}  # the test plays the PCM
        r.emulator.driver_engage(set_speed_mph=30)
        held = play_the_pcm(r, listener, 3.0, cruise_state=7)  # "standstill"
        assert engaged(r), r.agent.state.reason
        assert r.agent._requested_accel > 0  # the controller would go
        assert {request["RELEASE_STANDSTILL"] for request in held} == {0}
        # the request goes to the standing car's 0 and stays: nothing builds up to be let go
        commands = [request["ACCEL_CMD"] for request in held]
        assert all(later <= earlier for earlier, later in itertools.pairwise(commands))
        assert commands[-1] == 0.0
        # "adaptive engaged": the driver pressed RES
        resumed = play_the_pcm(r, listener, 1.0, cruise_state=8)
        assert resumed
        assert {request["RELEASE_STANDSTILL"] for request in resumed} == {1}
        # pulling away within the limiter's 2.5 m/s^3 from 0 (one frame's quantum of slack)
        period = r.agent.command_period_s
        for frame, request in enumerate(resumed, start=1):
            assert request["ACCEL_CMD"] <= 2.5 * period * frame + 0.01
        assert resumed[-1]["ACCEL_CMD"] > 0


def test_the_emulated_pcm_holds_a_stop_the_agent_never_releases_until_the_driver_resumes(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """End to end, with the emulator's own PCM: behind a leader that stops for 20 s, the car
    stops, the PCM holds it after its 3 s timer, and the agent stays engaged and sends no
    release while its controller would go; the leader drives off and the car stays until the
    driver's RES, then the agent pulls away."""
    # 40 m ahead at 10 m/s, stopped from 110 to 130 s (the rig's clock starts at 100 s)
    leader = SpeedProfileLeader(
        [100.0, 105.0, 110.0, 130.0, 135.0], [10.0, 10.0, 0.0, 0.0, 10.0], position_m=1040.0
    )
    with (
        rig(
            "toyota_rav4",
            tmp_path,
            dbc_cache,
            controller="microaccel",
            speed_mps=10.0,
            leader=leader,
            target_speed_mps=10.0,
        ) as r,
        can.Bus(interface="virtual", channel=r.agent_bus.channel_id) as listener,
    ):
        codec = r.agent.codec
        r.emulator.driver_engage(set_speed_mph=25)
        r.run(30.0, until=lambda: r.emulator.standstill_held)
        assert r.emulator.standstill_held
        held_at = r.clock.monotonic()
        assert held_at < 125.0
        r.run(134.0 - held_at)  # the leader left at 130 s
        assert r.emulator.speed_mps == 0.0
        assert r.emulator.lead()[0] > 20.0  # type: ignore[operator]
        assert engaged(r), r.agent.state.reason
        assert r.agent._requested_accel > 0  # the controller would go
        requests = [
            codec.decode(frame.arbitration_id, frame.data)[1]
            for frame in iter(lambda: listener.recv(timeout=0), None)
            if frame.arbitration_id == codec.frame_id("ACC_CONTROL")
        ]
        # from a PCM_CRUISE of the hold on, within a PCM period and an agent period of it
        after_hold = requests[-int((r.clock.monotonic() - held_at - 0.07) * 30) :]
        assert {request["RELEASE_STANDSTILL"] for request in after_hold} == {0}
        r.emulator.driver_resume()
        r.run(3.0)
        assert r.emulator.speed_mps > 2.0
        assert engaged(r), r.agent.state.reason


@pytest.mark.parametrize("key", ["nissan_rogue", "cadillac_xt5", "nissan_rogue_2018"])
def test_nothing_is_pressed_while_the_stock_acc_holds_a_standstill_for_the_driver(
    key: str, tmp_path: Path, dbc_cache: Path
) -> None:
    """At a standstill the stock ACC holds (the 2023 Rogue's CRUISE_STATE 4, the XT5's
    AcceleratorPedal2 CruiseState 4; the 2018-20 Rogue shows none, so every engaged stop reads
    as held there), + resumes the car. The paper's
    clip leaves out 0 mph samples, so a stopped car's setting is the controller's own, and the
    board went on pressing + towards the plan's 60 mph through the hold: it drove off a stop
    that is the driver's to leave. Now the agent stays engaged and presses nothing until the
    driver resumes."""
    # 40 m ahead at 10 m/s, stopped from 110 to 130 s (the rig's clock starts at 100 s)
    leader = SpeedProfileLeader(
        [100.0, 108.0, 110.0, 130.0, 135.0], [10.0, 10.0, 0.0, 0.0, 10.0], position_m=1040.0
    )
    with rig(
        key,
        tmp_path,
        dbc_cache,
        controller="simple",
        speed_mps=10.0,
        leader=leader,
        target_speed_mps=26.8224,  # 60 mph
    ) as r:
        r.run(7.0)
        # set late, at 45 mph: the agent walks it down to 20 as the car stops, then up again
        r.emulator.driver_engage(set_speed_mph=45)
        r.run(30.0, until=lambda: r.emulator.standstill_held)
        assert r.emulator.standstill_held
        held_at = r.clock.monotonic()
        assert held_at < 125.0
        presses = r.agent.sequencer.presses
        setting = r.emulator.acc.set_speed_mph
        assert setting is not None
        assert setting < 55  # the walk up to 60 mph was not done when the hold began
        r.run(136.0 - held_at)  # the leader left at 130 s
        assert r.emulator.speed_mps == 0.0
        assert r.emulator.standstill_held
        assert r.agent.sequencer.presses == presses
        assert r.emulator.acc.set_speed_mph == setting
        assert engaged(r), r.agent.state.reason
        assert r.agent.safety.refused == {}
        r.emulator.driver_resume()
        r.run(5.0)
        assert r.emulator.speed_mps > 2.0
        assert engaged(r), r.agent.state.reason


def test_the_rav4_releases_no_standstill_from_a_pcm_cruise_over_two_periods_old(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """ACC_CONTROL released the standstill whenever the latest PCM_CRUISE the agent had read
    showed none, however old: the car state stays valid on a PCM_CRUISE 10 periods (0.33 s)
    old, time enough for the PCM to have stopped the car and held it since, and the release
    would have driven off a hold that is the driver's to release. From a PCM_CRUISE read more
    than 2 of its periods ago the request keeps the standstill (0), and the agent goes on
    commanding: a late PCM_CRUISE is no reason to hand back."""
    with (
        rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r,
        can.Bus(interface="virtual", channel=r.agent_bus.channel_id) as listener,
    ):
        r.emulator.muted = {"PCM_CRUISE"}  # the test plays the PCM
        r.emulator.driver_engage(set_speed_mph=50)
        play_the_pcm(r, listener, 3.0, cruise_state=8)  # "adaptive engaged"
        assert engaged(r), r.agent.state.reason
        period = r.agent.command_period_s
        late = play_the_pcm(r, listener, 6 * period, cruise_state=None)
        # one request a period, the last PCM_CRUISE read 1, 2, ... 6 periods before each
        assert len(late) == 6
        assert late[0]["RELEASE_STANDSTILL"] == 1
        assert [request["RELEASE_STANDSTILL"] for request in late[2:]] == [0, 0, 0, 0]
        assert engaged(r), r.agent.state.reason
        assert r.agent.safety.refused == {}
        back = play_the_pcm(r, listener, 6 * period, cruise_state=8)
        assert {request["RELEASE_STANDSTILL"] for request in back} == {1}


def test_a_policy_reading_the_commanded_accel_gets_what_the_limiter_let_through(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """A policy asking for 1.5 x (its commanded-acceleration input x 3 + 0.2) m/s^2, the last
    command plus 0.2 (x 1.5): it feeds on the agent's limiter, which raises it at 2.5 m/s^3 to
    the range's 1.5 m/s^2. An agent that left the figure out would fail the controller and hand
    the car back; one that fed the car's measured acceleration would lag the ramp."""
    weight = np.zeros((7, 1))
    weight[6, 0] = 3.0
    policy = tmp_path / "commanded.npz"
    save_policy(policy, "accel", [weight], [np.array([0.2])], accel_observation="commanded_accel")
    with rig(
        "toyota_rav4",
        tmp_path,
        dbc_cache,
        controller="rl_accel",
        params={"policy": str(policy)},
        speed_mps=20.0,
    ) as r:
        engage_and_settle(r, 45)  # 20.1 m/s: the ACC holds the car's speed, about 0 m/s^2
        commanded = []
        for _ in range(8):
            r.run(CONTROL_PERIOD_S)
            commanded.append(r.agent.limiter.reference_mps2)
        assert engaged(r), r.agent.state.reason
        assert r.agent.stats.controller_errors == 0
        steps = np.diff(commanded)
        rising = steps[np.asarray(commanded[1:]) < 1.5]
        assert len(rising) >= 4
        np.testing.assert_allclose(rising, 0.25, atol=1e-9)
        r.run(1.0)
        assert r.agent.limiter.reference_mps2 == pytest.approx(1.5)


# The speed over which the safety layer refuses every acceleration request asking for more
# speed: the fleet's top speed (73 mph) and its tolerance (2 mph).
REFUSED_OVER_MPS = SafetyLimits().accel.top_speed_mps + SafetyLimits().over_top_speed_tolerance_mps


def test_an_accel_car_over_the_top_speed_is_taken_over_only_once_under_it(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """A RAV4 its ACC drove at 78 mph, accelerating, was taken over and handed back at once:
    the limiter starts from the car's measured acceleration (+0.8 m/s^2) and brings its
    request down within the jerk limit, and the safety layer refused that first, still
    positive, request over 75 mph ("actuator refused by the safety layer"), again after every
    hold. The agent now waits, saying why, until the car is under 75 mph, then the usual
    `engage_after_s`."""
    with rig(
        "toyota_rav4", tmp_path, dbc_cache, controller="microaccel", speed_mps=77 * MPS_PER_MPH
    ) as r:
        r.emulator.driver_engage(set_speed_mph=83)  # its ACC accelerates the car at ~1 m/s^2
        r.run(4.0, until=lambda: bool(r.agent.stats.handbacks))
        assert r.agent.stats.handbacks == {}, f"refused: {dict(r.agent.safety.refused)}"
        assert not engaged(r)  # never taken over: every engagement ends in a hand-back
        assert r.emulator.speed_mps > REFUSED_OVER_MPS
        assert r.emulator.accel_mps2 > 0.0  # still accelerating
        assert r.agent.state.reason == "above the fleet's top speed"
        assert r.agent.status_report()["engage_reason"] == "above the fleet's top speed"
        r.emulator.driver_engage(set_speed_mph=65)  # the driver sets a lower speed: ACC slows
        read: list[tuple[float, float]] = []

        def reads_then_engaged() -> bool:
            snapshot = r.agent.snapshot
            assert snapshot is not None
            assert snapshot.reading is not None
            read.append((snapshot.time_s, snapshot.reading.speed_mps))
            return engaged(r)

        r.run(30.0, until=reads_then_engaged)
        assert engaged(r), r.agent.state.reason
        under_since = next(
            time_s
            for index, (time_s, _) in enumerate(read)
            if all(speed <= REFUSED_OVER_MPS for _, speed in read[index:])
        )
        waited = r.agent.state.since_s - under_since
        engage_after_s = r.agent.engage_policy.engage_after_s
        assert engage_after_s <= waited < engage_after_s + 2 * r.agent.command_period_s
        r.run(5.0)
        assert engaged(r), r.agent.state.reason
        assert r.agent.safety.refused == {}
        assert r.agent.stats.handbacks == {}


@pytest.mark.parametrize("start_mph", [70.8, 71.0, 71.2, 71.4, 71.6])
def test_an_accel_car_accelerating_toward_the_top_speed_is_not_taken_over_into_a_refusal(
    tmp_path: Path, dbc_cache: Path, start_mph: float
) -> None:
    """Its ACC accelerating it toward 83 mph, a RAV4 was taken over just under 75 mph at
    +1 m/s^2 or more; the requests, easing off that acceleration at the jerk limit, were still
    positive when it passed 75 mph, and the first of those was refused and the car handed back
    (from each of these starts, before the agent counted the speed gained while easing off).
    Now the agent waits: no request is refused, no car handed back."""
    with rig(
        "toyota_rav4",
        tmp_path,
        dbc_cache,
        controller="microaccel",
        speed_mps=start_mph * MPS_PER_MPH,
    ) as r:
        r.emulator.driver_engage(set_speed_mph=83)
        r.run(12.0, until=lambda: bool(r.agent.stats.handbacks))
        assert r.agent.safety.refused == {}
        assert r.agent.stats.handbacks == {}
        assert r.agent.state.reason == "above the fleet's top speed"


def test_an_engaged_accel_car_going_over_the_top_speed_stays_engaged(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The top speed bars only taking over: a car the agent commands that a downhill pushes
    over it is slowed back by the limiter (at up to 1 m/s^2), whose requests are at most 0 by
    the time the car is 2 mph over, so handing it back would gain nothing."""
    with rig(
        "toyota_rav4",
        tmp_path,
        dbc_cache,
        controller="microaccel",
        speed_mps=72 * MPS_PER_MPH,
        target_speed_mps=40.0,  # 89 mph: the controller asks for more, the limiter holds 73
    ) as r:
        engage_and_settle(r, set_speed_mph=72)
        r.run(5.0, until=lambda: not engaged(r))
        top_mps = SafetyLimits().accel.top_speed_mps
        assert r.emulator.speed_mps == pytest.approx(top_mps, abs=0.3)
        # a downhill the emulator does not model: 1.5 m/s^2 more than the powertrain makes
        period = r.agent.command_period_s
        for _ in range(round(5.0 / period)):
            r.emulator.speed_mps += 1.5 * period
            r.run(period)
            assert engaged(r), r.agent.state.reason
        assert r.emulator.speed_mps > REFUSED_OVER_MPS
        r.run(20.0, until=lambda: not engaged(r))
        assert engaged(r), r.agent.state.reason
        assert r.emulator.speed_mps == pytest.approx(top_mps, abs=0.3)
        assert r.agent.safety.refused == {}
        assert r.agent.stats.handbacks == {}


def test_a_button_car_over_the_top_speed_is_taken_over(tmp_path: Path, dbc_cache: Path) -> None:
    """A button car has no top speed of the agent's to wait for: its own ACC slows it to any
    setting, and the controllers' clip keeps the setting at 73 mph at most."""
    with rig(
        "nissan_rogue", tmp_path, dbc_cache, controller="simple", speed_mps=80 * MPS_PER_MPH
    ) as r:
        engage_and_settle(r, set_speed_mph=80)
        r.run(30.0, until=lambda: not engaged(r))
        assert engaged(r), r.agent.state.reason
        assert r.emulator.acc.set_speed_mph is not None
        assert r.emulator.acc.set_speed_mph <= 73
        assert r.emulator.speed_mps < 74 * MPS_PER_MPH


def test_leaving_the_corridor_hands_back_within_one_period(tmp_path: Path, dbc_cache: Path) -> None:
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        left_at = r.clock.monotonic()
        r.gps.offset_m = 300.0
        assert hand_back_time(r, left_at) <= CONTROL_PERIOD_S
        assert r.agent.state.reason == "off the assigned corridor"


def test_driving_against_the_corridor_hands_back_within_one_period(
    tmp_path: Path, dbc_cache: Path
) -> None:
    # Same place, opposite heading: the other carriageway runs beside the reference line.
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        turned_at = r.clock.monotonic()
        r.gps.heading_offset_deg = 180.0
        assert hand_back_time(r, turned_at) <= CONTROL_PERIOD_S
        assert r.agent.state.reason == "off the assigned corridor"


def test_another_lane_hands_back(tmp_path: Path, dbc_cache: Path) -> None:
    with rig("nissan_rogue", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r)
        r.gps.lane = 3
        r.run(CONTROL_PERIOD_S)
        assert r.agent.state.reason == "not in the assigned lane"


def test_garbage_frames_hand_back_and_the_agent_keeps_running(
    tmp_path: Path, dbc_cache: Path
) -> None:
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        r.emulator.send_raw(
            can.Message(arbitration_id=180, data=b"\x01\x02\x03", is_extended_id=False)
        )
        r.emulator.send_raw(can.Message(arbitration_id=180, data=bytes(8), is_extended_id=False))
        r.emulator.send_raw(
            can.Message(arbitration_id=0x123, data=b"\xff" * 8, is_extended_id=False)
        )
        sent_at = r.clock.monotonic()
        assert hand_back_time(r, sent_at) <= CONTROL_PERIOD_S
        assert r.agent.reader.stats.errors["length"] == 1
        assert r.agent.reader.stats.errors["checksum"] >= 1
        # The next good SPEED frame clears it; the agent takes over again after 1 s steady.
        r.run(3.0, until=lambda: engaged(r))
        assert engaged(r)


def test_a_plan_without_our_lane_leaves_the_car_to_its_acc(tmp_path: Path, dbc_cache: Path) -> None:
    with rig("nissan_rogue", tmp_path, dbc_cache, controller="simple", target_speed_mps=None) as r:
        assert not r.agent.accept_plan(uniform_plan(25.0, published=r.clock.now(), lanes=(1, 3)))
        assert r.agent.stats.plans_refused == 1
        r.emulator.driver_engage(set_speed_mph=50)
        r.run(3.0)
        assert r.agent.state.mode is Mode.STOCK
        assert r.agent.state.reason == "no fresh plan"
        assert r.agent.sequencer.presses == 0  # the 2023 Rogue's board pressed nothing
        assert r.emulator.agent_frames == 0


def every_lane_plan(
    now: datetime,
    published: datetime,
    *,
    x_m: list[float],
    end_x_m: list[float],
    speeds: list[float],
) -> Plan:
    """Plan 2 of the rig's corridor with the same targets on its four lanes, valid for 10 min
    from `now`."""
    return Plan.model_validate(
        {
            "plan_id": 2,
            "corridor": uniform_plan(25.0, published=now).corridor,
            "published_at": published,
            "valid_until": now + timedelta(minutes=10),
            "lanes": [
                {"lane": lane, "x_m": x_m, "end_x_m": end_x_m, "target_speed_mps": speeds}
                for lane in (1, 2, 3, 4)
            ],
        }
    )


def test_a_plan_that_does_not_reach_the_car_hands_back(tmp_path: Path, dbc_cache: Path) -> None:
    """A lane covering 0-200 m of the corridor, the car at 1,000 m: the lookup held the lane's
    last target flat past its end, and an engaged RAV4 slowed from 25 to 5 m/s on a target
    the plan never set for its place."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel", speed_mps=25.0) as r:
        engage_and_settle(r)
        now = r.clock.now()
        short = every_lane_plan(
            now, now, x_m=[0.0, 100.0], end_x_m=[100.0, 200.0], speeds=[5.0, 5.0]
        )
        assert r.agent.accept_plan(short)
        r.run(1.0)

        assert not engaged(r)
        assert r.agent.state.reason == "the plan does not reach the car's position"
        r.run(5.0)
        assert r.emulator.speed_mps > 20.0


def test_an_aged_plan_read_past_its_end_hands_back(tmp_path: Path, dbc_cache: Path) -> None:
    """A lane to 1,500 m (5 m/s on its last 100 m) published 150 s ago: its targets are read
    625 m downstream of the car. At about 1,000 m the car is on the lane, but its lookup is
    past the end, where it held the 5 m/s flat: an engaged RAV4 slowed from 25 m/s to 11.5
    on a target the plan never set for its place (audit)."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel", speed_mps=25.0) as r:
        engage_and_settle(r)
        now = r.clock.now()
        aged = every_lane_plan(
            now,
            now - timedelta(seconds=150),
            x_m=[0.0, 1400.0],
            end_x_m=[1400.0, 1500.0],
            speeds=[25.0, 5.0],
        )
        assert r.agent.accept_plan(aged)
        r.run(1.0)

        assert r.agent.snapshot.x_m is not None
        assert r.agent.snapshot.x_m < 1500.0  # on the lane
        assert not engaged(r)
        assert r.agent.state.reason == "the plan does not reach the car's position"
        r.run(5.0)
        assert r.emulator.speed_mps > 20.0


def test_a_car_moved_to_another_corridor_follows_no_plan_of_the_old_one(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """Only a new lane dropped the plan held: a car moved to another corridor in the same lane
    followed the old corridor's targets at its new positions until the next poll, or until the
    old plan's valid_until when the poll failed; and a plan of another corridor was taken."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        assert r.agent.lane_plan is not None
        config = r.agent.config
        assert config is not None
        document = seed_corridor_document()
        elsewhere = CorridorGeometry.from_segments(
            "I-24-EB", document["corridor"]["lanes"], document["i24_segments"]
        )
        r.agent.configure(config.model_copy(update={"corridor_id": "I-24-EB"}), elsewhere)
        assert r.agent.lane_plan is None
        r.run(2.0)
        assert not engaged(r)
        assert r.agent.state.reason == "no fresh plan"
        # the answer to a poll sent before the move is the old corridor's: not followed
        assert not r.agent.accept_plan(uniform_plan(25.0, published=r.clock.now()))
        assert r.agent.lane_plan is None
        assert r.agent.stats.plans_refused == 1


def test_a_new_config_hands_back_saying_so_not_that_the_operator_disabled_the_car(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """A config whose controller's parameters changed hands the car back to take over anew with
    a new controller; the reason (status, log, hand-back counts) said "agent not enabled for
    this vehicle", the operator's choice, which it was not."""
    with rig("cadillac_xt5", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r)
        config = r.agent.config
        assert config is not None
        assert r.agent.assignment is not None
        corridor = r.agent.assignment.corridor
        controller = config.controller.model_copy(update={"params": {"speed_offset_mph": 2.0}})
        r.agent.configure(config.model_copy(update={"controller": controller}), corridor)
        r.run(0.1)
        assert r.agent.stats.handbacks == {"a new assignment: taking over anew": 1}
        r.run(5.0, until=lambda: engaged(r))
        assert engaged(r)


def test_a_new_config_that_drives_alike_keeps_the_car_and_one_that_does_not_hands_it_back(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """Every new config handed the car back, even one whose status period alone changed: the
    stock ACC took over for the engage wait on an operator's change of no consequence to the
    driving. Now only a change of how the car is driven does (`FIELDS_KEEPING_CONTROL`)."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        config = r.agent.config
        assert config is not None
        assert r.agent.assignment is not None
        corridor = r.agent.assignment.corridor
        controller = r.agent.assignment.controller
        alike = config.model_copy(
            update={
                "ping_period_s": 2.0,
                "status_period_s": 20.0,
                "plan_poll_s": 10.0,
                "stale_plan_after_s": 120.0,
                "route": "B",
                "config_version": 2,
            }
        )
        r.agent.configure(alike, corridor)
        r.run(2.0)
        assert engaged(r)
        assert r.agent.stats.handbacks == {}
        assert r.agent.assignment.controller is controller  # the same controller, its state
        snapshot = r.agent.snapshot
        assert snapshot is not None
        assert snapshot.config_version == 2  # the version held is the one reported
        tuned = config.controller.model_copy(update={"params": {"k": 0.7}})
        r.agent.configure(
            alike.model_copy(update={"controller": tuned, "config_version": 3}), corridor
        )
        r.run(0.1)
        assert not engaged(r)
        assert r.agent.stats.handbacks == {"a new assignment: taking over anew": 1}
        r.run(5.0, until=lambda: engaged(r))
        assert engaged(r)
        assert r.agent.assignment.controller is not controller


@pytest.mark.parametrize(
    ("field", "value"), [("assigned_lane", 3), ("active", False), ("in_maintenance", True)]
)
def test_a_new_lane_or_the_operator_disabling_the_car_still_hands_it_back(
    field: str, value: object, tmp_path: Path, dbc_cache: Path
) -> None:
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        config = r.agent.config
        assert config is not None
        assert r.agent.assignment is not None
        r.agent.configure(config.model_copy(update={field: value}), r.agent.assignment.corridor)
        r.run(0.1)
        assert not engaged(r)
        assert sum(r.agent.stats.handbacks.values()) == 1


def test_lane_change_recovery_engages_on_a_cut_in_and_releases(
    tmp_path: Path, dbc_cache: Path
) -> None:
    # RAV4 with MicroAccel at 25 m/s behind a leader 80 m ahead at 25 m/s, target 25 m/s.
    with rig(
        "toyota_rav4",
        tmp_path,
        dbc_cache,
        controller="microaccel",
        speed_mps=25.0,
        target_speed_mps=25.0,
        leader=ConstantSpeedLeader(1080.0, 25.0, 100.0),
    ) as r:
        engage_and_settle(r, 56)
        r.run(5.0)
        controller = r.agent.assignment.controller  # type: ignore[union-attr]
        assert isinstance(controller, MicroAccelController)
        assert controller.recovery.activations == 0
        r.emulator.cut_in(40.0, 22.0)  # TTC 13 s: a safe cut-in
        r.run(1.0)
        assert controller.recovery.activations == 1
        r.run(20.0, until=lambda: not controller.recovery.active)
        assert not controller.recovery.active
        assert engaged(r)
        gap, _ = r.emulator.lead()
        assert gap is not None
        assert gap > 20.0
        assert r.agent.safety.refused == {}


def test_pings_are_spooled_once_a_second(tmp_path: Path, dbc_cache: Path) -> None:
    with rig(
        "toyota_rav4",
        tmp_path,
        dbc_cache,
        controller="microaccel",
        leader=ConstantSpeedLeader(1050.0, 22.0, 100.0),
        config_fields={"config_version": 7},
    ) as r:
        engage_and_settle(r)
        r.run(10.0)
        rows = r.agent.spool.oldest(100)
        elapsed = r.clock.monotonic() - 100.0  # the rig starts its clock at 100 s
        assert abs(len(rows) - elapsed) <= 1.0
        ping = rows[-1][1]
        assert ping["vehicle_id"] == "SF-TEST"
        assert ping["controller_engaged"] is True
        assert ping["acc_engaged"] is True
        assert ping["controller"] == "microaccel"
        assert ping["plan_id"] == 1
        # the config it drove under, so ingest knows whether it holds that assignment yet
        assert ping["config_version"] == 7
        assert ping["lead_present"] is True
        assert 0 < ping["lead_distance_m"] < 100
        timestamps = [row[1]["ts"] for row in rows]
        assert timestamps == sorted(set(timestamps))


def test_a_shortened_ping_period_applies_from_the_last_ping(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The next ping was set with the period of the config then: cut from 60 s to 1 s, the car
    sent its next ping 60 s after the last, not 1 s."""
    with rig(
        "toyota_rav4",
        tmp_path,
        dbc_cache,
        controller="microaccel",
        config_fields={"ping_period_s": 60.0},
    ) as r:
        r.run(3.0)
        assert r.agent.stats.pings_spooled == 1
        config = r.agent.config
        assert r.agent.assignment is not None
        assert config is not None
        r.agent.configure(
            config.model_copy(update={"ping_period_s": 1.0}), r.agent.assignment.corridor
        )
        r.run(0.2)
        assert r.agent.stats.pings_spooled == 2  # the last one is over 1 s old: due at once
        r.run(3.0)
        assert r.agent.stats.pings_spooled == 5


def test_a_reading_outside_the_contract_costs_only_its_field(
    tmp_path: Path, dbc_cache: Path
) -> None:
    with rig(
        "toyota_rav4",
        tmp_path,
        dbc_cache,
        controller="microaccel",
        leader=ConstantSpeedLeader(1050.0, 22.0, 100.0),
    ) as r:
        engage_and_settle(r)
        snapshot = r.agent.snapshot
        assert snapshot is not None
        assert snapshot.reading is not None
        # a radar glitch: a lead 1.5 km away (the contract allows up to 1000 m)
        glitch = replace(snapshot.reading, lead_distance_m=1500.0)
        r.agent.snapshot = replace(snapshot, reading=glitch)
        r.clock.advance(1.0)
        ping = r.agent.ping()
        assert ping is not None
        assert "lead_distance_m" not in ping
        assert ping["lead_present"] is True
        assert ping["speed_mps"] > 0
        assert r.agent.stats.fields_dropped["ping"] == 1
        # a status report is always sent (only its ts is required)
        assert "ts" in r.agent.status_report()


def test_the_status_reports_the_pings_a_full_spool_dropped(tmp_path: Path, dbc_cache: Path) -> None:
    spool = PingSpool(tmp_path / "small.sqlite", max_rows=5)
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel", spool=spool) as r:
        r.run(10.5)  # a ping a second, no server to take them
        status = r.agent.status_report()
        assert status["spool_backlog"] == 5
        assert status["spool_dropped"] == spool.counter("dropped") >= 5


def test_a_car_whose_spool_cannot_be_opened_drives_and_reports_its_backlog(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The agent could not be built without a spool file (the card missing or read-only), so
    the car drove with no agent at all and reported nothing."""
    (tmp_path / "card").write_text("")  # where the spool's folder should be
    spool = PingSpool(tmp_path / "card" / "spool.sqlite")
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel", spool=spool) as r:
        engage_and_settle(r)
        r.run(10.0)
        assert engaged(r)
        status = r.agent.status_report()
        assert status["spool_backlog"] == r.agent.stats.pings_spooled >= 10
        r.agent.shutdown()
        assert r.agent.state.mode is Mode.STOCK


def test_no_ping_says_a_car_of_unknown_speed_stands(tmp_path: Path, dbc_cache: Path) -> None:
    """With the car's CAN not read and a receiver that reports no speed (gpsd leaves it out of
    a fix it has none for), the ping went out at 0 m/s: to the server, whose traffic estimate
    it joins, a car standing on the highway. A ping needs a speed, so none goes out."""
    with rig("nissan_rogue", tmp_path, dbc_cache, controller="simple") as r:
        receiver = r.gps

        class NoSpeedReceiver:
            def latest(self) -> GpsFix | None:
                fix = receiver.latest()
                return None if fix is None else replace(fix, speed_mps=None)

        r.agent.gps = NoSpeedReceiver()
        r.run(1.0)
        r.clock.advance(0.01)  # past the instant of the last ping spooled
        ping = r.agent.ping()
        assert ping is not None
        assert ping["speed_mps"] == pytest.approx(22.0, abs=0.5)  # the car's own
        r.emulator.muted = set(r.emulator.frames)
        r.run(1.0)
        snapshot = r.agent.snapshot
        assert snapshot is not None
        assert snapshot.reading is None
        assert snapshot.fix is not None
        r.clock.advance(0.01)
        assert r.agent.ping() is None
        r.agent.gps = receiver  # the receiver's speed, where the car's is missing
        r.run(0.1)
        r.clock.advance(0.01)
        ping = r.agent.ping()
        assert ping is not None
        assert ping["speed_mps"] == pytest.approx(22.0, abs=0.5)


def test_a_button_car_that_does_not_report_its_gap_hands_back_and_says_so(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The Rogue's FOLLOW_DISTANCE 0 ("no follow distance") is no gap the sequencer can step
    from: it pressed nothing, never stalled, and the agent stayed engaged commanding nothing."""
    with rig("nissan_rogue", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r, set_speed_mph=50)
        r.emulator.acc.gap_setting = 0
        r.run(1.0, until=lambda: not engaged(r))
        assert not engaged(r)
        assert r.agent.state.reason == "ACC set speed or gap not reported by the car"
        r.emulator.acc.gap_setting = 3
        r.run(5.0, until=lambda: engaged(r))
        assert engaged(r), r.agent.state.reason


def test_no_ping_is_stamped_by_a_wall_clock_the_gps_time_contradicts(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """A Pi has no real-time clock: booted, it reads its last shutdown's time until NTP sets
    it, and its pings were stamped hours off, which the server stores (inside its window)."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        r.gps.utc_ahead_of_wall_s = 3 * 3600.0  # the clock is three hours behind
        r.run(3.0)
        assert r.agent.stats.pings_spooled == 0
        assert r.agent.stats.pings_clock_unset >= 2
        # a receiver a second late is within what the check allows
        r.gps.utc_ahead_of_wall_s = -1.0
        r.run(3.0)
        assert r.agent.stats.pings_spooled >= 2
        # NTP sets the clock: pings carry the GPS's time, within the allowance
        r.clock.step_wall(3 * 3600.0 - 0.5)
        r.gps.utc_ahead_of_wall_s = 0.5
        spooled = r.agent.stats.pings_spooled
        r.run(3.0)
        assert r.agent.stats.pings_spooled >= spooled + 2


def test_pings_go_on_after_the_wall_clock_steps_back(tmp_path: Path, dbc_cache: Path) -> None:
    """NTP steps the wall clock back an hour: no ping may have the same (vehicle, ts) as the
    last, but the car must not go silent for the hour until its clock passes that ts again."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="microaccel") as r:
        engage_and_settle(r)
        r.run(3.0)
        spooled = r.agent.stats.pings_spooled
        r.clock.step_wall(-3600.0)
        r.run(5.0)
        assert r.agent.stats.pings_spooled >= spooled + 4
        assert engaged(r), r.agent.state.reason  # the plan's age is the car's steady clock's


def test_a_plan_answer_brings_the_config_forward_once_per_newer_version(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The plan answer's `X-Config-Version` brought the config refresh forward whenever it
    differed from the car's: a refresh failing for a lasting reason was retried at every plan
    poll instead of backing off, and a replica answering from memory in a database outage,
    naming an older version, had the car read its config every 5 s (review)."""
    with rig(
        "toyota_rav4", tmp_path, dbc_cache, controller="simple", config_fields={"config_version": 4}
    ) as r:
        announced = r.agent._config_announced
        assert not announced(None, 4)  # an old server names none
        assert not announced(3, 4)  # older: no news
        assert not announced(4, 4)
        assert announced(5, 4)  # newer: read it now
        assert not announced(5, 4)  # the same news again: the refresh's schedule rules
        assert announced(6, 4)


def test_a_control_pass_after_the_stop_neither_engages_nor_sends(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The stop waits 2 s for the control loop (`runner.LOOP_JOIN_S`); a pass blocked longer
    ran on after the stop had handed the car back, stepped the engage state on from what it
    read before, and sent: after the stop, passes went on to engage the car again (review)."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r)
        r.agent.shutdown()
        assert r.agent.state.mode is Mode.STOCK
        r.run(0.1)  # the car receives what was on the bus at the stop
        frames = r.emulator.agent_frames
        r.run(5.0)  # passes as a control thread outwaited by the stop would run them
        assert r.agent.state.mode is Mode.STOCK
        assert r.emulator.agent_frames == frames


def test_a_stop_during_a_control_pass_leaves_the_car_handed_back(
    tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The stop may come from another thread while a pass is reading the car (its thread
    outwaited by the stop): that pass then stepped the engage state on from the state before
    the stop, said the car was engaged again, and could send (second review). The stop lands
    here in the middle of the pass's engage checks, as the other thread would."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r)
        checks = r.agent._enabled

        def stop_meanwhile(assignment: object) -> bool:
            r.agent.shutdown()
            return checks(assignment)  # type: ignore[arg-type]

        monkeypatch.setattr(r.agent, "_enabled", stop_meanwhile)
        admitted = r.agent.safety.sent
        r.agent.tick()
        assert r.agent.state.mode is Mode.STOCK
        assert r.agent.state.reason == "stopped"
        assert r.agent.safety.sent == admitted  # no frame admitted after the stop


def test_a_stop_during_the_controller_step_sends_nothing_after_it(
    tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same stop landing later in the pass, while the controller steps: the pass had
    already judged the car engaged, and went on to send the controller's request to the car
    the stop had just handed back."""
    with rig("toyota_rav4", tmp_path, dbc_cache, controller="simple") as r:
        engage_and_settle(r)
        control = r.agent._control
        admitted_at_stop: list[int] = []

        def stop_meanwhile(*arguments: object) -> None:
            r.agent.shutdown()
            admitted_at_stop.append(r.agent.safety.sent)
            control(*arguments)  # type: ignore[arg-type]

        monkeypatch.setattr(r.agent, "_control", stop_meanwhile)
        while not admitted_at_stop:  # until a pass is due to control (every control period)
            r.clock.advance(1 / 30)
            r.agent.tick()
        assert r.agent.safety.sent == admitted_at_stop[0]  # no frame admitted after the stop
