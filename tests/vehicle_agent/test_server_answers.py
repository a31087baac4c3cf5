"""What the agent makes of server answers that are not what the contract says, and of gpsd
reports that are not what gpsd documents: refused with a reason, never a crash or a lost row."""

from __future__ import annotations

import json
import socket
import threading
import time
from datetime import UTC, datetime
from typing import Any

import httpx
import pytest

from sim.emulator.rig import uniform_plan, vehicle_config
from vehicle_agent.agent import MAX_BACKOFF_S, Schedule
from vehicle_agent.gps import GpsdSource
from vehicle_agent.server import NewPlan, ServerClient, ServerTimeout, UnexpectedAnswer

PINGS = [{"vehicle_id": "SF-001", "ts": f"2026-12-02T10:00:0{i}Z"} for i in range(3)]


def client_answering(body: dict[str, Any]) -> ServerClient:
    def answer(request: httpx.Request) -> httpx.Response:
        return httpx.Response(200, json=body)

    http = httpx.Client(base_url="http://server.test", transport=httpx.MockTransport(answer))
    return ServerClient(http, "SF-001", "token")


@pytest.mark.parametrize(
    ("body", "reason"),
    [
        # an index beyond the batch: the agent looked it up and jammed its spool on IndexError
        ({"accepted": 2, "duplicates": 0, "rejected": [{"index": 5, "error": "x"}]}, "for a batch"),
        ({"accepted": 1, "duplicates": 0, "rejected": [{"index": 0, "error": "x"}] * 2}, "batch"),
        # an answer that accounts for fewer pings than were sent: the rest would be forgotten
        ({"accepted": 1, "duplicates": 0, "rejected": []}, "accounts for 1 of 3"),
        # counts that sum to the batch only with one below zero: no ping is answered for once
        ({"accepted": 4, "duplicates": -1, "rejected": []}, "unexpected answer"),
    ],
)
def test_a_ping_answer_that_does_not_account_for_the_batch_is_refused(
    body: dict[str, Any], reason: str
) -> None:
    with pytest.raises(UnexpectedAnswer, match=reason):
        client_answering(body).post_pings(PINGS)


def test_a_ping_answer_for_every_ping_is_taken() -> None:
    body = {"accepted": 1, "duplicates": 1, "rejected": [{"index": 2, "error": "lane"}]}
    assert client_answering(body).post_pings(PINGS).accepted == 1


def test_a_corridor_without_sub_segments_is_an_unexpected_answer() -> None:
    """The server sends one for a corridor whose sub-segments are not loaded yet."""
    with pytest.raises(UnexpectedAnswer, match="has no sub-segments"):
        client_answering({"lanes": 4, "segments": []}).corridor("I-24-WB")

    # an infinite lane count escaped as an OverflowError, and config and corridor were asked
    # again on every network pass
    def infinite_lanes(request: httpx.Request) -> httpx.Response:
        return httpx.Response(200, content=b'{"lanes": 1e400, "segments": []}')

    http = httpx.Client(
        base_url="http://server.test", transport=httpx.MockTransport(infinite_lanes)
    )
    with pytest.raises(UnexpectedAnswer, match="unusable geometry"):
        ServerClient(http, "SF-001", "token").corridor("I-24-WB")


@pytest.mark.parametrize(
    "call",
    [
        lambda client: client.config(),
        lambda client: client.policy("a" * 64),
        lambda client: client.plan(2, None),
        lambda client: client.post_pings(PINGS),
    ],
    ids=["config", "policy", "plan", "pings"],
)
def test_an_answer_that_cannot_be_decoded_is_an_unexpected_answer(call: Any) -> None:
    """A body that is not the Content-Encoding it names (a misbehaving proxy) raised httpx's
    DecodingError, which no caller expects: a policy download that met it left the car
    engaged on the policy assigned before, asking again on every network pass."""

    def answer(request: httpx.Request) -> httpx.Response:
        return httpx.Response(200, headers={"Content-Encoding": "gzip"}, content=b"not gzip")

    http = httpx.Client(base_url="http://server.test", transport=httpx.MockTransport(answer))
    with pytest.raises(UnexpectedAnswer, match="DecodingError"):
        call(ServerClient(http, "SF-001", "token"))


def gpsd(*reports: object) -> GpsdSource:
    source = GpsdSource(clock=lambda: 5.0)
    for report in reports:
        source.handle(json.dumps(report))
    return source


