"""The INRIX feed: the provider's JSON in mph stored in SI, unknown codes counted, nothing twice.

The input is the real recorded feed of ../shared/data/trajectories_with_inrix/ (per-minute
segment speeds), converted to the provider's format; columns 0, 1 and 20 of those files lie off
the seed corridor, so the feed reports 3 codes we do not know.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest
from sqlalchemy import Engine, text
from sqlalchemy.ext.asyncio import async_sessionmaker

from app.core.db import make_async_engine
from app.feeds.inrix import SegmentReading, SnapshotReadings, readings
from app.feeds.recording import read_recording, snapshots_from_drive
from app.feeds.service import StoreResult, store_readings
from tests.support.api import serving
from tests.support.servers import cli_env, run_cli
from tests.support.tokens import bearer, issue

MPH = 0.44704  # m/s


@pytest.fixture(scope="module")
def drive(shared_dir: Path) -> Path:
    """The 2021-03-15 drive with the INRIX feed of the same minutes."""
    return sorted((shared_dir / "data/trajectories_with_inrix").glob("2021-03-15*"))[0]


@pytest.fixture
def api(seeded_database_url: str) -> Iterator[httpx.Client]:
    # The recorded 2021 feed goes through the API here: a window of a century lets it in (the
    # window's own default is tested in tests/security/test_hostile_inputs.py).
    with serving(seeded_database_url, inrix_max_age_days=36500) as client:
        yield client


@pytest.fixture
def feed(seeded_engine: Engine) -> dict[str, str]:
    return bearer(issue(seeded_engine, "feed"))


def estimates(engine: Engine) -> dict[tuple[str, datetime], dict[str, Any]]:
    with engine.connect() as connection:
        rows = connection.execute(text("SELECT * FROM fact_inrix_estimate"))
        return {(row.xd_code, row.measured_at): dict(row._mapping) for row in rows}


def provider_response(*segments: dict[str, Any], **top: Any) -> dict[str, Any]:
    sets: dict[str, Any] = {"segments": list(segments)}
    if "timestamp" in top:
        sets["timestamp"] = top.pop("timestamp")
    return {"docType": "GetSegmentSpeed", **top, "result": {"segmentspeeds": [sets]}}


def test_the_recorded_feed_converts_to_provider_snapshots_in_mph(drive: Path) -> None:
    snapshots = snapshots_from_drive(drive)

    assert len(snapshots) == 13  # one per minute
    # trajectory.csv starts at unix 1615814550.7; speed.csv's first row is at -270.7 s.
    assert snapshots[0].recorded_at == datetime(2021, 3, 15, 13, 18, tzinfo=UTC)
    [speeds] = snapshots[0].response["result"]["segmentspeeds"]
    assert speeds["timestamp"] == "2021-03-15T13:18:00.000Z"
    by_code = {segment["code"]: segment for segment in speeds["segments"]}
    assert len(by_code) == 21
    # speed.csv column 2 reads 31.2928 m/s = 70 mph; column 11 reads 8.49376 m/s = 19 mph.
    assert by_code["SF-I24WB-02"]["speed"] == 70.0
    assert by_code["SF-I24WB-11"]["speed"] == 19.0
    assert by_code["SF-I24WB-11"]["c-Value"] == 90.0
    # Segment 2 spans 717.166 m (segments.json): 717.166 / 31.2928 = 22.918 s = 0.382 min.
    assert by_code["SF-I24WB-02"]["travelTimeMinutes"] == 0.382
    assert "travelTimeMinutes" not in by_code["SF-I24WB-20"]  # its end is unknown


def test_a_snapshot_is_stored_in_si_with_unknown_codes_counted_and_never_twice(
    api: httpx.Client, feed: dict[str, str], seeded_engine: Engine, drive: Path
) -> None:
    response = snapshots_from_drive(drive)[0].response

    answer = api.post("/api/v1/feeds/inrix", json=response, headers=feed)

    assert answer.status_code == 200
    body = answer.json()
    assert (body["accepted"], body["duplicates"], body["unknown_codes"]) == (18, 0, 3)
    assert body["unknown"] == ["SF-I24WB-00", "SF-I24WB-01", "SF-I24WB-20"]
    assert body["measured_at"] == ["2021-03-15T13:18:00Z"]
    stored = estimates(seeded_engine)
    assert len(stored) == 18
    row = stored[("SF-I24WB-02", datetime(2021, 3, 15, 13, 18, tzinfo=UTC))]
    assert row["corridor_id"] == "I-24-WB"
    assert row["speed_mps"] == pytest.approx(70 * MPH)  # 31.2928 m/s
    assert row["travel_time_s"] == pytest.approx(0.382 * 60)  # 22.92 s
    assert (row["score"], row["c_value"], row["is_closed"]) == (30, 100.0, False)
    slow = stored[("SF-I24WB-11", datetime(2021, 3, 15, 13, 18, tzinfo=UTC))]
    assert slow["speed_mps"] == pytest.approx(19 * MPH)  # the queue: 8.49 m/s

    again = api.post("/api/v1/feeds/inrix", json=response, headers=feed).json()
    assert (again["accepted"], again["duplicates"], again["unknown_codes"]) == (0, 18, 3)
    assert len(estimates(seeded_engine)) == 18


def test_every_provider_field_is_converted_and_closures_kept(
    api: httpx.Client, feed: dict[str, str], seeded_engine: Engine
) -> None:
    response = provider_response(
        {
            "code": "SF-I24WB-05",
            "type": "XDS",
            "speed": 45,
            "average": 50,
            "reference": 60,
            "travelTimeMinutes": 1.5,
            "score": 20,
            "c-Value": 72.5,
            "segmentClosed": False,
            "subSegments": [{"offset": 0.1, "speed": 40}],
        },
        {"code": "SF-I24WB-06", "type": "XDS", "score": 10, "segmentClosed": True},
        createdDate="2026-11-23T08:00:30Z",
        timestamp="2026-11-23T08:00:00Z",
    )
    answer = api.post("/api/v1/feeds/inrix", json=response, headers=feed)

    assert answer.json()["accepted"] == 2
    measured = datetime(2026, 11, 23, 8, 0, tzinfo=UTC)
    stored = estimates(seeded_engine)
    five = stored[("SF-I24WB-05", measured)]
    assert five["speed_mps"] == pytest.approx(45 * MPH)
    assert five["average_speed_mps"] == pytest.approx(50 * MPH)
    assert five["reference_speed_mps"] == pytest.approx(60 * MPH)
    assert five["travel_time_s"] == pytest.approx(90.0)
    assert (five["score"], five["c_value"]) == (20, 72.5)
    closed = stored[("SF-I24WB-06", measured)]
    assert closed["is_closed"] is True
    assert closed["speed_mps"] is None


def test_a_set_without_timestamp_takes_the_response_created_date(
    api: httpx.Client, feed: dict[str, str], seeded_engine: Engine
) -> None:
    response = provider_response(
        {"code": "SF-I24WB-07", "speed": 60}, createdDate="2026-11-23T08:01:00Z"
    )
    assert api.post("/api/v1/feeds/inrix", json=response, headers=feed).status_code == 200
    assert ("SF-I24WB-07", datetime(2026, 11, 23, 8, 1, tzinfo=UTC)) in estimates(seeded_engine)


@pytest.mark.parametrize(
    ("document", "expected"),
    [
        ({"segmentspeeds": []}, "result"),
        ({"result": {"segmentspeeds": {"timestamp": "2026-11-23T08:00:00Z"}}}, "segmentspeeds"),
    ],
    ids=["no-result", "no-list-of-sets"],
)
def test_a_body_that_is_not_a_segment_speed_response_is_422(
    api: httpx.Client,
    feed: dict[str, str],
    seeded_engine: Engine,
    document: dict[str, Any],
    expected: str,
) -> None:
    answer = api.post("/api/v1/feeds/inrix", json=document, headers=feed)
    assert answer.status_code == 422
    assert expected in str(answer.json()["detail"])
    assert estimates(seeded_engine) == {}


def test_a_set_with_no_time_or_no_segments_is_refused_on_its_own_and_the_others_kept(
    api: httpx.Client, feed: dict[str, str], seeded_engine: Engine
) -> None:
    """One broken segment set made the whole body a 422, and the good sets of that minute
    were lost with it (through `inrix poll`, fetched again and again until the period ended).
    An unreadable createdDate cost even sets with timestamps of their own."""
    good = {"timestamp": "2026-11-23T08:00:00Z", "segments": [{"code": "SF-I24WB-07", "speed": 60}]}
    response = {
        "createdDate": "yesterday-ish",
        "result": {
            "segmentspeeds": [
                good,
                {"timestamp": "garbage", "segments": [{"code": "SF-I24WB-08", "speed": 50}]},
                {"timestamp": "2026-11-23T08:00:00Z", "segments": {"code": "SF-I24WB-08"}},
                "not a set",
                {"segments": [{"code": "SF-I24WB-08", "speed": 50}]},
            ]
        },
    }
    answer = api.post("/api/v1/feeds/inrix", json=response, headers=feed)

    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["accepted"] == 1
    refused = {r["segment_set"]: r for r in body["refused"]}
    assert sorted(refused) == [1, 2, 3, 4]
    assert all(r["segment"] is None and r["code"] is None for r in refused.values())
    assert refused[1]["error"].startswith("timestamp: ")
    assert refused[2]["error"].startswith("segments: ")
    assert refused[4]["error"].startswith("no timestamp, and the response's createdDate: ")
    assert set(estimates(seeded_engine)) == {
        ("SF-I24WB-07", datetime(2026, 11, 23, 8, 0, tzinfo=UTC))
    }
    alone = provider_response({"code": "SF-I24WB-07", "speed": 60})
    answer = api.post("/api/v1/feeds/inrix", json=alone, headers=feed)
    assert answer.status_code == 200
    [only] = answer.json()["refused"]
    assert only == {
        "segment_set": 0,
        "segment": None,
        "code": None,
        "error": "no timestamp (and no createdDate)",
    }


def test_a_bad_segment_is_refused_on_its_own_and_the_snapshot_kept(
    api: httpx.Client, feed: dict[str, str], seeded_engine: Engine
) -> None:
    """One segment out of range, one without a code and a code read twice at one timestamp
    are refused with their place and reason; the other readings of the minute are stored."""
    response = provider_response(
        {"code": "SF-I24WB-05", "speed": 45, "c-Value": 100.5},
        {"code": "SF-I24WB-06", "speed": -3},
        {"speed": 50},
        "not a segment",
        {"code": "SF-I24WB-07", "speed": 50},
        {"code": "SF-I24WB-07", "speed": 20},
        {"code": "SF-I24WB-08", "speed": 55},
        timestamp="2026-11-23T08:00:00Z",
    )
    answer = api.post("/api/v1/feeds/inrix", json=response, headers=feed)

    assert answer.status_code == 200
    body = answer.json()
    assert (body["accepted"], body["duplicates"], body["unknown_codes"]) == (2, 0, 0)
    refused = {(r["segment"], r["code"]): r["error"] for r in body["refused"]}
    assert list(refused) == [
        (0, "SF-I24WB-05"),
        (1, "SF-I24WB-06"),
        (2, None),
        (3, None),
        (5, "SF-I24WB-07"),
    ]
    assert refused[0, "SF-I24WB-05"].startswith("c-Value: ")
    assert refused[1, "SF-I24WB-06"].startswith("speed: ")
    assert refused[2, None].startswith("code: ")
    assert "already read at this timestamp (segment 4, which is kept)" in refused[5, "SF-I24WB-07"]
    measured = datetime(2026, 11, 23, 8, 0, tzinfo=UTC)
    stored = estimates(seeded_engine)
    assert set(stored) == {("SF-I24WB-07", measured), ("SF-I24WB-08", measured)}
    assert stored[("SF-I24WB-07", measured)]["speed_mps"] == pytest.approx(50 * MPH)


def test_a_code_with_a_lone_surrogate_is_refused_unnamed_and_the_snapshot_kept(
    api: httpx.Client, feed: dict[str, str], seeded_engine: Engine
) -> None:
    """A code that has no UTF-8 (an escaped lone surrogate) is refused on its own, with its
    code left out of the answer (it could not be written: the answer was a 500 and the
    snapshot lost); the other reading is stored."""
    response = provider_response(
        {"code": "SF-I24WB-05\ud800", "speed": 45},
        {"code": "SF-I24WB-08", "speed": 55},
        timestamp="2026-11-23T08:00:00Z",
    )
    answer = api.post(
        "/api/v1/feeds/inrix",
        content=json.dumps(response).encode("ascii"),  # the surrogate as \ud800, as sent
        headers={**feed, "content-type": "application/json"},
    )

    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["accepted"] == 1
    (refusal,) = body["refused"]
    assert (refusal["segment"], refusal["code"]) == (0, None)
    assert refusal["error"].startswith("code: ")
    measured = datetime(2026, 11, 23, 8, 0, tzinfo=UTC)
    assert set(estimates(seeded_engine)) == {("SF-I24WB-08", measured)}


def test_a_code_read_again_at_one_instant_in_another_segment_set_is_refused(
    api: httpx.Client, feed: dict[str, str], seeded_engine: Engine
) -> None:
    """Two sets naming one instant in two zones: the second reading of a code (20 mph against
    50) was answered "already stored" and dropped without a word, where within one set it
    is refused with its place."""
    response = {
        "docType": "GetSegmentSpeed",
        "result": {
            "segmentspeeds": [
                {
                    "timestamp": "2026-11-23T08:00:00Z",
                    "segments": [{"code": "SF-I24WB-07", "speed": 50}],
                },
                {
                    "timestamp": "2026-11-23T02:00:00-06:00",
                    "segments": [
                        {"code": "SF-I24WB-07", "speed": 20},
                        {"code": "SF-I24WB-08", "speed": 55},
                    ],
                },
            ]
        },
    }
    answer = api.post("/api/v1/feeds/inrix", json=response, headers=feed)

    assert answer.status_code == 200
    body = answer.json()
    assert (body["accepted"], body["duplicates"]) == (2, 0)
    (refusal,) = body["refused"]
    assert (refusal["segment"], refusal["code"]) == (0, "SF-I24WB-07")
    assert (
        "already read at this timestamp (segment set 0, segment 0, which is kept)"
        in (refusal["error"])
    )
    stored = estimates(seeded_engine)
    measured = datetime(2026, 11, 23, 8, 0, tzinfo=UTC)
    assert stored[("SF-I24WB-07", measured)]["speed_mps"] == pytest.approx(50 * MPH)


def test_a_snapshot_larger_than_one_insert_is_stored_whole(
    seeded_engine: Engine, seeded_database_url: str
) -> None:
    """One INSERT takes at most 65,535 parameters (5,957 readings of 11): a snapshot of a
    larger network is stored in several, in one transaction."""
    codes = [f"SF-I24WB-{seq:02d}" for seq in range(2, 20)]
    moments = [datetime(2026, 11, 23, 8, 0, tzinfo=UTC) + timedelta(minutes=k) for k in range(400)]
    snapshot = SnapshotReadings(
        [
            SegmentReading(code, moment, 20.0, None, None, None, 30, None, False)
            for moment in moments
            for code in codes
        ],
        [],
    )
    assert len(snapshot.readings) == 7200

    async def store() -> StoreResult:
        engine = make_async_engine(seeded_database_url, pool_size=1)
        try:
            async with async_sessionmaker(engine)() as session, session.begin():
                return await store_readings(session, snapshot, datetime.now(UTC))
        finally:
            await engine.dispose()

    result = asyncio.run(store())
    assert (result.accepted, result.duplicates) == (7200, 0)
    assert len(estimates(seeded_engine)) == 7200


@pytest.mark.parametrize(("role", "status"), [("admin", 200), ("vehicle", 403), ("viewer", 403)])
def test_only_feed_and_admin_tokens_post_the_feed(
    api: httpx.Client, seeded_engine: Engine, drive: Path, role: str, status: int
) -> None:
    token = issue(seeded_engine, role, "SF-001" if role == "vehicle" else None)  # type: ignore[arg-type]
    response = snapshots_from_drive(drive)[1].response
    answer = api.post("/api/v1/feeds/inrix", json=response, headers=bearer(token))
    assert answer.status_code == status
    assert api.post("/api/v1/feeds/inrix", json=response).status_code == 401


def test_convert_then_replay_the_real_feed_from_the_command_line(
    seeded_database_url: str, seeded_engine: Engine, drive: Path, tmp_path: Path
) -> None:
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    recording = tmp_path / "inrix.jsonl"

    converted = run_cli("inrix", "convert", str(drive), str(recording), env=env)
    assert converted.returncode == 0, converted.stderr
    assert len(read_recording(recording)) == 13

    replayed = run_cli("inrix", "replay", str(recording), "--speed", "0", env=env)
    assert replayed.returncode == 0, replayed.stderr
    lines = replayed.stdout.splitlines()
    assert lines[0].startswith("2021-03-15T13:18:00+00:00: 18 stored, 0 already stored, 3 of")
    assert lines[-1] == f"replayed 13 snapshot(s) from {recording}"
    stored = estimates(seeded_engine)
    assert len(stored) == 13 * 18
    # The last minute's column 11 in speed.csv: 12.96416 m/s (29 mph).
    last = stored[("SF-I24WB-11", datetime(2021, 3, 15, 13, 30, tzinfo=UTC))]
    assert last["speed_mps"] == pytest.approx(12.96416, abs=1e-4)

    again = run_cli("inrix", "replay", str(recording), "--speed", "0", env=env)
    assert "0 stored, 18 already stored" in again.stdout
    assert len(estimates(seeded_engine)) == 13 * 18


def test_replay_can_stamp_an_old_recording_as_now(
    seeded_database_url: str, seeded_engine: Engine, drive: Path, tmp_path: Path
) -> None:
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    recording = tmp_path / "inrix.jsonl"
    run_cli("inrix", "convert", str(drive), str(recording), env=env)
    before = datetime.now(UTC)

    result = run_cli("inrix", "replay", str(recording), "--speed", "0", "--shift-to-now", env=env)

    assert result.returncode == 0, result.stderr
    stamps = sorted({measured for _, measured in estimates(seeded_engine)})
    assert len(stamps) == 13
    # stored at once: stamped as the last 12 minutes, none after the moment it was stored
    assert before <= stamps[-1] <= datetime.now(UTC)
    assert (stamps[-1] - stamps[0]).total_seconds() == pytest.approx(12 * 60)


def test_a_broken_recording_is_one_line_naming_the_line(
    seeded_database_url: str, tmp_path: Path
) -> None:
    recording = tmp_path / "broken.jsonl"
    recording.write_text('{"recorded_at": "2021-03-15T13:18:00Z", "response": {}}\n' + "not json\n")
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    result = run_cli("inrix", "replay", str(recording), env=env)
    assert result.returncode == 1
    assert result.stderr.strip().startswith("smoothfleet: error: broken.jsonl line 2:")
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_replayed_snapshot_stamped_in_the_future_is_skipped_naming_its_line(
    seeded_database_url: str, seeded_engine: Engine, drive: Path, tmp_path: Path
) -> None:
    """Replays and polls stored readings a year ahead (and one shifted to the year 4216): only
    the API refused a stamp in the future. The replay skips that snapshot, stores the rest (it
    stopped there until 2026-12-05, and a backfill lost every later minute) and fails."""
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    recording = tmp_path / "inrix.jsonl"
    run_cli("inrix", "convert", str(drive), str(recording), env=env)
    lines = recording.read_text().splitlines()
    ahead = (datetime.now(UTC) + timedelta(days=365)).strftime("%Y-%m-%dT%H:%M:%SZ")
    entry = json.loads(lines[1])
    entry["response"]["result"]["segmentspeeds"][0]["timestamp"] = ahead
    lines[1] = json.dumps(entry)
    recording.write_text("\n".join(lines) + "\n")

    result = run_cli("inrix", "replay", str(recording), "--speed", "0", env=env)

    assert result.returncode == 1
    assert "line 2: timestamp " in result.stderr
    assert "s in the future; nothing of this snapshot was stored" in result.stderr
    assert f"stored {len(lines) - 1} of {len(lines)} snapshot(s); 1 unusable" in result.stderr
    stored = {measured for _, measured in estimates(seeded_engine)}
    assert len(stored) == len(lines) - 1  # every snapshot but the one from the future
    assert max(stored) < datetime.now(UTC)


def test_a_recorded_answer_that_is_no_response_is_skipped_and_the_rest_replayed(
    seeded_database_url: str, seeded_engine: Engine, drive: Path, tmp_path: Path
) -> None:
    """`inrix poll --record` keeps every answer it fetched, an expired token's 200 included;
    the replay stopped at the first such line, and a backfill lost every later minute."""
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    recording = tmp_path / "odd.jsonl"
    run_cli("inrix", "convert", str(drive), str(recording), env=env)
    lines = recording.read_text().splitlines()
    expired = {"statusId": 43, "statusText": "Token expired", "result": None}
    entry = json.loads(lines[1])
    lines.insert(1, json.dumps({"recorded_at": entry["recorded_at"], "response": expired}))
    recording.write_text("\n".join(lines) + "\n")
    result = run_cli("inrix", "replay", str(recording), "--speed", "0", env=env)
    assert result.returncode == 1
    assert "line 2: not an INRIX segment-speed response: result" in result.stderr
    assert f"stored {len(lines) - 1} of {len(lines)} snapshot(s)" in result.stderr
    assert len({measured for _, measured in estimates(seeded_engine)}) == len(lines) - 1


def test_a_feed_folder_with_empty_cells_converts_leaving_them_out(tmp_path: Path) -> None:
    """An empty confidence cell made `inrix convert` stop with 'unexpected ValueError: cannot
    convert float NaN to integer', where `sim evaluate` read the same folder."""
    folder = tmp_path / "drive"
    folder.mkdir()
    (folder / "trajectory.csv").write_text("Time,Velocity\n1000.0,36.0\n1000.1,36.0\n")
    (folder / "segments.json").write_text("[0.0, 800.0]")
    (folder / "speed.csv").write_text("time,0,1\n-60.0,30.5,20.0\n0.0,29.0,\n")
    (folder / "confidence.csv").write_text("time,0,1\n-60.0,30,\n0.0,30,30\n")
    (folder / "cvalue.csv").write_text("time,0,1\n-60.0,90,50\n0.0,80,70\n")

    first, second = (
        snapshot.response["result"]["segmentspeeds"][0]["segments"]
        for snapshot in snapshots_from_drive(folder)
    )

    assert "score" not in first[1]  # the empty score cell
    assert first[1]["speed"] == pytest.approx(20.0 / MPH, abs=1e-3)
    assert [segment["code"] for segment in second] == ["SF-I24WB-00"]  # the empty speed cell


