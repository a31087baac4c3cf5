"""Policies as versioned artefacts on the real server: upload, idempotence, mismatches, download
by a vehicle, assignments naming a policy (docs/interfaces.md, "Policies")."""

from __future__ import annotations

import hashlib
import json
import subprocess
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest
from sqlalchemy import Engine, text

from app.core.config import Settings
from app.core.db import session_scope
from app.policies.service import ManifestConflict, assign_shipped_policies
from app.seed import seed
from smoothfleet.cli.common import CliError
from smoothfleet.cli.demo import _demo_on
from tests.support.fleet import drive, post_pings
from tests.support.policies import acc_policy_bytes, accel_policy_bytes
from tests.support.servers import cli_env, live_server, run_cli
from tests.support.tokens import bearer, issue
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

ACC_FILE = BUNDLED_POLICIES / "rl_acc.npz"
ACCEL_FILE = BUNDLED_POLICIES / "rl_accel.npz"
ACC_SHA256 = hashlib.sha256(ACC_FILE.read_bytes()).hexdigest()
ACCEL_SHA256 = hashlib.sha256(ACCEL_FILE.read_bytes()).hexdigest()
# What a seeded server holds before any upload: the shipped rl_accel its RAV4s run (app/seed.py).
SEEDED = {ACCEL_SHA256}


def manifest_of(policy: Path) -> dict[str, Any]:
    document: dict[str, Any] = json.loads(policy.with_suffix(".json").read_text())
    return document


class Api:
    """A client on the live server and one token per role."""

    def __init__(self, client: httpx.Client, engine: Engine) -> None:
        self.client = client
        self.engine = engine
        self.tokens = {
            role: issue(engine, role)  # type: ignore[arg-type]
            for role in ("viewer", "operator", "admin", "feed")
        }
        self.tokens["vehicle"] = issue(engine, "vehicle", "SF-001")

    def upload(
        self,
        content: bytes,
        manifest: dict[str, Any] | bytes,
        role: str = "operator",
        **form: str,
    ) -> httpx.Response:
        document = manifest if isinstance(manifest, bytes) else json.dumps(manifest).encode()
        return self.client.post(
            "/api/v1/policies",
            files={
                "policy": ("policy.npz", content, "application/octet-stream"),
                "manifest": ("policy.json", document, "application/json"),
            },
            data=form,
            headers=bearer(self.tokens[role]),
        )

    def get(self, path: str, role: str = "viewer") -> httpx.Response:
        return self.client.get(path, headers=bearer(self.tokens[role]))

    def assign(self, vehicle_id: str, controller: dict[str, Any]) -> httpx.Response:
        body = {"lane": 2, "route": "A", "controller": controller}
        return self.client.put(
            f"/api/v1/vehicles/{vehicle_id}/assignment",
            json=body,
            headers=bearer(self.tokens["operator"]),
        )


@pytest.fixture
def api(seeded_database_url: str, seeded_engine: Engine) -> Iterator[Api]:
    with live_server(seeded_database_url) as base, httpx.Client(base_url=base, timeout=30) as c:
        yield Api(c, seeded_engine)


def held_policies(engine: Engine) -> set[str]:
    """The sha256 of every policy the server holds."""
    with engine.connect() as connection:
        return set(connection.scalars(text("SELECT policy_sha256 FROM dim_policy")))


def rejected(response: httpx.Response, status: int = 422) -> tuple[list[str], str]:
    assert response.status_code == status, response.text
    (error,) = response.json()["detail"]
    return error["loc"], error["msg"]


