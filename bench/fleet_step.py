"""The demo fleet's control step: can one worker process hold 10 Hz for its cars?

    .venv/bin/python -m bench.fleet_step [--vehicles 50] [--seconds 30]

(as a module, like the other benches, so the repository's packages import)

Builds one fleet worker's cars exactly as `smoothfleet demo` does (`sim.fleet.worker.Fleet`:
every car the real agent on its own virtual CAN bus with a car emulator of its make, in the
demo's looped real stop-and-go traffic), --vehicles cars of the seed roster (the demo
splits its 100 cars over two workers, so 50 is one worker's share; every n-th roster car, so
the makes mix as in a worker). There is no server: each
agent is given its roster controller and a plan at the traffic's speed directly, so the timed
loop is the control step alone. The cars are stepped every 0.1 s of real time for --seconds, as
the worker's control thread does, and the script prints:
- the CPU one control step of all the cars takes (thread time: what the machine's load does not
  inflate much) at p50 / p90 / p99, per car, and the share of the 0.1 s period it fills;
- the wall interval between steps and the share of late steps (those the load does inflate);
- the share of car-steps with the controller engaged (the agents really drove);
- baseline, measured in the same run: cantools decoding the same number of frames of each make
  as the agents received, and nothing else (the least a real agent must do with its bus).
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from collections import Counter
from pathlib import Path

import can
import numpy as np

from contract.corridor import CorridorGeometry
from seed_data.build import ROSTER_FILE
from sim.drives import load_drive
from sim.emulator.rig import seed_geometry
from sim.fleet.traffic import CorridorTraffic, synthetic_waves
from sim.fleet.worker import CONTROL_PERIOD_S, Fleet, VehicleSpec
from smoothfleet.cli.demo import TRAFFIC_DRIVE, TRAFFIC_OFFSET_S
from vehicle_agent.cars import car_for
from vehicle_agent.codec import codec_for

# Cars start this far inside the corridor's ends (m), as in the demo.
START_MARGIN_M = 300.0
WARM_UP_S = 5.0


def roster_specs(count: int, geometry: CorridorGeometry) -> list[tuple[VehicleSpec, str]]:
    """`count` roster cars (every n-th: the makes mixed as in a demo worker) spread along the
    corridor, with their controllers."""
    with ROSTER_FILE.open() as roster:
        rows = list(csv.DictReader(roster))
    rows = rows[:: max(1, len(rows) // count)][:count]
    spacing = (geometry.length_m - 2 * START_MARGIN_M) / max(1, len(rows))
    return [
        (
            VehicleSpec(
                vehicle_id=row["vehicle_id"],
                make=row["make"],
                model=row["model"],
                year=int(row["year"]),
                lane=int(row["assigned_lane"]),
                token="",
                position_m=START_MARGIN_M + order * spacing,
            ),
            row["controller_name"],
        )
        for order, row in enumerate(rows)
    ]


def decode_baseline(frames_per_make: Counter[str], dbc_cache: Path) -> float:
    """Seconds cantools takes to decode that many frames of each make's watched messages."""
    elapsed = 0.0
    for key, count in frames_per_make.items():
        interface = car_for(key)
        codec = codec_for(interface.dbc_name, interface.checksums, dbc_cache)
        database = codec.database
        frames = [
            can.Message(
                arbitration_id=codec.frame_id(name),
                data=codec.encode(name, {}),
                is_extended_id=False,
            )
            for name in interface.messages
        ]
        started = time.thread_time()
        for index in range(count):
            frame = frames[index % len(frames)]
            database.decode_message(frame.arbitration_id, bytes(frame.data), decode_choices=False)
        elapsed += time.thread_time() - started
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=30.0)
    args = parser.parse_args()
    geometry = seed_geometry()
    drive = load_drive(TRAFFIC_DRIVE) if TRAFFIC_DRIVE.is_file() else synthetic_waves()
    with tempfile.TemporaryDirectory(prefix="sf-fleet-step-") as scratch:
        dbc_cache = Path(scratch) / "dbc"
        specs = roster_specs(args.vehicles, geometry)
        fleet = Fleet(
            [spec for spec, _ in specs],
            geometry,
            CorridorTraffic(drive, start_offset_s=TRAFFIC_OFFSET_S),
            epoch_unix_s=time.time(),
            spool_dir=Path(scratch),
            dbc_cache=dbc_cache,
            server_for=lambda vehicle: None,
        )
        for car, (_, controller) in zip(fleet.cars, specs, strict=True):
            car.configure_without_server(controller, geometry, 25.0)
        fleet.start()
        step_cpu: list[float] = []
        intervals: list[float] = []
        frames_before: Counter[str] = Counter()
        engaged_before = 0
        steps_before = 0
        late = 0
        next_step = time.monotonic()
        measuring_from = next_step + WARM_UP_S
        last = next_step
        end = measuring_from + args.seconds
        while True:
            now = time.monotonic()
            if now >= end:
                break
            started = time.thread_time()
            fleet.control_step()
            used = time.thread_time() - started
            if now >= measuring_from:
                if not step_cpu:  # the first measured step: counters from here
                    for car in fleet.cars:
                        frames_before[car.agent.car.key] += car.agent.reader.stats.frames
                    engaged_before, steps_before = fleet.engaged_steps, fleet.steps - 1
                else:
                    intervals.append(now - last)
                step_cpu.append(used)
            last = now
            next_step += CONTROL_PERIOD_S
            pause = next_step - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            else:
                late += now >= measuring_from
                next_step = time.monotonic()
        frames: Counter[str] = Counter()
        for car in fleet.cars:
            frames[car.agent.car.key] += car.agent.reader.stats.frames
        frames.subtract(frames_before)
        steps = fleet.steps - steps_before
        engaged = (fleet.engaged_steps - engaged_before) / max(1, steps * len(fleet.cars))
        modes = Counter(car.agent.state.mode.value for car in fleet.cars)
        fleet.close()
        baseline = decode_baseline(frames, dbc_cache)
    cpu_ms = 1000 * np.array(step_cpu)
    period_ms = 1000 * CONTROL_PERIOD_S
    makes = ", ".join(
        f"{count} {key}" for key, count in Counter(c.agent.car.key for c in fleet.cars).items()
    )
    print(f"{len(fleet.cars)} cars ({makes}), {steps} control steps over {args.seconds:.0f} s")
    print(
        f"control step CPU  : p50 {np.percentile(cpu_ms, 50):6.1f} ms, p90 "
        f"{np.percentile(cpu_ms, 90):6.1f} ms, p99 {np.percentile(cpu_ms, 99):6.1f} ms "
        f"({1000 * np.median(cpu_ms) / len(fleet.cars):.0f} us per car; p50 fills "
        f"{100 * np.median(cpu_ms) / period_ms:.0f} % of the {period_ms:.0f} ms period)"
    )
    print(
        f"wall between steps: mean {1000 * np.mean(intervals):6.1f} ms, p99 "
        f"{1000 * np.percentile(intervals, 99):6.1f} ms; "
        f"late steps {100 * late / max(1, steps):.0f} %"
    )
    print(f"engaged           : {100 * engaged:.0f} % of car-steps; modes at the end {dict(modes)}")
    decoded = sum(frames.values())
    print(
        f"baseline          : cantools decoding the {decoded} frames the agents received "
        f"({decoded / max(1, steps):.0f} a step): {1000 * baseline / max(1, steps):.1f} ms a step"
    )


if __name__ == "__main__":
    main()