def test_a_numeric_xd_code_and_a_null_closure_flag_are_read_as_the_provider_means_them() -> None:
    """Both refused the segment: XD codes are digits, sent as a JSON integer they name the same
    segment; `"segmentClosed": null` says no more than an absent flag."""
    read = readings(
        provider_response(
            {"code": 449620170, "speed": 45, "segmentClosed": None},
            {"code": 4.5, "speed": 45},
            {"code": True, "speed": 45},
            timestamp="2026-11-23T08:00:00Z",
        )
    )
    assert [(r.xd_code, r.is_closed) for r in read.readings] == [("449620170", False)]
    assert [r.segment for r in read.refused] == [1, 2]


def test_a_minute_stored_late_keeps_the_latency_it_was_fetched_with(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    """The poller's backlog (a database outage) and a replay store minutes long after they
    were fetched: the latency analytics counted that delay as the provider's. A minute fetched
    180 s after its time and stored an hour later reads 180 s."""
    measured = datetime.now(UTC).replace(second=0, microsecond=0) - timedelta(hours=1)
    recording = tmp_path / "backlog.jsonl"
    response = provider_response(
        {"code": "SF-I24WB-05", "speed": 45},
        {"code": "SF-I24WB-06", "speed": 50},
        timestamp=measured.isoformat(),
    )
    fetched = measured + timedelta(seconds=180)
    recording.write_text(
        json.dumps({"recorded_at": fetched.isoformat(), "response": response}) + "\n"
    )
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    replayed = run_cli("inrix", "replay", str(recording), "--speed", "0", env=env)
    assert replayed.returncode == 0, replayed.stderr
    with seeded_engine.connect() as connection:
        latency, fetched_at, received_at = connection.execute(
            text(
                "SELECT v.latency_s, e.fetched_at, e.received_at FROM analytics.inrix_latency v "
                "JOIN fact_inrix_estimate e USING (corridor_id, measured_at) LIMIT 1"
            )
        ).one()
    assert latency == pytest.approx(180.0)
    assert fetched_at == fetched
    assert (received_at - measured).total_seconds() > 3500  # stored an hour later
