"""Running an agent on a car: the control loop on its own thread at the make's command period
(a rate keeper measuring lag), pings on another, the network on a third, until stopped."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from vehicle_agent.agent import Agent
from vehicle_agent.logs import ThrottledLog
from vehicle_agent.loop import RateKeeper

log = logging.getLogger(__name__)

# How often the loops report their lag in the log (s).
LAG_REPORT_S = 60.0


def run_loop(
    name: str, period_s: float, step: Callable[[], object], stop: threading.Event
) -> RateKeeper:
    """Call `step` every `period_s` until `stop` is set; a step that raises is logged (at most
    once per kind of error every 10 s) and the loop goes on. Returns the rate keeper, with the
    loop's lag."""
    keeper = RateKeeper(period_s)
    failures = ThrottledLog(log)
    reported = time.monotonic()
    while not stop.is_set():
        try:
            step()
        except Exception as error:  # the loop must survive any single bad step
            failures.exception(type(error).__name__, f"{name} step failed")
        keeper.wait()
        if time.monotonic() - reported >= LAG_REPORT_S:
            reported = time.monotonic()
            log.info(
                "%s loop lag p50 %.1f ms, p99 %.1f ms, %d periods missed",
                name,
                keeper.lag_percentile(50) * 1000,
                keeper.lag_percentile(99) * 1000,
                keeper.missed,
            )
    return keeper


# How long the stop waits for the control and telemetry loops to finish their step (s): each
# step takes milliseconds; a loop stuck longer is a fault the stop does not wait out.
LOOP_JOIN_S = 2.0
# The network thread's join after the stop (s): the car is handed back and the spool closed by
# then; this only lets a request that is ending end. With two loop joins and the upload wait
# (`agent.STOP_UPLOAD_WAIT_S`) the stop stays within systemd's 10 s (`TimeoutStopSec`).
NETWORK_JOIN_S = 1.0


def run_agent(agent: Agent, stop: threading.Event) -> None:
    """Run until `stop` is set, then hand the car back and close the spool.

    The car is handed back as soon as the control loop has stopped commanding, not after the
    network thread: that thread may be inside a request for a whole client timeout, and the
    stop used to wait for it first (10 s at most) while systemd gives the whole stop 10 s
    (deploy/smoothfleet-agent.service). `Agent.shutdown` itself waits for the answer to an
    upload in flight before it closes the spool; the network thread is joined last.
    """
    threads = [
        threading.Thread(
            target=run_loop,
            args=("control", agent.command_period_s, agent.tick, stop),
            name="control",
            daemon=True,
        ),
        threading.Thread(
            target=run_loop,
            args=("telemetry", 0.1, agent.record, stop),
            name="telemetry",
            daemon=True,
        ),
        threading.Thread(
            target=run_loop,
            args=("network", 0.2, agent.network, stop),
            name="network",
            daemon=True,
        ),
    ]
    for thread in threads:
        thread.start()
    stop.wait()
    control, telemetry, network = threads
    control.join(timeout=LOOP_JOIN_S)
    telemetry.join(timeout=LOOP_JOIN_S)  # its last ping into the spool before it closes
    agent.shutdown()
    network.join(timeout=NETWORK_JOIN_S)