def test_an_upload_is_stored_by_its_sha256_and_a_vehicle_downloads_the_same_bytes(
    api: Api,
) -> None:
    content = ACC_FILE.read_bytes()

    first = api.upload(content, manifest_of(ACC_FILE))

    assert first.status_code == 201, first.text
    stored = first.json()
    assert (stored["sha256"], stored["controller"], stored["created"]) == (
        ACC_SHA256,
        "rl_acc",
        True,
    )
    assert stored["size_bytes"] == len(content)
    assert stored["seed"] == manifest_of(ACC_FILE)["seed"]
    download = api.get(f"/api/v1/policies/{ACC_SHA256}", role="vehicle")
    assert download.status_code == 200
    assert download.content == content
    assert download.headers["content-type"] == "application/octet-stream"
    assert download.headers["etag"] == f'"{ACC_SHA256}"'
    manifest = api.get(f"/api/v1/policies/{ACC_SHA256}/manifest", role="vehicle")
    assert manifest.json() == manifest_of(ACC_FILE)
    listed = api.get("/api/v1/policies").json()
    assert [policy["sha256"] for policy in listed] == [ACC_SHA256, *SEEDED]  # newest first


def test_uploading_the_same_file_twice_stores_it_once(api: Api) -> None:
    content = ACC_FILE.read_bytes()
    first = api.upload(content, manifest_of(ACC_FILE))

    again = api.upload(content, manifest_of(ACC_FILE), role="admin")

    assert again.status_code == 200, again.text
    assert again.json()["created"] is False
    # the first upload's record stands
    assert again.json()["uploaded_by"] == first.json()["uploaded_by"]
    assert held_policies(api.engine) == {ACC_SHA256, *SEEDED}


def test_the_same_manifest_again_is_no_conflict_whatever_jsonb_made_of_its_numbers(
    api: Api,
) -> None:
    content = ACC_FILE.read_bytes()
    # JSONB keeps 1e23 as the exact decimal 10**23, which reads back as an int != the float
    manifest = {**manifest_of(ACC_FILE), "scale": 1e23, "steps": [1e23, 0.1, 3]}
    assert api.upload(content, manifest).status_code == 201

    again = api.upload(content, manifest)

    assert again.status_code == 200, again.text
    assert again.json()["created"] is False


def test_the_same_file_with_another_manifest_is_a_conflict(api: Api) -> None:
    content = ACC_FILE.read_bytes()
    assert api.upload(content, manifest_of(ACC_FILE)).status_code == 201

    other = {**manifest_of(ACC_FILE), "seed": 99}
    response = api.upload(content, other)

    assert response.status_code == 409
    assert "another manifest" in response.json()["detail"]
    stored = api.get(f"/api/v1/policies/{ACC_SHA256}/manifest").json()
    assert stored["seed"] == manifest_of(ACC_FILE)["seed"]


def test_a_manifest_naming_another_hash_is_refused(api: Api) -> None:
    manifest = {**manifest_of(ACC_FILE), "sha256": ACCEL_SHA256}

    loc, msg = rejected(api.upload(ACC_FILE.read_bytes(), manifest))

    assert loc == ["body", "manifest", "sha256"]
    assert ACCEL_SHA256 in msg
    assert ACC_SHA256 in msg
    assert held_policies(api.engine) == SEEDED


def test_a_manifest_nested_too_deeply_to_read_is_refused_not_a_server_error(api: Api) -> None:
    deep = b"[" * 200_000 + b"]" * 200_000  # under the body limit; json.loads recurses out

    loc, msg = rejected(api.upload(ACC_FILE.read_bytes(), deep))

    assert loc == ["body", "manifest"]
    assert "nested too deeply" in msg
    assert held_policies(api.engine) == SEEDED


def test_a_manifest_with_nan_is_refused_naming_it(api: Api) -> None:
    """Python writes an unmeasured KPI as NaN, which is no JSON: the upload ended in a database
    error naming no field (policy audit)."""
    manifest = json.dumps({**manifest_of(ACC_FILE), "kpi": float("nan")}).encode()

    loc, msg = rejected(api.upload(ACC_FILE.read_bytes(), manifest))

    assert loc == ["body", "manifest"]
    assert msg == (
        "NaN is no JSON number and cannot be stored (write null for a figure that was not measured)"
    )
    assert held_policies(api.engine) == SEEDED


