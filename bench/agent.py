"""Vehicle agent speed: one control step, and the agent's CPU and memory on a busy bus.

    .venv/bin/python -m bench.agent [--steps 3000] [--seconds 60] [--fps 2000]

(as a module, like the other benches, so the repository's packages import)

1. One control step, per make: the frames the emulated car sent during one 0.1 s control period
   are waiting on the virtual bus; the timed `Agent.tick()` decodes them, builds the car state,
   runs the engage logic and the controller, and (RAV4) limits, encodes and safety-checks the
   acceleration request and sends it. The emulator's own stepping is not timed. Baseline in the
   same run: decoding the same frames with cantools alone (the least any agent must do).
   Goal (issue 5): p99 <= 1 ms. Then each controller's `step` alone on one observation (what
   it adds to a tick; issue 13's policies beside the hand-designed controllers).
2. The agent (its three threads, as `smoothfleet-agent` runs them) on a RAV4 driving behind a
   leader while the bus carries --fps frames/s (the car's own ~200 frames/s topped up with
   frames of ids the agent does not watch; a virtual bus does not filter, so the agent sees and
   ignores them all) for --seconds. CPU share of one core of the agent's
   threads (from /proc/self/task), and the process's peak RSS. Baseline in the same run: the
   thread putting the frames on the bus. Goal: RSS <= 150 MB.
"""

from __future__ import annotations

import argparse
import itertools
import os
import resource
import tempfile
import threading
import time
from pathlib import Path

import can
import numpy as np

from sim.emulator.car import CarEmulator, board_wired_to
from sim.emulator.leaders import ConstantSpeedLeader
from sim.emulator.rig import EmulatorGps, seed_geometry, uniform_plan, vehicle_config
from vehicle_agent.agent import Agent
from vehicle_agent.cars import car_for
from vehicle_agent.clock import ManualClock, SystemClock
from vehicle_agent.controllers import Observation, TargetProfile, build_controller
from vehicle_agent.engage import EngagePolicy, Mode
from vehicle_agent.gps import GpsFix
from vehicle_agent.runner import run_agent
from vehicle_agent.spool import PingSpool

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")
_channels = itertools.count()


class LatchedGps:
    """A GPS receiver's latest fix, refreshed by the (untimed) emulator loop at 10 Hz, read by
    the agent as it reads gpsd's: an attribute, not a computation."""

    def __init__(self, source: EmulatorGps) -> None:
        self.source = source
        self.fix: GpsFix | None = None

    def refresh(self) -> None:
        self.fix = self.source.latest()

    def latest(self) -> GpsFix | None:
        return self.fix


def build(
    key: str, controller: str, clock: ManualClock | SystemClock, spool_dir: Path
) -> tuple[Agent, CarEmulator, can.BusABC, can.BusABC]:
    channel = f"bench-agent-{next(_channels)}"
    car_bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    agent_bus = can.Bus(interface="virtual", channel=channel)
    start = clock.monotonic()
    emulator = CarEmulator(
        key,
        car_bus,
        speed_mps=25.0,
        position_m=1000.0,
        corridor=seed_geometry(),
        start_s=start,
        leader=ConstantSpeedLeader(1045.0, 25.0, start),
        frame_epoch_s=lambda: clock.now().timestamp(),
    )
    agent = Agent(
        vehicle_id="SF-BENCH",
        car=car_for(key),
        bus=agent_bus,
        clock=clock,
        gps=LatchedGps(EmulatorGps(emulator, clock)),  # type: ignore[arg-type]
        spool=PingSpool(spool_dir / f"{channel}.sqlite"),
        engage_policy=EngagePolicy(engage_after_s=0.2, override_holdoff_s=0.2),
        button_port=board_wired_to(emulator),
    )
    agent.configure(vehicle_config(key, controller, stale_plan_after_s=3600.0), seed_geometry())
    agent.accept_plan(uniform_plan(25.0, published=clock.now()))
    emulator.driver_engage(set_speed_mph=56)
    return agent, emulator, car_bus, agent_bus


