"""How many spooled pings the agent sends in one upload, when the server refuses a batch whole.

The server answers a batch ping by ping (accepted, duplicate, rejected), but it can refuse a
request as a whole: 413 when the body is over its size limit (its own `max_body_bytes`, or a
proxy's in front of it), 422 when the body breaks the schema it runs (a server on a newer
contract), 409 when its database refuses rows that passed every check. Sent again unchanged,
such a batch is refused again, and since the spool sends oldest first, every later ping would
wait behind it until the spool's bound dropped them all.

So a refused batch is split: the next one is half its size, down to a single ping, which is then
given up as rejected (`vehicle_agent.uplink`). A body too large lowers the ceiling for the rest
of the run (the limit will not move by itself, and each refused body costs the car's uplink its
bytes); a refusal of the content does not: once the batches after the refused ping are taken,
they grow back, doubling, to the ceiling.

A batch that gets no answer within the call's timeout is halved too, the ceiling kept: on a
slow uplink (a weak cellular signal) a full batch of 1,000 pings (about 300 kB) takes longer to
send than the timeout allows, and sent again at the same size it timed out again; the backlog
only grew, and the server saw the same first pings resent while none after them arrived. A
smaller batch gets through, and the size grows back with each answered one.
"""

from __future__ import annotations

from contract.vehicles import MAX_PINGS_PER_BATCH


class PingBatchSize:
    """The size of the next upload batch: halved on a whole refusal, regrown on success."""

    def __init__(self, ceiling: int = MAX_PINGS_PER_BATCH) -> None:
        if ceiling < 1:
            raise ValueError(f"a batch ceiling must be at least 1 ping, got {ceiling}")
        self.ceiling = ceiling
        self.size = ceiling

    def refused(self, sent: int, *, too_large: bool) -> None:
        """A batch of `sent` pings was refused whole; `too_large` when for its size (413)."""
        half = max(1, sent // 2)
        if too_large:
            self.ceiling = min(self.ceiling, half)
        self.size = min(self.size, half)

    def timed_out(self, sent: int) -> None:
        """A batch of `sent` pings got no answer in time: the next is half as large (the link
        may be slow rather than the body too large, so the ceiling stays)."""
        self.size = min(self.size, max(1, sent // 2))

    def taken(self) -> None:
        """The server answered a batch ping by ping: the next may be twice as large."""
        self.size = min(self.ceiling, self.size * 2)