@pytest.mark.parametrize(
    ("value", "loc", "reason"),
    [
        ("1e400", ["body", "manifest"], "the number 1e400 is beyond a float's range"),
        (
            "1" * 5000,
            ["body", "manifest"],
            "the number 111111111111... (5000 characters) is beyond a float's range",
        ),
        (
            str(10**400),
            ["body", "manifest"],
            "the number 100000000000... (401 characters) is beyond a float's range",
        ),
        ('"a\\u0000b"', ["body", "manifest", "kpi"], "text must not contain the NUL character"),
        ('["ok", "a\\ud800"]', ["body", "manifest", "kpi", "1"], "a lone UTF-16 surrogate"),
    ],
    ids=["1e400", "5000-digits", "401-digits", "nul", "surrogate"],
)
def test_a_manifest_value_postgresql_or_a_float_cannot_hold_is_refused_naming_it(
    api: Api, value: str, loc: list[str], reason: str
) -> None:
    """Each was a 500 (audit): Python's integer-length limit in the reader, a float overflow
    when a re-upload compared the manifests, PostgreSQL's JSON refusing the text."""
    document = json.dumps(manifest_of(ACC_FILE))[:-1] + f', "kpi": {value}}}'

    found_loc, msg = rejected(api.upload(ACC_FILE.read_bytes(), document.encode()))

    assert found_loc == loc
    assert reason in msg
    assert held_policies(api.engine) == SEEDED


