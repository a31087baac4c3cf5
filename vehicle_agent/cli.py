"""`smoothfleet-agent`: run the vehicle agent on a car.

    smoothfleet-agent --server https://fleet.example --token TOKEN --vehicle-id SF-001 \\
        --can socketcan:can0

Every option can also come from the environment (SMOOTHFLEET_AGENT_SERVER_URL, ..._TOKEN,
..._VEHICLE_ID, ..._CAN, ..._MAKE, ..._GPS, ..._SPOOL_PATH, ...) or an env file. Without
--make the car's make comes from the server's config for the vehicle.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

import httpx

from vehicle_agent.agent import AGENT_VERSION, Agent
from vehicle_agent.bus import BusSpecError, open_bus
from vehicle_agent.cars import CarInterface, UnknownCarError, car_for
from vehicle_agent.clock import SystemClock
from vehicle_agent.codec import codec_for
from vehicle_agent.dbc import DbcError
from vehicle_agent.gps import GpsdSource, GpsFix, GpsSource
from vehicle_agent.policies import PolicyStore
from vehicle_agent.ports import (
    ButtonBoardRequired,
    GpioButtonBoard,
    release_board_lines,
    require_button_board,
    sysfs_gpio_writer,
)
from vehicle_agent.runner import run_agent
from vehicle_agent.safety import SafetyLayer
from vehicle_agent.server import ServerClient, ServerError
from vehicle_agent.settings import (
    AgentSettings,
    AgentSettingsError,
    board_lines,
    gpsd_address,
    load_agent_settings,
)
from vehicle_agent.spool import PingSpool
from vehicle_agent.state import CarStateReader

log = logging.getLogger("smoothfleet-agent")


class NoGps:
    """No GPS receiver: the agent reports without position and never takes over."""

    def latest(self) -> GpsFix | None:
        """Never a fix."""
        return None


def parser() -> argparse.ArgumentParser:
    """The command line."""
    p = argparse.ArgumentParser(
        prog="smoothfleet-agent", description="Run the smoothfleet vehicle agent on this car."
    )
    p.add_argument("--server", dest="server_url", help="server URL (SMOOTHFLEET_AGENT_SERVER_URL)")
    p.add_argument("--token", help="the vehicle's bearer token (SMOOTHFLEET_AGENT_TOKEN)")
    p.add_argument("--vehicle-id", help="roster id, e.g. SF-001 (SMOOTHFLEET_AGENT_VEHICLE_ID)")
    p.add_argument("--can", help="CAN channel, e.g. socketcan:can0 (SMOOTHFLEET_AGENT_CAN)")
    p.add_argument(
        "--make",
        help="car interface: nissan_rogue (2023), cadillac_xt5, toyota_rav4 or nissan_rogue_2018",
    )
    p.add_argument("--gps", help="gpsd:<host>:<port> or none (SMOOTHFLEET_AGENT_GPS)")
    p.add_argument("--spool", dest="spool_path", type=Path, help="ping spool SQLite file")
    p.add_argument("--button-board", help="GPIO lines, e.g. plus=17,minus=27,gap=22")
    p.add_argument("--env-file", type=Path, help="read SMOOTHFLEET_AGENT_* settings from a file")
    p.add_argument("--log-level", help="DEBUG, INFO, WARNING (SMOOTHFLEET_AGENT_LOG_LEVEL)")
    p.add_argument(
        "--release-buttons",
        action="store_true",
        help="write every button-board line low and exit (run after the agent stops, however)",
    )
    p.add_argument("--version", action="version", version=f"smoothfleet-agent {AGENT_VERSION}")
    return p


def choose_car(
    settings: AgentSettings, server: ServerClient, stop: threading.Event
) -> CarInterface:
    """The car from --make, or from the server's config (retried until the server answers)."""
    if settings.make:
        return car_for(settings.make)
    delay = 1.0
    while not stop.is_set():
        try:
            config = server.config()
            return car_for(config.make, config.model, config.year)
        except ServerError as error:
            if error.status in (401, 403, 404):
                raise
            log.warning("waiting for the server to learn the car's make: %s", error)
        stop.wait(delay)
        delay = min(delay * 2, 30.0)
    raise KeyboardInterrupt


def gps_source(settings: AgentSettings) -> GpsSource:
    """gpsd (gpsd:<host>:<port>), or none."""
    address = gpsd_address(settings.gps)
    if address is None:
        return NoGps()
    source = GpsdSource(time.monotonic, *address)
    source.start()
    return source


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `smoothfleet-agent`."""
    args = parser().parse_args(argv)
    try:
        settings = load_agent_settings(
            args.env_file,
            server_url=args.server_url,
            token=args.token,
            vehicle_id=args.vehicle_id,
            can=args.can,
            make=args.make,
            gps=args.gps,
            spool_path=args.spool_path,
            button_board=args.button_board,
            log_level=args.log_level,
        )
    except AgentSettingsError as error:
        sys.stderr.write(f"smoothfleet-agent: {error}\n")
        return 2
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    if settings.button_board:
        # a line an earlier agent left high (killed mid-press) would hold its button down
        failures = release_board_lines(
            board_lines(settings.button_board), sysfs_gpio_writer(settings.gpio_root)
        )
        for failure in failures:
            sys.stderr.write(f"smoothfleet-agent: {failure}\n")
        if failures or args.release_buttons:
            return 1 if failures else 0
    elif args.release_buttons:
        return 0  # no board set: nothing to lower (CAN button frames stop with the agent)
    stop = threading.Event()

    def request_stop(signum: int, frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, request_stop)
    signal.signal(signal.SIGINT, request_stop)
    with httpx.Client(base_url=settings.server_url) as http:
        server = ServerClient(
            http, settings.vehicle_id, settings.token.get_secret_value(), settings.http_timeout_s
        )
        try:
            car = choose_car(settings, server, stop)
            # before the bus, the spool and gpsd: a car the agent cannot press is refused first
            require_button_board(car, has_board=bool(settings.button_board))
            codec = codec_for(car.dbc_name, car.checksums, settings.dbc_cache_dir)
            filters = CarStateReader(car, codec).can_filters()
            bus = open_bus(settings.can, filters, fd=car.can_fd)
        except (ServerError, UnknownCarError, DbcError, BusSpecError, ButtonBoardRequired) as error:
            sys.stderr.write(f"smoothfleet-agent: {error}\n")
            return 1
        except KeyboardInterrupt:
            return 0
        # a spool file that cannot be opened (a missing or read-only card) holds its pings in
        # memory and says so in the log (vehicle_agent.spool): the agent still runs the car's
        # controller and reports its status, the backlog showing the fault
        spool = PingSpool(settings.spool_file, settings.spool_max_rows)
        board = None
        if settings.button_board:
            lines = board_lines(settings.button_board)
            writer = sysfs_gpio_writer(settings.gpio_root)

            def board(safety: SafetyLayer) -> GpioButtonBoard:
                return GpioButtonBoard(lines, writer, safety)

        agent = Agent(
            vehicle_id=settings.vehicle_id,
            car=car,
            bus=bus,
            clock=SystemClock(),
            gps=gps_source(settings),
            spool=spool,
            server=server,
            button_port=board,
            dbc_cache=settings.dbc_cache_dir,
            wave_speed_mps=settings.wave_speed_mps,
            policies=PolicyStore(settings.policy_dir),
        )
        log.info(
            "agent %s for %s (%s) on %s", AGENT_VERSION, settings.vehicle_id, car.key, settings.can
        )
        try:
            run_agent(agent, stop)
        finally:
            bus.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
