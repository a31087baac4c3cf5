"""The demo's status line: what an operator would check, every few seconds, in the pages' units.

    13:02:05  pings 99.8/s · reporting 100/100 · cleared 98 · engaged 71 · plan 42 s old ·
              INRIX 212 s old · fleet step 0.10 s (2 % late) · verdict changes 98 (0 after
              clearance)

The counts come from GET /api/v1/fleet (the numbers the fleet page shows, with the same
readiness), the ping rate from the server's own /metrics counter, the ages from the warehouse,
the fleet's control step from the progress files its workers write. A car whose verdict changes
between two polls is counted (and named), so a run shows whether clearance held.
"""

from __future__ import annotations

import json
import re
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import httpx
from sqlalchemy import Engine, text

from app.fleet.readiness import describe_age

STATUS_PERIOD_S = 5.0
ACCEPTED_PINGS = re.compile(r'^smoothfleet_pings_total\{outcome="accepted"\} ([0-9.e+]+)$', re.M)


@dataclass(frozen=True)
class FleetStatus:
    """One poll's figures (None where the source did not answer)."""

    at: datetime
    pings_per_s: float | None
    vehicles: int
    reporting: int
    cleared: int
    engaged: int
    plan_age_s: float | None
    inrix_age_s: float | None
    step_interval_s: float | None
    late_share: float | None
    verdict_changes: int
    verdict_flips: int = 0


def status_line(status: FleetStatus, zone: Any = None) -> str:
    """The status as one line of text."""

    def age(seconds: float | None) -> str:
        return "none" if seconds is None else f"{describe_age(seconds)} old"

    pings = "—" if status.pings_per_s is None else f"{status.pings_per_s:.1f}/s"
    step = (
        "—"
        if status.step_interval_s is None
        else f"{status.step_interval_s:.2f} s ({100 * (status.late_share or 0.0):.0f} % late)"
    )
    return (
        f"{status.at.astimezone(zone).strftime('%H:%M:%S %Z')}  pings {pings} · reporting "
        f"{status.reporting}/{status.vehicles} · cleared {status.cleared} · engaged "
        f"{status.engaged} · plan {age(status.plan_age_s)} · INRIX {age(status.inrix_age_s)} · "
        f"fleet step {step} · verdict changes {status.verdict_changes} "
        f"({status.verdict_flips} after clearance)"
    )


@dataclass
class VerdictTracker:
    """Counts the changes of each car's verdict between polls; a car's first clearance (the
    fleet starting up) is not a flip, every change after it is."""

    verdicts: dict[str, str] = field(default_factory=dict)
    changes: list[tuple[datetime, str, str, str]] = field(default_factory=list)
    cleared_once: set[str] = field(default_factory=set)
    flips: int = 0

    def update(
        self, at: datetime, verdicts: Mapping[str, str]
    ) -> list[tuple[datetime, str, str, str]]:
        """Fold in one poll; returns the changes since the previous one (when, car, from, to)."""
        changed = []
        for vehicle_id, verdict in verdicts.items():
            before = self.verdicts.get(vehicle_id)
            if before is not None and before != verdict:
                changed.append((at, vehicle_id, before, verdict))
                self.flips += vehicle_id in self.cleared_once
            if verdict == "cleared":
                self.cleared_once.add(vehicle_id)
            self.verdicts[vehicle_id] = verdict
        self.changes.extend(changed)
        return changed


def read_progress(paths: Sequence[Path]) -> tuple[float | None, float | None]:
    """(mean seconds between control steps, share of late steps) over the workers' last window."""
    steps = late = 0
    wall = 0.0
    for path in paths:
        try:
            progress = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        steps += int(progress["window_steps"])
        late += int(progress["window_late_steps"])
        wall += float(progress["window_wall_s"])
    if steps == 0:
        return None, None
    return wall / steps, late / steps


class StatusMonitor:
    """Polls the server and the warehouse every STATUS_PERIOD_S and says the status line."""

    def __init__(
        self,
        base_url: str,
        token: str,
        engine: Engine,
        progress_paths: Sequence[Path],
        say: Callable[[str], None],
        zone: Any = None,
    ) -> None:
        self.http = httpx.Client(
            base_url=base_url, headers={"Authorization": f"Bearer {token}"}, timeout=10.0
        )
        self.engine = engine
        self.progress_paths = list(progress_paths)
        self.say = say
        self.zone = zone
        self.tracker = VerdictTracker()
        self.stop = threading.Event()
        self._pings: tuple[float, float] | None = None
        self._unanswered: str | None = None

    def _pings_per_s(self) -> float | None:
        try:
            metrics = self.http.get("/metrics").text
        except httpx.HTTPError:
            return None
        found = ACCEPTED_PINGS.search(metrics)
        if found is None:
            return None
        now, total = time.monotonic(), float(found.group(1))
        previous, self._pings = self._pings, (now, total)
        if previous is None or now <= previous[0]:
            return None
        return (total - previous[1]) / (now - previous[0])

    def poll(self) -> FleetStatus | None:
        """One poll (None when the fleet API did not answer)."""
        pings = self._pings_per_s()
        try:
            response = self.http.get("/api/v1/fleet")
        except httpx.HTTPError as error:
            self._no_answer(type(error).__name__)
            return None
        if response.status_code != 200:
            self._no_answer(f"HTTP {response.status_code} {response.text[:120]}")
            return None
        self._unanswered = None
        fleet: dict[str, Any] = response.json()
        at = datetime.now(UTC)
        changed = self.tracker.update(
            at, {v["vehicle_id"]: v["verdict"] for v in fleet["vehicles"]}
        )
        for _, vehicle_id, before, after in changed:
            self.say(f"  {vehicle_id}: {before} -> {after}")
        with self.engine.connect() as connection:
            plan_at, inrix_at = connection.execute(
                text(
                    "SELECT (SELECT max(published_at) FROM plan_run WHERE status = 'published'), "
                    "(SELECT max(measured_at) FROM fact_inrix_estimate)"
                )
            ).one()
        step, late = read_progress(self.progress_paths)
        counts = fleet["counts"]
        return FleetStatus(
            at=at,
            pings_per_s=pings,
            vehicles=counts["vehicles"],
            reporting=counts["reporting"],
            cleared=counts["cleared"],
            engaged=counts["engaged"],
            plan_age_s=None if plan_at is None else (at - plan_at).total_seconds(),
            inrix_age_s=None if inrix_at is None else (at - inrix_at).total_seconds(),
            step_interval_s=step,
            late_share=late,
            verdict_changes=len(self.tracker.changes),
            verdict_flips=self.tracker.flips,
        )

    def _no_answer(self, why: str) -> None:
        """Say once why the fleet API gave no status (the status line went silent: a run whose
        database another demo dropped said nothing for two minutes)."""
        if why != self._unanswered:
            self._unanswered = why
            self.say(f"status: GET /api/v1/fleet -> {why}")

    def run(self) -> None:
        """A status line every STATUS_PERIOD_S until stopped."""
        while not self.stop.wait(STATUS_PERIOD_S):
            status = self.poll()
            if status is not None:
                self.say(status_line(status, self.zone))
        self.http.close()