def test_a_corrupted_file_is_refused_by_its_hash(api: Api) -> None:
    content = bytearray(ACC_FILE.read_bytes())
    content[len(content) // 2] ^= 0xFF

    loc, _ = rejected(api.upload(bytes(content), manifest_of(ACC_FILE)))

    assert loc == ["body", "manifest", "sha256"]


def test_a_file_that_is_not_a_policy_of_the_named_controller_is_refused(api: Api) -> None:
    accel = ACCEL_FILE.read_bytes()
    # the hash is right, but the manifest calls the accel policy an acc one
    as_acc = {**manifest_of(ACCEL_FILE), "actuation": "acc"}
    loc, msg = rejected(api.upload(accel, as_acc))
    assert loc == ["body", "policy"]
    assert "actuation accel, not acc" in msg

    garbage = b"not a policy at all"
    loc, msg = rejected(
        api.upload(garbage, {"sha256": hashlib.sha256(garbage).hexdigest(), "actuation": "acc"})
    )
    assert loc == ["body", "policy"]
    assert "not a policy file" in msg

    loc, msg = rejected(api.upload(accel, manifest_of(ACCEL_FILE), controller="rl_acc"))
    assert loc == ["body", "controller"]
    assert "rl_accel" in msg
    # a controller that is none names the ones there are (it said "an accel policy, not nope")
    loc, msg = rejected(api.upload(accel, manifest_of(ACCEL_FILE), controller="nope"))
    assert loc == ["body", "controller"]
    assert msg.endswith("'nope' is no RL controller: one of rl_acc, rl_accel")

    loc, msg = rejected(api.upload(accel, b"{not json"))
    assert loc == ["body", "manifest"]

    # acc policies of earlier speed actions: the cars would read their outputs wrongly
    for speed_action, why in (
        (None, "change from the last second's mean speed"),
        ("around_plan", "speed action 'around_plan', which"),
    ):
        content = acc_policy_bytes(speed_action)
        loc, msg = rejected(
            api.upload(content, {"sha256": hashlib.sha256(content).hexdigest(), "actuation": "acc"})
        )
        assert loc == ["body", "policy"]
        assert why in msg
    # an accel action this agent does not know
    content = accel_policy_bytes("time_gap_only")
    loc, msg = rejected(
        api.upload(content, {"sha256": hashlib.sha256(content).hexdigest(), "actuation": "accel"})
    )
    assert loc == ["body", "policy"]
    assert "accel action 'time_gap_only'" in msg
    # an observation this agent does not build
    content = accel_policy_bytes(accel_observation="lidar")
    loc, msg = rejected(
        api.upload(content, {"sha256": hashlib.sha256(content).hexdigest(), "actuation": "accel"})
    )
    assert loc == ["body", "policy"]
    assert "observation 'lidar', which this agent does not build" in msg
    assert held_policies(api.engine) == SEEDED


def test_an_accel_policy_reading_the_commanded_accel_is_stored(api: Api) -> None:
    content = accel_policy_bytes(accel_observation="commanded_accel")
    digest = hashlib.sha256(content).hexdigest()
    response = api.upload(content, {"sha256": digest, "actuation": "accel"})
    assert response.status_code == 201, response.text
    assert api.get(f"/api/v1/policies/{digest}", role="vehicle").content == content


def test_who_may_upload_and_download(api: Api) -> None:
    content = ACC_FILE.read_bytes()
    viewer = api.upload(content, manifest_of(ACC_FILE), role="viewer")
    assert viewer.status_code == 403
    assert viewer.json()["detail"].startswith("a viewer token may not do this")
    assert api.upload(content, manifest_of(ACC_FILE), role="vehicle").status_code == 403
    assert api.upload(content, manifest_of(ACC_FILE)).status_code == 201
    assert api.get(f"/api/v1/policies/{ACC_SHA256}", role="feed").status_code == 403
    assert api.client.get(f"/api/v1/policies/{ACC_SHA256}").status_code == 401
    assert api.get("/api/v1/policies", role="vehicle").status_code == 403
    missing = api.get(f"/api/v1/policies/{'0' * 64}", role="vehicle")
    assert missing.status_code == 404
    assert "no policy" in missing.json()["detail"]


def test_an_assignment_names_a_stored_policy_and_the_car_reads_it_in_its_config(
    api: Api,
) -> None:
    assert api.upload(ACC_FILE.read_bytes(), manifest_of(ACC_FILE)).status_code == 201

    response = api.assign("SF-001", {"name": "rl_acc", "params": {"policy_sha256": ACC_SHA256}})

    assert response.status_code == 200, response.text
    config = api.get("/api/v1/vehicles/SF-001/config", role="vehicle").json()
    assert config["controller"] == {"name": "rl_acc", "params": {"policy_sha256": ACC_SHA256}}


def test_the_change_log_says_which_policy_was_assigned(api: Api) -> None:
    """Swapping a car between two policies left two identical change rows: who put which
    policy on which car, and when, could not be told (policy audit)."""
    assert api.upload(ACC_FILE.read_bytes(), manifest_of(ACC_FILE)).status_code == 201
    for controller in (
        {"name": "rl_acc", "params": {"policy_sha256": ACC_SHA256}},
        {"name": "simple", "params": {}},
    ):
        assert api.assign("SF-001", controller).status_code == 200
    with api.engine.connect() as connection:
        rows = connection.execute(
            text(
                "SELECT controller_name, controller_params FROM fact_vehicle_change "
                "WHERE vehicle_id = 'SF-001' ORDER BY config_version"
            )
        ).all()
    assert [tuple(row) for row in rows] == [
        ("rl_acc", {"policy_sha256": ACC_SHA256}),
        ("simple", {}),
    ]


def test_an_assignment_naming_a_policy_the_server_lacks_is_refused(api: Api) -> None:
    before = api.get("/api/v1/vehicles/SF-001/config", role="vehicle").json()

    # a well-formed hash the server does not hold: the request is valid, the state conflicts
    loc, msg = rejected(
        api.assign("SF-001", {"name": "rl_acc", "params": {"policy_sha256": ACC_SHA256}}), 409
    )

    assert loc == ["body", "controller", "params", "policy_sha256"]
    assert "no policy" in msg
    assert "upload it first" in msg
    assert api.get("/api/v1/vehicles/SF-001/config", role="vehicle").json() == before
    # a stored policy of the other controller (the seed stored rl_accel) is refused too
    loc, msg = rejected(
        api.assign("SF-001", {"name": "rl_acc", "params": {"policy_sha256": ACCEL_SHA256}}), 409
    )
    assert "is a rl_accel policy, not rl_acc" in msg
    loc, msg = rejected(
        api.assign("SF-001", {"name": "rl_acc", "params": {"policy_sha256": "ABC"}})
    )
    assert loc == ["body", "controller", "params", "policy_sha256"]


def test_the_command_line_uploads_once_and_refuses_a_mismatch(
    seeded_database_url: str, tmp_path: Path
) -> None:
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)

    first = run_cli("policy", "upload", str(ACC_FILE), env=env)
    again = run_cli("policy", "upload", str(ACC_FILE), "--controller", "rl_acc", env=env)

    assert first.returncode == 0, first.stderr
    assert f"rl_acc policy {ACC_SHA256} stored" in first.stdout
    assert again.returncode == 0, again.stderr
    assert "already stored" in again.stdout
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({**manifest_of(ACC_FILE), "sha256": ACCEL_SHA256}))
    refused = run_cli("policy", "upload", str(ACC_FILE), "--manifest", str(wrong), env=env)
    assert refused.returncode == 1
    assert refused.stderr.startswith("smoothfleet: error: policy:")
    assert "the file's sha256 is" in refused.stderr
    infinite = tmp_path / "infinite.json"
    infinite.write_text(json.dumps({**manifest_of(ACC_FILE), "kpi": float("-inf")}))
    refused = run_cli("policy", "upload", str(ACC_FILE), "--manifest", str(infinite), env=env)
    assert refused.returncode == 1
    assert refused.stderr == (
        f"smoothfleet: error: policy: manifest {infinite}: -Infinity is no JSON number and cannot "
        "be stored (write null for a figure that was not measured)\n"
    )
    listed = run_cli("policy", "list", env=env)
    assert ACC_SHA256 in listed.stdout
    assert "2 policy(ies)" in listed.stdout  # the upload and the seed's rl_accel


