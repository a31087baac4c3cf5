"""A ping batch the server refuses as a whole is split until no ping blocks the ones behind it
(vehicle_agent/batching.py); the server over its body limit is in test_agent_server.py."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest

from sim.emulator.rig import Rig
from tests.support.cars import car_served_by
from vehicle_agent.batching import PingBatchSize
from vehicle_agent.policies import PolicyStore


@contextmanager
def car_answered_by(
    answer: Callable[[httpx.Request], httpx.Response], tmp_path: Path, dbc_cache: Path
) -> Iterator[Rig]:
    """SF-001 and its agent, whose server is `answer`."""
    transport = httpx.MockTransport(answer)
    with (
        httpx.Client(base_url="http://server.test", transport=transport) as http,
        car_served_by(http, "SF-001", "token", tmp_path, dbc_cache) as r,
    ):
        yield r


def test_a_refused_batch_halves_and_the_size_grows_back_to_its_ceiling() -> None:
    batch = PingBatchSize(1000)
    batch.refused(1000, too_large=False)
    assert (batch.size, batch.ceiling) == (500, 1000)
    batch.refused(500, too_large=False)
    batch.taken()
    batch.taken()
    assert batch.size == 1000
    batch.refused(1000, too_large=True)  # over a size limit: it will not move by itself
    batch.taken()
    assert (batch.size, batch.ceiling) == (500, 500)
    batch.refused(1, too_large=False)
    assert batch.size == 1
    with pytest.raises(ValueError, match="at least 1 ping"):
        PingBatchSize(0)


def test_a_batch_with_no_answer_in_time_halves_and_keeps_its_ceiling() -> None:
    batch = PingBatchSize(1000)
    batch.timed_out(1000)
    assert (batch.size, batch.ceiling) == (500, 1000)
    batch.timed_out(1)
    assert batch.size == 1
    batch.taken()
    assert batch.size == 2


def test_on_an_uplink_too_slow_for_a_full_batch_the_backlog_drains(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """A link that carries no more than 200 pings within the call's timeout: a 1,000-ping
    batch timed out at every try and was sent again whole, so the server saw the same first
    pings again and again and the backlog only grew."""
    stored: list[str] = []

    def slow_link(request: httpx.Request) -> httpx.Response:
        pings = json.loads(request.content)["pings"]
        if len(pings) > 200:
            raise httpx.WriteTimeout("the body did not go out in time", request=request)
        new = [ping["ts"] for ping in pings if ping["ts"] not in stored]
        stored.extend(new)
        return httpx.Response(
            200,
            json={"accepted": len(new), "duplicates": len(pings) - len(new), "rejected": []},
        )

    with car_answered_by(slow_link, tmp_path, dbc_cache) as r:
        r.run(1500.0)
        spooled = [ping["ts"] for _, ping in r.agent.spool.oldest(2000)]
        assert len(spooled) >= 1000
        for _ in range(20):
            r.agent.upload()
            if not r.agent.spool.backlog():
                break
        assert r.agent.spool.backlog() == 0
        assert stored[: len(spooled)] == spooled  # each once, in order


def test_a_ping_a_newer_server_refuses_whole_is_given_up_and_the_rest_arrive(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """A server whose schema no longer takes one of the spooled pings answers the batch 422.
    The agent sent that batch again at every back-off, so none of its pings, nor any later
    one, ever arrived."""
    stored: list[str] = []
    requests = 0
    refused_ts: list[str] = []

    def newer_server(request: httpx.Request) -> httpx.Response:
        nonlocal requests
        requests += 1
        pings = json.loads(request.content)["pings"]
        if any(ping["ts"] in refused_ts for ping in pings):
            return httpx.Response(422, json={"detail": "pings.3.lane: not a lane"})
        stored.extend(ping["ts"] for ping in pings)
        return httpx.Response(200, json={"accepted": len(pings), "duplicates": 0, "rejected": []})

    with car_answered_by(newer_server, tmp_path, dbc_cache) as r:
        r.run(40.0)
        spooled = [ping["ts"] for _, ping in r.agent.spool.oldest(100)]
        assert len(spooled) == 40
        refused_ts.append(spooled[7])
        for _ in range(10):
            r.agent.upload()
            if not r.agent.spool.backlog():
                break
        assert r.agent.spool.backlog() == 0
        # each once, in order, but for the newest ping, sent alone to tell a refusal of that
        # one ping from a server refusing every ping whole (it was taken: the refused one is
        # given up)
        assert stored == spooled[:7] + [spooled[-1]] + spooled[8:-1]
        assert r.agent.spool.counter("rejected") == 1
        assert r.agent.stats.pings_uploaded == 39
        assert requests < 40  # split by halves, not sent one by one
        # once past the refused ping, batches grow back
        r.run(40.0)
        sent = requests
        r.agent.upload()
        assert r.agent.spool.backlog() == 0
        assert requests - sent <= 3


def test_a_spool_that_cannot_be_written_backs_uploads_off(tmp_path: Path, dbc_cache: Path) -> None:
    """A spool error (a full or read-only card) left the upload before its schedule was
    updated: the next network pass, 0.2 s later, posted the same batch again, and so on."""

    def server(request: httpx.Request) -> httpx.Response:
        if request.url.path != "/api/v1/pings":
            return httpx.Response(503)  # config, plan, status: away, as they may be
        pings = json.loads(request.content)["pings"]
        return httpx.Response(200, json={"accepted": len(pings), "duplicates": 0, "rejected": []})

    with car_answered_by(server, tmp_path, dbc_cache) as r:
        r.run(5.0)
        # a card remounted read-only: the spool still reads, every write fails
        r.agent.spool._db.execute("PRAGMA query_only = ON")
        assert r.agent.upload() == 0
        assert r.agent.stats.spool_errors == 1
        r.clock.advance(0.2)  # the next network pass: the upload waits out its back-off
        r.agent.network()
        assert r.agent.stats.spool_errors == 1


def test_leftover_downloads_that_cannot_be_removed_do_not_stop_the_agent(tmp_path: Path) -> None:
    """Tidying the policy store raised out of the agent's start-up on a card remounted
    read-only (here a stale leftover that is a folder, which no one may unlink)."""
    store_dir = tmp_path / "policies"
    stale = store_dir / "tmpabc.part"
    stale.mkdir(parents=True)
    os.utime(stale, (time.time() - 2 * 86400, time.time() - 2 * 86400))
    store = PolicyStore(store_dir)
    assert stale.exists()
    assert not store.holds("a" * 64)


@pytest.mark.parametrize("status", [409, 413, 422])
def test_a_server_that_refuses_every_ping_whole_empties_no_spool(
    status: int, tmp_path: Path, dbc_cache: Path
) -> None:
    """Each batch refused whole was halved down to one ping, which was given up: a server (or
    a proxy) refusing every body emptied the spool at five pings a second, counted only as
    "rejected". The newest ping sent alone tells a refusal of everything from one of a ping."""

    def refusing(request: httpx.Request) -> httpx.Response:
        return httpx.Response(status, json={"detail": "not today"})

    with car_answered_by(refusing, tmp_path, dbc_cache) as r:
        r.run(30.0)
        spooled = r.agent.spool.backlog()
        assert spooled >= 25
        for _ in range(40):
            r.agent.upload()
        assert r.agent.spool.backlog() == spooled
        assert r.agent.spool.counter("rejected") == 0


def test_an_upload_sends_no_new_batch_once_the_agent_stops(tmp_path: Path, dbc_cache: Path) -> None:
    """The stop waits for the answer to the batch in flight (`Agent.shutdown`), not for the
    rest of the call's batches."""
    batches: list[int] = []

    def server(request: httpx.Request) -> httpx.Response:
        pings = json.loads(request.content)["pings"]
        batches.append(len(pings))
        return httpx.Response(200, json={"accepted": len(pings), "duplicates": 0, "rejected": []})

    with car_answered_by(server, tmp_path, dbc_cache) as r:
        r.run(30.0)
        r.agent.uplink.batch = PingBatchSize(10)
        assert r.agent.server is not None
        outcome = r.agent.uplink.upload(r.agent.server, stopping=lambda: bool(batches))
        assert (batches, outcome.uploaded, r.agent.spool.backlog()) == ([10], 10, 20)