def test_a_sky_report_without_its_satellites_keeps_the_count() -> None:
    tpv = {"class": "TPV", "mode": 3, "lat": 36.0, "lon": -86.6}
    used = [{"PRN": n, "used": True} for n in range(9)]
    source = gpsd({"class": "SKY", "satellites": used}, {"class": "SKY", "hdop": 0.9}, tpv)
    fix = source.latest()
    assert fix is not None
    assert fix.satellites == 9
    assert gpsd({"class": "SKY", "uSat": 7}, tpv).latest().satellites == 7  # type: ignore[union-attr]


def test_gpsds_no_fix_report_ends_the_fix_at_once() -> None:
    """gpsd reports a lost fix as a TPV of mode 1 with no position; it was dropped, and the
    last 3D fix stayed current for 2 s more, the car driving on extrapolated from it."""
    fixed = {"class": "TPV", "mode": 3, "lat": 36.0, "lon": -86.6}
    lost = gpsd(fixed, {"class": "TPV", "mode": 1}).latest()
    assert lost is not None
    assert not lost.has_fix
    assert (lost.lat, lost.lon) == (36.0, -86.6)  # where it was last known, for the record
    regained = gpsd(fixed, {"class": "TPV", "mode": 1}, fixed).latest()
    assert regained is not None
    assert regained.has_fix
    assert gpsd({"class": "TPV", "mode": 1}).latest() is None  # no fix yet: still none


def test_a_fix_carries_the_receivers_time_where_gpsd_gives_one() -> None:
    tpv = {"class": "TPV", "mode": 3, "lat": 36.0, "lon": -86.6}
    timed = gpsd(tpv | {"time": "2026-12-03T07:30:00.250Z"}).latest()
    assert timed is not None
    assert timed.utc == datetime(2026, 12, 3, 7, 30, 0, 250000, tzinfo=UTC)
    # no time, or one that is no time with its zone: the fix stands, with no receiver time
    for stamp in (None, "soon", "2026-12-03T07:30:00"):
        fix = gpsd(tpv | {"time": stamp}).latest()
        assert fix is not None
        assert fix.utc is None


@pytest.mark.parametrize(
    "report",
    [
        [],
        {"class": "TPV", "mode": 3, "lat": None, "lon": -86.6},
        {"class": "TPV", "mode": None, "lat": 36.0, "lon": -86.6, "speed": "fast"},
        {"class": "SKY", "satellites": None},
    ],
    ids=["a list", "null lat", "null mode", "null satellites"],
)
def test_an_odd_gpsd_report_is_skipped_not_fatal(report: object) -> None:
    source = gpsd(report, {"class": "TPV", "mode": 3, "lat": 36.0, "lon": -86.6})
    fix = source.latest()
    assert fix is not None
    assert fix.lat == 36.0


@pytest.mark.parametrize(
    "line",
    [
        '{"class": "TPV", "mode": 1e999, "lat": 36.1, "lon": -86.6}',
        '{"class": "TPV", "mode": 3, "lat": ' + "9" * 400 + ', "lon": -86.6}',
        '{"class": "TPV", "mode": 3, "lat": ' + "9" * 5000 + ', "lon": -86.6}',
        "[" * 100_000,
        '{"class": "TPV", "mode": 3, "lat": NaN, "lon": -86.6}',
        '{"class": "TPV", "mode": 3, "lat": 91.0, "lon": -86.6}',
    ],
    ids=[
        "infinite mode",
        "400-digit lat",
        "5000-digit lat",
        "deep nesting",
        "NaN lat",
        "off the globe",
    ],
)
def test_a_gpsd_line_that_breaks_a_parser_is_skipped_and_no_fix(line: str) -> None:
    """Each ended the reader thread (an OverflowError, a ValueError from json, a
    RecursionError), leaving the car without a fix until a restart; a NaN latitude read as a
    fix no ping could be built from."""
    source = GpsdSource(clock=lambda: 5.0)
    source.handle(line)
    assert source.latest() is None
    source.handle('{"class": "TPV", "mode": 3, "lat": 36.0, "lon": -86.6}')
    fix = source.latest()
    assert fix is not None
    assert fix.lat == 36.0


def test_the_network_back_off_stops_counting_at_its_cap() -> None:
    """2 ** 1024 overflows a float: after 1,025 failures in a row (8.5 h at the 30 s cap) the
    back-off raised, and the failing job ran on every network pass."""
    schedule = Schedule()
    for _ in range(2000):
        schedule.failed(0.0, 1.0)
    assert schedule.next_s == MAX_BACKOFF_S
    schedule.done(0.0, 1.0)
    schedule.failed(0.0, 1.0)
    assert schedule.next_s == 1.0


