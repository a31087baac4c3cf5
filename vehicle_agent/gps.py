"""GPS for the agent: a fix source behind one small interface (gpsd on a car, the emulator in
simulation and tests)."""

from __future__ import annotations

import json
import logging
import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import datetime
from typing import Any, Protocol

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class GpsFix:
    """One position fix; `time_s` is the agent's monotonic time when it arrived."""

    time_s: float
    lat: float
    lon: float
    has_fix: bool = True
    speed_mps: float | None = None
    heading_deg: float | None = None
    satellites: int | None = None
    # The lane, where a lane source exists (a simulation); GPS alone cannot tell lanes apart.
    lane: int | None = None
    # The receiver's time of the fix (UTC, from the satellites): what the agent's own wall
    # clock is checked against before it stamps a ping (a Pi has no real-time clock).
    utc: datetime | None = None


class GpsSource(Protocol):
    """Anything that can say where the car is."""

    def latest(self) -> GpsFix | None:
        """The most recent fix, or None before the first one."""


class GpsdSource:
    """Fixes from gpsd's JSON protocol (TPV reports; SKY for the satellite count), read by a
    background thread so the control loop never waits on the GPS."""

    def __init__(
        self, clock: Callable[[], float], host: str = "127.0.0.1", port: int = 2947
    ) -> None:
        self.clock = clock
        self.address = (host, port)
        self._latest: GpsFix | None = None
        self._satellites: int | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gpsd", daemon=True)

    def start(self) -> None:
        """Start reading in the background (reconnecting when gpsd goes away)."""
        self._thread.start()

    def stop(self) -> None:
        """Stop the reader thread."""
        self._stop.set()

    def latest(self) -> GpsFix | None:
        """The most recent TPV fix."""
        return self._latest

    def handle(self, line: str) -> None:
        """Fold in one gpsd JSON report; one that is not the shape gpsd documents (a null
        position, a list, text where a number belongs) is skipped, not allowed to end the
        reader thread: a reader gone quiet leaves the car without a current fix."""
        try:
            report = json.loads(line)
        except (ValueError, RecursionError):  # not JSON, a 5,000-digit number, deep nesting
            return
        if not isinstance(report, dict):
            return
        try:
            self._fold(report)
        except (TypeError, ValueError, AttributeError, OverflowError) as error:
            # OverflowError: "mode": 1e999, a latitude of 400 digits
            log.debug("gpsd: skipped a %s report (%s)", report.get("class"), error)

    def _fold(self, report: dict[str, Any]) -> None:
        if report.get("class") == "SKY":
            # gpsd sends some SKY reports with the dilutions only: those say nothing of the
            # satellites, and must not read as none
            if isinstance(report.get("satellites"), list):
                self._satellites = sum(1 for s in report["satellites"] if s.get("used"))
            elif isinstance(report.get("uSat"), int):
                self._satellites = int(report["uSat"])
        elif report.get("class") == "TPV" and "lat" in report and "lon" in report:
            lat, lon = float(report["lat"]), float(report["lon"])
            # json reads NaN: a position that is no number, or off the globe, is no fix (it
            # read as one, and the car showed a fix it could build no ping from)
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
                raise ValueError(f"position ({lat}, {lon}) is not on the globe")
            self._latest = GpsFix(
                time_s=self.clock(),
                lat=lat,
                lon=lon,
                has_fix=int(report.get("mode") or 0) >= 2,
                speed_mps=_number(report.get("speed")),
                heading_deg=_number(report.get("track")),
                satellites=self._satellites,
                utc=_utc(report.get("time")),
            )
        elif report.get("class") == "TPV" and "mode" in report and int(report["mode"]) < 2:
            # gpsd's word that the receiver lost its fix comes with no position: the last fix
            # stops being one now, not 2 s later when it ages out, while the car drove on
            # extrapolated from it
            if self._latest is not None:
                self._latest = replace(self._latest, time_s=self.clock(), has_fix=False)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                with socket.create_connection(self.address, timeout=5) as connection:
                    connection.sendall(b'?WATCH={"enable":true,"json":true}\n')
                    buffer = b""
                    while not self._stop.is_set():
                        chunk = connection.recv(4096)
                        if not chunk:
                            break
                        buffer += chunk
                        *lines, buffer = buffer.split(b"\n")
                        for line in lines:
                            self.handle(line.decode("utf-8", "replace"))
                        if len(buffer) > MAX_REPORT_BYTES:  # no newline in sight: not gpsd
                            raise OSError(f"a line over {MAX_REPORT_BYTES} bytes")
            except OSError as error:
                log.warning("gpsd at %s:%s: %s", *self.address, error)
            except Exception:  # noqa: BLE001 - the reader must outlive any one bad report
                # a thread that ended here left the car without a fix until a restart
                log.exception("gpsd reader: unexpected error; reconnecting")
            self._stop.wait(2.0)


# gpsd's longest reports (SKY with every satellite) are a few kilobytes.
MAX_REPORT_BYTES = 1 << 20


def _utc(value: object) -> datetime | None:
    """gpsd's ISO 8601 `time` ("2026-12-03T07:30:00.000Z") as an aware datetime; None where it
    is absent (no fix time yet) or not such a time."""
    if not isinstance(value, str):
        return None
    try:
        stamped = datetime.fromisoformat(value)
    except ValueError:
        return None
    return stamped if stamped.tzinfo is not None else None


def _number(value: object) -> float | None:
    """A JSON number as a float; None for anything else (gpsd leaves out what it lacks)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    return None
