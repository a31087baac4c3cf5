"""The spooled pings to the server: oldest first, in batches, until the spool is empty or the
server cannot take more.

Each batch the server answers ping by ping leaves the spool, but for the pings it refused for
now (`Rejection.retryable`: its clock or roster behind) that are young enough to send again.
A batch refused whole is split (`vehicle_agent.batching`), and a lone ping refused whole is
given up, so that no ping blocks the ones behind it, once the newest ping sent alone is taken:
a server that refuses every ping whole would otherwise empty the spool, one ping at a time.
The agent decides what an outcome means for its schedule and its counters (`Agent.upload`);
this module only speaks the protocol.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from contract.vehicles import PingAnswer, Rejection
from vehicle_agent.batching import PingBatchSize
from vehicle_agent.server import RequestRefused, ServerClient, ServerError, ServerTimeout
from vehicle_agent.spool import PingSpool

log = logging.getLogger(__name__)

# Upload at most this many batches per call, so status and plan polls stay timely.
MAX_BATCHES_PER_CALL = 5
# A ping the server refused for now (its clock or roster behind, `Rejection.retryable`) is sent
# again for this long after its own time, a day's deployment: long enough for an operator to
# mend the server's clock or add the car to the roster before it is given up.
RETRYABLE_PING_KEEP_S = 12 * 3600.0
# A ping the server refused for now that is stamped more than this ahead of the car's own
# clock (s) was stamped by a clock that ran ahead (a glitch since set right), not refused by
# a server clock behind: it is given up. Kept, it stayed spooled until RETRYABLE_PING_KEEP_S
# past its own time (a day and a half for one stamped a day ahead, for ever for a year), sent
# with every upload, which then backed off. Well above a clock step of NTP's or a GPS
# receiver's lag, and below the server's default window for a ping ahead
# (SMOOTHFLEET_PING_MAX_FUTURE_S, 300 s): a ping such a server refuses is further ahead still.
STAMPED_AHEAD_GIVE_UP_S = 60.0

SpoolRows = Sequence[tuple[int, dict[str, Any]]]


@dataclass
class UploadOutcome:
    """What one upload did: pings the server answered for (they left the spool), lone pings
    it refused whole (given up: they left the spool as rejected), pings kept to send again,
    pings given up as stamped ahead of the car's clock (among those answered for), the errors
    met on the way, and whether it ended on its own (the spool drained, or the call's batches
    sent) rather than stopped by the server (a failure, or pings it cannot take yet)."""

    uploaded: int = 0
    given_up: int = 0
    held_back: int = 0
    stamped_ahead: int = 0
    errors: list[ServerError] = field(default_factory=list)
    completed: bool = True


def ping_age_s(ts: object, now: datetime) -> float:
    """Seconds from a spooled ping's `ts` to `now`; infinite for one that does not read as a
    time with its zone (the spool holds only what the contract built, so never in practice)."""
    try:
        stamped = datetime.fromisoformat(str(ts))
        return (now - stamped).total_seconds()
    except (ValueError, TypeError):
        return math.inf


class PingUplink:
    """Sends a spool's pings; holds the size of the next batch across calls."""

    def __init__(self, spool: PingSpool, wall_clock: Callable[[], datetime]) -> None:
        self.spool = spool
        self.wall_clock = wall_clock
        self.batch = PingBatchSize()

    def upload(self, server: ServerClient, stopping: Callable[[], bool]) -> UploadOutcome:
        """Up to MAX_BATCHES_PER_CALL batches, oldest pings first; no new batch once
        `stopping()` says the agent stops, which waits only for the batch in flight."""
        outcome = UploadOutcome()
        for _ in range(MAX_BATCHES_PER_CALL):
            if stopping():
                break
            batch_size = self.batch.size
            rows = self.spool.oldest(batch_size)
            if not rows:
                break
            try:
                answer = server.post_pings([ping for _, ping in rows])
            except RequestRefused as error:
                outcome.errors.append(error)
                if len(rows) > 1:  # the next batch is half as large
                    self.batch.refused(len(rows), too_large=error.too_large)
                    continue
                if self._refused_for_itself(server, rows[0], outcome):
                    continue
                outcome.completed = False
                return outcome
            except ServerError as error:
                if isinstance(error, ServerTimeout):
                    self.batch.timed_out(len(rows))
                outcome.errors.append(error)
                outcome.completed = False
                return outcome
            self.batch.taken()
            if self._settle(rows, answer, outcome):
                # the server cannot take them yet: try again later, backing off, not in a loop
                outcome.completed = False
                return outcome
            if len(rows) < batch_size:
                break
        return outcome

    def _settle(self, rows: SpoolRows, answer: PingAnswer, outcome: UploadOutcome) -> bool:
        """The answered pings leave the spool but those refused for now; whether any stay."""
        kept = self._held_back(rows, answer.rejected, outcome)
        gone = [row_id for row_id, _ in rows if row_id not in kept]
        self.spool.remove(gone, rejected=len(answer.rejected) - len(kept))
        outcome.uploaded += len(gone)
        outcome.held_back += len(kept)
        return bool(kept)

    def _refused_for_itself(
        self, server: ServerClient, row: tuple[int, dict[str, Any]], outcome: UploadOutcome
    ) -> bool:
        """Whether a lone ping refused whole was refused for itself, and so given up (a ping a
        newer server cannot read must not block the ones behind it), rather than by a server
        that refuses any ping whole (a proxy's 413 for every body, a schema the agent does not
        speak): then every ping would be given up in turn, the spool emptied at five a second.
        The newest ping spooled, sent alone, tells: taken, the lone one leaves the spool as
        rejected; refused as well, or no other ping to ask with, both stay and uploads back
        off."""
        row_id, ping = row
        newest = self.spool.newest()
        if newest is None or newest[0] == row_id:
            return False
        try:
            answer = server.post_pings([newest[1]])
        except ServerError as error:
            if isinstance(error, RequestRefused):
                log.warning(
                    "server refuses pings whole (%s): the spool kept, uploads back off", error
                )
            outcome.errors.append(error)
            return False
        self._settle([newest], answer, outcome)
        log.warning("server refused ping %s on its own: given up", ping.get("ts"))
        self.spool.remove([row_id], rejected=1)
        outcome.given_up += 1
        return True

    def _held_back(
        self, rows: SpoolRows, rejected: Sequence[Rejection], outcome: UploadOutcome
    ) -> set[int]:
        """The spool rows of the pings refused for now and young enough to send again; a
        final refusal, a ping older than RETRYABLE_PING_KEEP_S, or one stamped more than
        STAMPED_AHEAD_GIVE_UP_S ahead of the car's clock (counted in the outcome) leaves the
        spool."""
        now = self.wall_clock()
        kept: list[tuple[int, object, str]] = []
        ahead: list[tuple[float, object, str]] = []
        for rejection in rejected:
            row_id, ping = rows[rejection.index]
            ts = ping.get("ts")
            age_s = ping_age_s(ts, now)
            if rejection.retryable and -age_s > STAMPED_AHEAD_GIVE_UP_S:
                ahead.append((-age_s, ts, rejection.error))
            elif rejection.retryable and age_s <= RETRYABLE_PING_KEEP_S:
                kept.append((row_id, ts, rejection.error))
            else:
                log.warning("server rejected ping %s: %s", ts, rejection.error)
        if ahead:
            # one line a batch: a clock that ran ahead for a minute stamped sixty of them
            ahead_s, ts, error = max(ahead, key=lambda stamped: stamped[0])
            log.warning(
                "gave up %d pings the server refused, stamped up to %.0f s ahead of the car's "
                "clock (%s: %s): a clock that ran ahead stamped them",
                len(ahead),
                ahead_s,
                ts,
                error,
            )
            outcome.stamped_ahead += len(ahead)
        if kept:
            # one line a retry, not one a ping: a server clock behind refuses every ping, again
            # every back-off, and each line lands on the car's SD card
            _, ts, error = kept[0]
            log.warning("server refused %d pings for now (%s: %s): kept", len(kept), ts, error)
        return {row_id for row_id, _, _ in kept}