@pytest.mark.parametrize("field", ["ping_period_s", "status_period_s", "plan_poll_s"])
@pytest.mark.parametrize("value", [1e300, "Infinity"])
def test_a_config_whose_period_would_stop_a_job_for_the_run_is_refused(
    field: str, value: object
) -> None:
    """A period is when the agent next does the job, set once: 1e300 stopped pings, status
    reports or plan polls until a restart, the corrected config notwithstanding. Such a config
    is an unexpected answer (the car keeps the one it has and asks again)."""
    body = vehicle_config("toyota_rav4", "microaccel").model_dump(mode="json")
    raw = json.dumps(body | {field: 0.0}).replace(f'"{field}": 0.0', f'"{field}": {value}')

    def answer(request: httpx.Request) -> httpx.Response:
        return httpx.Response(200, content=raw, headers={"content-type": "application/json"})

    http = httpx.Client(base_url="http://server.test", transport=httpx.MockTransport(answer))
    with pytest.raises(UnexpectedAnswer, match=field):
        ServerClient(http, "SF-001", "token").config()


def test_a_plan_answer_says_when_the_server_sent_it_by_its_own_clock() -> None:
    """Its Date dates the plan's age on arrival, which a car clock behind cannot take away."""
    plan = uniform_plan(25.0, published=datetime(2026, 12, 5, 12, 0, tzinfo=UTC))

    def answer(request: httpx.Request) -> httpx.Response:
        headers = {"Date": "Sat, 05 Dec 2026 12:02:30 GMT", "ETag": '"7"'}
        return httpx.Response(200, content=plan.model_dump_json(), headers=headers)

    http = httpx.Client(base_url="http://server.test", transport=httpx.MockTransport(answer))
    fetched = ServerClient(http, "SF-001", "token").plan(2, None)
    assert isinstance(fetched, NewPlan)
    assert fetched.served_at == datetime(2026, 12, 5, 12, 2, 30, tzinfo=UTC)

    def undated(request: httpx.Request) -> httpx.Response:
        return httpx.Response(200, content=plan.model_dump_json(), headers={"Date": "soon"})

    http = httpx.Client(base_url="http://server.test", transport=httpx.MockTransport(undated))
    fetched = ServerClient(http, "SF-001", "token").plan(2, None)
    assert isinstance(fetched, NewPlan)
    assert fetched.served_at is None


@pytest.mark.parametrize(
    ("encoding", "drip"),
    [
        (b"", b" " * 20),
        # a gzip header whose file name never ends: it decodes to nothing while it drips, so a
        # deadline read from the decoded body was never looked at
        (b"Content-Encoding: gzip\r\n", b"\x1f\x8b\x08\x08\x00\x00\x00\x00\x00\x03" + b"a" * 20),
    ],
    ids=["plain", "gzip-header"],
)
def test_an_answer_dripped_slower_than_its_deadline_is_a_timeout_at_the_deadline(
    encoding: bytes, drip: bytes
) -> None:
    """httpx's timeout bounds each read: a body dripped a byte every 0.2 s never meets a 1 s
    read timeout, and held the network thread for the whole body (19 s against 3 s in an
    audit). The answer's bytes as they come are read against a deadline of the timeout."""
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]

    def serve_drip() -> None:
        connection, _ = listener.accept()
        with connection:
            connection.recv(65536)
            connection.sendall(
                b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n"
                + encoding
                + f"Content-Length: {len(drip)}\r\n\r\n".encode()
            )
            for byte in drip:
                time.sleep(0.2)
                try:
                    connection.sendall(bytes([byte]))
                except OSError:
                    return  # the client gave up

    server = threading.Thread(target=serve_drip, daemon=True)
    server.start()
    with httpx.Client(base_url=f"http://127.0.0.1:{port}") as http:
        client = ServerClient(http, "SF-001", "t", 1.0)
        started = time.monotonic()
        with pytest.raises(ServerTimeout, match="the answer took over 1 s"):
            client.config()
        assert time.monotonic() - started < 2.0
    server.join(timeout=5)
    listener.close()


def test_a_new_period_counts_from_the_last_run_but_never_cuts_a_back_off_or_a_retry_after() -> None:
    """A schedule is re-based on the config's period now (Agent.network), from the last
    success; the delays a failure or the server's Retry-After set are not the period's."""
    schedule = Schedule()
    schedule.done(100.0, 600.0)
    schedule.rebase(5.0)
    assert schedule.next_s == 105.0
    schedule.rebase(60.0)
    assert schedule.next_s == 160.0
    schedule.failed(110.0, 60.0)
    schedule.rebase(5.0)
    assert schedule.next_s == 140.0  # MAX_BACKOFF_S after the failure
    schedule.done(200.0, 5.0)
    schedule.not_before(260.0)
    schedule.rebase(1.0)
    assert schedule.next_s == 260.0