def control_step(key: str, controller: str, steps: int, spool_dir: Path) -> dict[str, float]:
    """Timed Agent.tick() over one control period's frames; cantools-only decode as baseline."""
    clock = ManualClock(monotonic_s=100.0)
    agent, emulator, car_bus, agent_bus = build(key, controller, clock, spool_dir)
    listener = can.Bus(interface="virtual", channel=car_bus.channel_info.split(" ")[-1])
    tick_ns, decode_ns, frames_per_period = [], [], []
    database = agent.codec.database
    for step in range(steps + 50):
        for _ in range(10):  # the car's frames of one period, as it sends them (10 ms steps)
            clock.advance(0.01)
            emulator.step(clock.monotonic())
        agent.gps.refresh()  # type: ignore[attr-defined]
        frames = []
        while (frame := listener.recv(timeout=0)) is not None:
            frames.append(frame)
        agent._next_control_s = 0.0  # a control step is due on every timed tick
        started = time.perf_counter_ns()
        agent.tick()
        elapsed = time.perf_counter_ns() - started
        started = time.perf_counter_ns()
        for frame in frames:
            database.decode_message(frame.arbitration_id, frame.data, decode_choices=False)
        baseline = time.perf_counter_ns() - started
        if step >= 50:  # warmed up and engaged
            tick_ns.append(elapsed)
            decode_ns.append(baseline)
            frames_per_period.append(len(frames))
        emulator.step(clock.monotonic())  # let the car read the agent's command
    assert agent.state.mode is Mode.ENGAGED, agent.state.reason
    for bus in (car_bus, agent_bus, listener):
        bus.shutdown()
    agent.spool.close()
    return {
        "p50_us": float(np.percentile(tick_ns, 50)) / 1000,
        "p90_us": float(np.percentile(tick_ns, 90)) / 1000,
        "p99_us": float(np.percentile(tick_ns, 99)) / 1000,
        "base_p50_us": float(np.percentile(decode_ns, 50)) / 1000,
        "base_p99_us": float(np.percentile(decode_ns, 99)) / 1000,
        "frames": float(np.mean(frames_per_period)),
        "control_steps": float(agent.stats.control_steps),
    }


def controller_alone(name: str, actuation: str, steps: int) -> dict[str, float]:
    """`controller.step` timed alone on one observation (what a controller adds to a tick)."""
    profile = TargetProfile(np.linspace(0.0, 5000.0, 51), np.full(51, 25.0))
    observation = Observation(
        time_s=0.0,
        speed_mps=24.0,
        target_speed_mps=25.0,
        position_m=1000.0,
        target=profile,
        lead_present=True,
        lead_distance_m=40.0,
        lead_rel_speed_mps=-1.0,
        acc_speed_setting_mph=55.0,
        acc_gap_setting=3,
    )
    controller = build_controller(name, actuation)
    elapsed_ns = []
    for step in range(steps + 500):
        started = time.perf_counter_ns()
        controller.step(observation)
        if step >= 500:
            elapsed_ns.append(time.perf_counter_ns() - started)
    return {
        "p50_us": float(np.percentile(elapsed_ns, 50)) / 1000,
        "p99_us": float(np.percentile(elapsed_ns, 99)) / 1000,
    }


def thread_cpu_s(native_ids: list[int]) -> float:
    """User + system CPU seconds of these threads of this process."""
    total = 0
    for tid in native_ids:
        fields = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
        total += int(fields[11]) + int(fields[12])  # utime, stime (fields 14 and 15)
    return total / CLOCK_TICKS