def documented_comparison() -> str:
    """The policy comparison query of docs/analytics.md, as written there."""
    document = (Path(__file__).resolve().parents[2] / "docs" / "analytics.md").read_text()
    start = document.index("-- Two policies on two halves of the fleet")
    return document[start : document.index(";", start)]


def test_the_documented_query_compares_two_policies_on_two_halves_of_the_fleet(api: Api) -> None:
    assert api.upload(ACC_FILE.read_bytes(), manifest_of(ACC_FILE)).status_code == 201
    other = "e" * 64  # a policy a car carries that was never uploaded
    now = datetime.now(UTC).replace(microsecond=0)
    halves = {ACC_SHA256: ["SF-001", "SF-002"], other: ["SF-003", "SF-004"]}
    for policy, vehicle_ids in halves.items():
        for vehicle_id in vehicle_ids:
            pings = drive(vehicle_id, now - timedelta(seconds=10), 2000.0, 25.0, 10)
            smooth = 0.1 if policy == ACC_SHA256 else 0.5
            post_pings(
                api.client,
                api.tokens["admin"],
                [
                    {
                        **ping,
                        "policy_sha256": policy,
                        "accel_mps2": smooth,
                        "controller_engaged": True,
                    }
                    for ping in pings
                ],
            )
    # SF-003 falls back to its stock ACC for 5 s, which brakes harder: that is not the policy's
    # driving, and must count in the engaged share only
    fallback = drive("SF-003", now + timedelta(seconds=1), 2250.0, 25.0, 5)
    post_pings(
        api.client,
        api.tokens["admin"],
        [
            {**ping, "policy_sha256": other, "accel_mps2": 2.0, "controller_engaged": False}
            for ping in fallback
        ],
    )
    post_pings(api.client, api.tokens["admin"], drive("SF-005", now, 2000.0, 25.0, 3))

    with api.engine.connect() as connection:
        rows = connection.execute(text(documented_comparison())).mappings().all()

    assert [row["policy_sha256"] for row in rows] == sorted(halves)  # SF-005 ran no policy
    by_policy = {row["policy_sha256"]: row for row in rows}
    assert (by_policy[ACC_SHA256]["vehicles"], by_policy[ACC_SHA256]["pings"]) == (2, 20)
    assert (by_policy[other]["vehicles"], by_policy[other]["pings"]) == (2, 25)
    assert by_policy[ACC_SHA256]["controller"] == "rl_acc"
    assert by_policy[other]["controller"] is None
    assert by_policy[ACC_SHA256]["accel_rms_mps2"] == pytest.approx(0.1, abs=1e-6)
    assert by_policy[other]["accel_rms_mps2"] == pytest.approx(0.5, abs=1e-6)
    assert float(by_policy[other]["engaged_pct"]) == 80.0
    assert float(by_policy[ACC_SHA256]["engaged_pct"]) == 100.0


