"""`smoothfleet sim ...`: the simulator on the real I-24 drives from the command line, one module
per command."""

from __future__ import annotations

import click

from smoothfleet.cli.sim.evaluate import evaluate_command
from smoothfleet.cli.sim.fleet import fleet_command
from smoothfleet.cli.sim.optimum import optimum_command
from smoothfleet.cli.sim.selection import select_command
from smoothfleet.cli.sim.time_space import time_space_command
from smoothfleet.cli.sim.train import train_command

__all__ = ["evaluate_command", "sim"]


@click.group("sim")
def sim() -> None:
    """Simulate platoons on real I-24 drives: evaluate planners x controllers."""


for command in (
    evaluate_command,
    select_command,
    time_space_command,
    fleet_command,
    train_command,
    optimum_command,
):
    sim.add_command(command)
