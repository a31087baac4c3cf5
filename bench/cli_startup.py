"""How long a `smoothfleet` command takes to start: the time before it does any work.

    .venv/bin/python -m bench.cli_startup [--repeat 5]

Each command line is run with `--help` (it parses its options and stops, so what is timed is
the interpreter and the imports the command needs), `--repeat` times, and the median wall time
printed. Two baselines from the same run: a bare interpreter (`python -c pass`, the floor) and
every command module imported before the same `--help` (what `smoothfleet --help`, which lists
them all, pays; the most any command could pay). The test suite runs the CLI as a subprocess
about a hundred times, so what a command imports is paid there too.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

COMMANDS = (
    (),  # the listing of every command
    ("sim", "evaluate"),
    ("sim", "train"),
    ("motion", "generate"),
    ("db", "upgrade"),
    ("vehicles", "list"),
    ("inrix", "replay"),
    ("serve",),
    ("demo",),
)
# Every command module, as one import.
EVERY_COMMAND_MODULE = (
    "import smoothfleet.cli.db, smoothfleet.cli.vehicles, smoothfleet.cli.tokens, "
    "smoothfleet.cli.users, smoothfleet.cli.analytics, smoothfleet.cli.serve, "
    "smoothfleet.cli.demo, smoothfleet.cli.inrix, smoothfleet.cli.sim, smoothfleet.cli.planner, "
    "smoothfleet.cli.motion, smoothfleet.cli.policy"
)


def median_wall_s(argv: list[str], repeat: int) -> float:
    """Median wall time of `argv` over `repeat` runs (each must succeed)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    python = sys.executable
    floor = median_wall_s([python, "-c", "pass"], args.repeat)
    print(f"{'baseline: bare interpreter':<24} {floor:6.2f} s")
    for words in COMMANDS:
        lazy = median_wall_s([python, "-m", "smoothfleet.cli", *words, "--help"], args.repeat)
        eager_code = (
            f"{EVERY_COMMAND_MODULE}; import sys; from smoothfleet.cli.main import main; "
            f"sys.argv = ['smoothfleet', *{list(words)!r}, '--help']; main()"
        )
        eager = median_wall_s([python, "-c", eager_code], args.repeat)
        label = " ".join([*words, "--help"])
        print(f"{label:<24} {lazy:6.2f} s   baseline (every command module) {eager:6.2f} s")


if __name__ == "__main__":
    main()