def busy_bus(seconds: float, fps: int, spool_dir: Path) -> dict[str, float]:
    """The running agent's CPU share and the process RSS with `fps` frames/s on its bus."""
    clock = SystemClock()
    agent, emulator, car_bus, agent_bus = build("toyota_rav4", "microaccel", clock, spool_dir)
    stop = threading.Event()
    sent = [0]
    gps = agent.gps
    assert isinstance(gps, LatchedGps)

    def traffic() -> None:
        filler_ids = itertools.cycle(range(0x600, 0x6FF))
        period = 0.01
        next_s = time.monotonic()
        while not stop.is_set():
            before = emulator.sent
            emulator.step(time.monotonic())
            gps.refresh()
            fill = max(int(fps * period) - (emulator.sent - before), 0)
            for _ in range(fill):
                car_bus.send(
                    can.Message(
                        arbitration_id=next(filler_ids), data=bytes(8), is_extended_id=False
                    )
                )
            sent[0] += emulator.sent - before + fill
            next_s += period
            time.sleep(max(next_s - time.monotonic(), 0.0))

    generator = threading.Thread(target=traffic, name="traffic", daemon=True)
    runner = threading.Thread(target=run_agent, args=(agent, stop), name="agent", daemon=True)
    generator.start()
    before_threads = {t.native_id for t in threading.enumerate()}
    runner.start()
    time.sleep(0.5)
    agent_threads = [
        t.native_id
        for t in threading.enumerate()
        if t.native_id not in before_threads and t.native_id is not None
    ]
    assert generator.native_id is not None
    cpu_agent_0, cpu_gen_0 = thread_cpu_s(agent_threads), thread_cpu_s([generator.native_id])
    frames_0, wall_0 = sent[0], time.monotonic()
    time.sleep(seconds)
    cpu_agent = thread_cpu_s(agent_threads) - cpu_agent_0
    cpu_gen = thread_cpu_s([generator.native_id]) - cpu_gen_0
    wall = time.monotonic() - wall_0
    frames = sent[0] - frames_0
    engaged = agent.state.mode is Mode.ENGAGED
    reason = agent.state.reason
    stop.set()
    runner.join(timeout=20)
    generator.join(timeout=5)
    car_bus.shutdown()
    agent_bus.shutdown()
    return {
        "agent_cpu_pct": 100 * cpu_agent / wall,
        "generator_cpu_pct": 100 * cpu_gen / wall,
        "fps": frames / wall,
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "engaged": float(engaged),
        "ticks": float(agent.stats.ticks),
        "reason": reason,  # type: ignore[dict-item]
    }


def main() -> None:
    """Run both measurements and print them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fps", type=int, default=2000)
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    with tempfile.TemporaryDirectory() as spool_dir:
        print(f"\n1. one control step ({args.steps} steps per make, microseconds)")
        print(
            "   make / controller            frames  p50    p90    p99    cantools decode p50/p99"
            "  ratio p50"
        )
        for key, controller in (
            ("toyota_rav4", "microaccel"),
            ("toyota_rav4", "rl_accel"),
            ("nissan_rogue", "microaccel_acc"),
            ("nissan_rogue", "rl_acc"),
            ("cadillac_xt5", "microaccel_acc"),
        ):
            r = control_step(key, controller, args.steps, Path(spool_dir))
            print(
                f"   {key + ' / ' + controller:30s} {r['frames']:5.1f}  {r['p50_us']:5.0f}  "
                f"{r['p90_us']:5.0f}  {r['p99_us']:5.0f}  "
                f"{r['base_p50_us']:5.0f} / {r['base_p99_us']:5.0f}"
                f"         {r['p50_us'] / r['base_p50_us']:4.1f}x"
            )
        print("\n   the controller alone (same observation, microseconds): p50 / p99")
        for name, actuation in (
            ("microaccel", "accel"),
            ("rl_accel", "accel"),
            ("microaccel_acc", "acc"),
            ("rl_acc", "acc"),
        ):
            alone = controller_alone(name, actuation, args.steps)
            print(f"   {name:30s} {alone['p50_us']:7.1f} / {alone['p99_us']:7.1f}")
        print(
            f"\n2. agent on a {args.fps} frames/s bus for {args.seconds:.0f} s (RAV4, microaccel)"
        )
        r = busy_bus(args.seconds, args.fps, Path(spool_dir))
        print(
            f"   frames on the bus: {r['fps']:.0f}/s; agent engaged at the end: "
            f"{bool(r['engaged'])} ({r['reason']})"
        )
        print(
            f"   agent threads CPU: {r['agent_cpu_pct']:.1f} % of one core; baseline (the "
            f"traffic thread): {r['generator_cpu_pct']:.1f} %; ratio "
            f"{r['agent_cpu_pct'] / max(r['generator_cpu_pct'], 1e-9):.2f}x"
        )
        print(f"   peak RSS of the process: {r['rss_mb']:.0f} MB")
    print(f"\nload average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