def test_a_wrong_method_names_every_method_the_path_serves(api: Api) -> None:
    response = api.client.put("/api/v1/policies", headers=bearer(api.tokens["operator"]))

    assert response.status_code == 405
    assert response.headers["allow"] == "GET, POST"


def test_an_unreadable_multipart_body_is_a_422_that_says_so(api: Api) -> None:
    response = api.client.post(
        "/api/v1/policies",
        content=b"--x\r\nContent-Disposition: form-data; name=policy\r\n\r\nabc\r\n--x--\r\n",
        headers={**bearer(api.tokens["operator"]), "Content-Type": "multipart/form-data"},
    )

    assert response.status_code == 422, response.text
    detail = response.json()["detail"]
    assert detail == "request body cannot be read: Missing boundary in multipart."


def test_the_roster_names_only_policies_the_server_holds(seeded_database_url: str) -> None:
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)

    def add(params: dict[str, Any]) -> subprocess.CompletedProcess[str]:
        return run_cli(
            "vehicles", "add", "--id", "SF-101", "--vin", "JN8BT3BB3PW906499", "--make",
            "Nissan", "--model", "Rogue", "--year", "2023", "--actuation", "acc", "--route", "A",
            "--lane", "1", "--controller", "rl_acc", "--params", json.dumps(params), env=env,
        )  # fmt: skip

    missing = add({"policy_sha256": ACC_SHA256})
    assert missing.returncode == 1
    # one vehicle on the command line is named, not "vehicle row 2" of a file it never had
    assert (
        f"vehicle SF-101: controller_params.policy_sha256: no policy {ACC_SHA256}" in missing.stderr
    )
    bogus = add({"policy_sha256": ACC_SHA256, "temperature": 2})
    assert bogus.returncode == 1
    assert "controller_params.temperature: Extra inputs are not permitted" in bogus.stderr
    assert run_cli("policy", "upload", str(ACC_FILE), env=env).returncode == 0
    added = add({"policy_sha256": ACC_SHA256})
    assert added.returncode == 0, added.stderr


def test_the_demo_refuses_to_store_a_shipped_policy_again_under_another_manifest(
    database_url: str, engine: Engine
) -> None:
    """`smoothfleet demo --rl --keep` on a database that stored the shipped file with an earlier
    manifest (the same bytes, another command) stops before the demo, saying what to do."""
    with session_scope(engine) as session:
        seed(session)
        first = assign_shipped_policies(session)
    with session_scope(engine) as session:
        assert assign_shipped_policies(session) == first  # the same manifest: a no-op
    earlier = manifest_of(ACC_FILE) | {"command": "smoothfleet sim train --actuation acc (earlier)"}
    with engine.begin() as connection:
        connection.execute(
            text(
                "UPDATE dim_policy SET manifest = CAST(:manifest AS jsonb)"
                " WHERE policy_sha256 = :sha"
            ),
            {"manifest": json.dumps(earlier), "sha": ACC_SHA256},
        )
    with (
        session_scope(engine) as session,
        pytest.raises(ManifestConflict, match="another manifest"),
    ):
        assign_shipped_policies(session)
    with pytest.raises(CliError, match="run the demo without --keep"):
        _demo_on(database_url, Settings(), 1.0, 1, rl=True)
