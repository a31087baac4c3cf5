"""The engage state machine: every mode against every combination of inputs, then timings."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vehicle_agent.engage import (
    CHECKS,
    INITIAL,
    TOO_FAST,
    EngageInputs,
    EngagePolicy,
    EngageState,
    Mode,
    failed,
    step,
)

POLICY = EngagePolicy(engage_after_s=1.0, override_holdoff_s=3.0)
FLAGS = [name for name, _ in CHECKS] + ["within_commandable_speed", "driver_active"]


def inputs(time_s: float, **flags: bool) -> EngageInputs:
    values = (
        {name: True for name, _ in CHECKS}
        | {"within_commandable_speed": True, "driver_active": False}
        | flags
    )
    return EngageInputs(time_s=time_s, **values)


STATES = [
    EngageState(Mode.STOCK, 0.0, None, "starting"),
    EngageState(Mode.STOCK, 0.0, 0.0, "waiting for steady conditions"),
    EngageState(Mode.ENGAGED, 0.0, 0.0, "engaged"),
    EngageState(Mode.OVERRIDDEN, 9.5, None, "driver override"),  # within the hold-off
    EngageState(Mode.OVERRIDDEN, 0.0, None, "driver override"),  # hold-off over
]


@pytest.mark.parametrize("state", STATES, ids=lambda s: f"{s.mode.value}-{s.since_s}")
def test_every_state_against_every_combination_of_inputs(state: EngageState) -> None:
    for values in itertools.product([True, False], repeat=len(FLAGS)):
        flags = dict(zip(FLAGS, values, strict=True))
        result = step(state, inputs(10.0, **flags), POLICY)
        all_pass = all(flags[name] for name, _ in CHECKS)
        if flags["driver_active"]:
            assert result.mode is Mode.OVERRIDDEN
            assert result.since_s == 10.0
        elif state.mode is Mode.OVERRIDDEN and state.since_s == 9.5:
            assert result == state  # still within the hold-off
        elif not all_pass:
            first = next(reason for name, reason in CHECKS if not flags[name])
            assert result.mode is Mode.STOCK
            assert result.reason == first
        elif state.mode is Mode.ENGAGED:
            # A car commanded stays commanded however fast: the speed bars only taking over.
            assert result == state
        elif not flags["within_commandable_speed"]:
            assert result.mode is Mode.STOCK
            assert result.reason == TOO_FAST
            assert result.ready_since_s is None  # the wait starts anew once slow enough
        elif state.ready_since_s == 0.0:
            assert result.mode is Mode.ENGAGED
        else:
            # Conditions just started to hold: wait engage_after_s before taking over.
            assert result.mode is Mode.STOCK
            assert result.ready_since_s == 10.0
        # Handing back wins: never engaged while anything is wrong.
        if result.mode is Mode.ENGAGED:
            assert all_pass
            assert not flags["driver_active"]
            if state.mode is not Mode.ENGAGED:
                assert flags["within_commandable_speed"]


@pytest.mark.parametrize("state", STATES, ids=lambda s: f"{s.mode.value}-{s.since_s}")
def test_a_failed_pass_hands_back_and_keeps_an_override_from_the_last_touch(
    state: EngageState,
) -> None:
    result = failed(state, 10.0, "agent step failed")
    assert result.mode is not Mode.ENGAGED
    assert result.ready_since_s is None  # every check holds anew before taking over
    assert result.reason == "agent step failed"
    if state.mode is Mode.OVERRIDDEN:
        assert result.mode is Mode.OVERRIDDEN
        assert result.since_s == state.since_s
        within = state.since_s + POLICY.override_holdoff_s > 10.0
        # all inputs good: still held off within the hold-off, as without the failure
        assert (step(result, inputs(10.0), POLICY).mode is Mode.OVERRIDDEN) is within


def test_takes_over_after_steady_conditions_and_hands_back_at_once() -> None:
    state = INITIAL
    for tick in range(10):
        state = step(state, inputs(tick * 0.1), POLICY)
        assert state.mode is Mode.STOCK
    state = step(state, inputs(1.0), POLICY)
    assert state.mode is Mode.ENGAGED
    for failing in [name for name, _ in CHECKS]:
        handed_back = step(state, inputs(1.1, **{failing: False}), POLICY)
        assert handed_back.mode is Mode.STOCK


def test_a_flickering_input_restarts_the_wait() -> None:
    state = step(INITIAL, inputs(0.0), POLICY)
    state = step(state, inputs(0.5, plan_fresh=False), POLICY)
    state = step(state, inputs(0.6), POLICY)
    state = step(state, inputs(1.2), POLICY)
    assert state.mode is Mode.STOCK
    assert step(state, inputs(1.6), POLICY).mode is Mode.ENGAGED


def test_a_car_too_fast_to_command_is_not_taken_over_but_a_commanded_one_is_kept() -> None:
    # Every check passes from 0 s, the car too fast until 2 s: it waits, saying why, and the
    # wait for steady conditions starts only once it is slow enough.
    state = step(INITIAL, inputs(0.0, within_commandable_speed=False), POLICY)
    assert (state.mode, state.since_s, state.ready_since_s, state.reason) == (
        Mode.STOCK,
        0.0,
        None,
        TOO_FAST,
    )
    assert step(state, inputs(1.5, within_commandable_speed=False), POLICY) == state
    state = step(state, inputs(2.0), POLICY)
    assert (state.mode, state.ready_since_s) == (Mode.STOCK, 2.0)
    assert step(state, inputs(2.9), POLICY).mode is Mode.STOCK
    state = step(state, inputs(3.0), POLICY)
    assert state.mode is Mode.ENGAGED
    # Going over while commanded (downhill): still commanded, the limiter slows it back.
    assert step(state, inputs(3.1, within_commandable_speed=False), POLICY) == state
    # A failing check hands it back with its own reason; once it passes again, the speed
    # keeps the car from being taken over.
    state = step(state, inputs(3.2, plan_fresh=False, within_commandable_speed=False), POLICY)
    assert (state.mode, state.reason) == (Mode.STOCK, "no fresh plan")
    state = step(state, inputs(3.3, within_commandable_speed=False), POLICY)
    assert (state.mode, state.since_s, state.reason) == (Mode.STOCK, 3.3, TOO_FAST)
    # After a driver's override too, the hold-off over.
    state = step(state, inputs(4.0, driver_active=True), POLICY)
    state = step(state, inputs(7.0, within_commandable_speed=False), POLICY)
    assert (state.mode, state.reason) == (Mode.STOCK, TOO_FAST)


def test_driver_override_holds_off_after_the_last_touch() -> None:
    engaged = EngageState(Mode.ENGAGED, 0.0, 0.0, "engaged")
    state = step(engaged, inputs(5.0, driver_active=True), POLICY)
    assert state.mode is Mode.OVERRIDDEN
    state = step(state, inputs(6.0, driver_active=True), POLICY)  # still touching
    assert step(state, inputs(8.9), POLICY).mode is Mode.OVERRIDDEN
    state = step(state, inputs(9.0), POLICY)
    assert state.mode is Mode.STOCK
    state = step(state, inputs(10.0), POLICY)
    assert state.mode is Mode.ENGAGED


flag_sets = st.fixed_dictionaries({name: st.booleans() for name in FLAGS})


@settings(max_examples=400, deadline=None)
@given(events=st.lists(st.tuples(st.floats(0.0, 2.0), flag_sets), min_size=1, max_size=60))
def test_any_sequence_of_inputs_never_commands_while_anything_is_wrong(
    events: list[tuple[float, dict[str, bool]]],
) -> None:
    state = INITIAL
    now = 0.0
    last_touch: float | None = None
    too_fast_at: float | None = None
    for advance, flags in events:
        now += advance
        current = inputs(now, **flags)
        previous = state
        state = step(state, current, POLICY)
        if flags["driver_active"]:
            last_touch = now
        if not flags["within_commandable_speed"]:
            too_fast_at = now
        if state.mode is Mode.ENGAGED:
            assert all(flags[name] for name, _ in CHECKS)
            assert not flags["driver_active"]
            assert last_touch is None or now - last_touch >= POLICY.override_holdoff_s
            if previous.mode is not Mode.ENGAGED:
                assert state.ready_since_s is not None
                assert now - state.ready_since_s >= POLICY.engage_after_s
                # slow enough to command over the whole wait
                assert too_fast_at is None or too_fast_at < state.ready_since_s
