"""Schemathesis over the whole OpenAPI with vehicle, operator and admin tokens and without one.

Every operation gets generated valid and invalid requests (examples, coverage of boundaries and
fuzzing) and every default check: no 5xx, every status code and header documented, every body
in its documented shape (errors: `{"detail": ...}`), schema-violating requests refused and
schema-valid ones accepted, on every operation. Timestamps are drawn from the last hour, and a
status report's `ts` outside the server's window is moved to now (schemathesis_hooks.py): the
API's window around now cannot be said in JSON Schema. Reports and assignments go to a vehicle of
the seeded roster (schemathesis.toml). The seed stores a shipped policy, so its reads are 200,
and a positive upload sends a shipped policy with its manifest (schemathesis_hooks.py):
a schema cannot say that a file must hash to its manifest and load. The run's seed is fixed so
CI is repeatable; run the same command without `--seed` for fresh cases (see docs/operations.md).
"""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from sqlalchemy import Engine, text

from app.core.config import load_settings
from app.plans.jobs import run_planner
from tests.planner.facts import inrix_snapshot, standing_slowdown
from tests.security.schemathesis_hooks import UNNAMED_CONTROLLER
from tests.support.servers import live_server
from tests.support.tokens import issue
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

REPO = Path(__file__).resolve().parents[2]
CONFIG = Path(__file__).with_name("schemathesis.toml")
# Stored by the seed (the RAV4s run it); schemathesis.toml names it as the policy the reads ask
# for.
STORED_POLICY = BUNDLED_POLICIES / "rl_accel.npz"
SEED = "20261123"
# Per principal, two runs. Drawn: the examples, then fuzzing with this many cases per operation,
# a fixed amount of work (255 cases or more over the 18 operations, ~20 s on an idle machine).
# Before, one run took `--max-time 20` for everything and the test asked for 200 cases of what
# fit: 913 on an idle machine, 195 on a busy one, which failed a sound API.
FUZZED_CASES_PER_OPERATION = "20"
# Boundaries: schemathesis's coverage phase, for as long as this. Whole, it takes about 200 s a
# principal with operator or admin rights, more than CI's 20 minutes hold for four principals;
# so it gets a time budget, and every case it reaches must pass, but how many it reaches is not
# asked. docs/operations.md gives the run to make before a release.
BOUNDARY_SECONDS = "8"


@pytest.fixture
def api_with_a_plan(seeded_database_url: str, seeded_engine: Engine) -> Iterator[str]:
    """The live API over a seeded warehouse (which holds a shipped policy) with a published plan
    (so plan and policy reads are 200)."""
    now = datetime.now(UTC).replace(microsecond=0)
    for minutes_ago in range(6, 1, -1):
        inrix_snapshot(seeded_engine, now - timedelta(minutes=minutes_ago), standing_slowdown())
    settings = load_settings(database_url=seeded_database_url, plan_valid_for_s=900)
    (outcome,) = run_planner(seeded_engine, settings)
    assert outcome.status == "published", outcome.reason
    with live_server(
        seeded_database_url,
        planner_enabled=False,
        plan_valid_for_s=900,
        rate_limit_per_token_per_s=0,  # limits have their own tests; here, reach the logic
    ) as base:
        yield base


@dataclass(frozen=True)
class Fuzzed:
    """The two schemathesis runs of one principal (`FUZZED_CASES_PER_OPERATION`,
    `BOUNDARY_SECONDS`)."""

    drawn: subprocess.CompletedProcess[str]
    boundaries: subprocess.CompletedProcess[str]

    def failures(self) -> str:
        """Both runs' tails, for an assertion's message."""
        return "\n".join(
            run.stdout[-6000:] + run.stderr[-2000:] for run in (self.drawn, self.boundaries)
        )


def fuzz(base: str, workdir: Path, *headers: str) -> Fuzzed:
    """Schemathesis over the API as the principal `headers` name, in two runs (`Fuzzed`)."""
    return Fuzzed(
        drawn=schemathesis(
            base,
            workdir,
            ["--phases", "examples,fuzzing", "--max-examples", FUZZED_CASES_PER_OPERATION],
            headers,
        ),
        boundaries=schemathesis(
            base, workdir, ["--phases", "coverage", "--max-time", BOUNDARY_SECONDS], headers
        ),
    )


def schemathesis(
    base: str, workdir: Path, phases: list[str], headers: tuple[str, ...]
) -> subprocess.CompletedProcess[str]:
    command = [
        str(Path(sys.executable).parent / "schemathesis"),
        "--config-file",
        str(CONFIG),
        "run",
        f"{base}/openapi.json",
        *phases,
        "--seed",
        SEED,
        "--workers",
        "1",
        "--generation-database",
        "none",
        "--no-color",
        *[part for header in headers for part in ("-H", header)],
    ]
    env = {
        **os.environ,
        "SCHEMATHESIS_HOOKS": "tests.security.schemathesis_hooks",
        "PYTHONPATH": str(REPO),
    }
    return subprocess.run(
        command, cwd=workdir, env=env, capture_output=True, text=True, timeout=600, check=False
    )


def cases_passed(report: str) -> int:
    """How many generated cases passed every check (all of them, or the run failed)."""
    found = re.search(r"(\d+) generated, (\d+) passed", report)
    assert found, report[-3000:]
    generated, passed = int(found[1]), int(found[2])
    assert generated == passed, report[-3000:]
    return passed


def accepted_on_the_roster_vehicle(engine: Engine) -> tuple[int, int]:
    """Status reports stored for SF-001, and its config version (bumped by each assignment)."""
    with engine.connect() as connection:
        reports = connection.execute(
            text("SELECT count(*) FROM fact_vehicle_status WHERE vehicle_id = 'SF-001'")
        ).scalar_one()
        version = connection.execute(
            text("SELECT config_version FROM dim_vehicle WHERE vehicle_id = 'SF-001'")
        ).scalar_one()
    return int(reports), int(version)


def stored_controllers(engine: Engine) -> set[str]:
    with engine.connect() as connection:
        return set(connection.scalars(text("SELECT controller FROM dim_policy")))


def test_the_policy_the_fuzzer_reads_is_the_one_stored_before_the_run() -> None:
    """schemathesis.toml's sha256 for the policy reads is the stored file's, not a stale one."""
    config = tomllib.loads(CONFIG.read_text(encoding="utf-8"))
    (sha256,) = {
        operation["parameters"]["path.sha256"]
        for operation in config["operations"]
        if "path.sha256" in operation.get("parameters", {})
    }
    assert sha256 == hashlib.sha256(STORED_POLICY.read_bytes()).hexdigest()
    assert STORED_POLICY.stem != UNNAMED_CONTROLLER  # so accepted uploads show as a new policy


@pytest.mark.slow
@pytest.mark.parametrize("role", ["vehicle", "operator", "admin"])
def test_fuzzing_with_a_token_passes_every_default_check(
    api_with_a_plan: str, seeded_engine: Engine, tmp_path: Path, role: str
) -> None:
    token = issue(seeded_engine, role, "SF-001" if role == "vehicle" else None)  # type: ignore[arg-type]
    reports_before, version_before = accepted_on_the_roster_vehicle(seeded_engine)
    assert stored_controllers(seeded_engine) == {STORED_POLICY.stem}
    result = fuzz(api_with_a_plan, tmp_path, f"Authorization: Bearer {token}")
    assert result.drawn.returncode == result.boundaries.returncode == 0, result.failures()
    assert cases_passed(result.drawn.stdout) >= 200
    cases_passed(result.boundaries.stdout)  # every boundary case reached passed
    # Every operation with a path parameter reads something that exists (the roster vehicle,
    # the stored policy), so its 200 path was fuzzed too: no "Missing test data" warning. (The
    # boundaries run draws path parameters at their limits too, which name nothing: 404s.)
    assert "404 responses" not in result.drawn.stdout, result.failures()
    # Schema-valid reports and assignments reached the validation and were stored, so
    # positive_data_acceptance judged them on a vehicle that exists, not on 404s.
    reports, version = accepted_on_the_roster_vehicle(seeded_engine)
    assert reports > reports_before
    assert (version > version_before) is (role != "vehicle")  # a vehicle token cannot assign
    # Schema-valid uploads (a shipped policy, schemathesis_hooks.py) were stored: the one of an
    # upload naming no controller is not the one stored before the run. A vehicle cannot upload.
    assert (UNNAMED_CONTROLLER in stored_controllers(seeded_engine)) is (role != "vehicle")


@pytest.mark.slow
def test_fuzzing_without_a_token_is_only_ever_refused_in_the_documented_shape(
    api_with_a_plan: str, tmp_path: Path
) -> None:
    result = fuzz(api_with_a_plan, tmp_path)
    assert result.drawn.returncode == result.boundaries.returncode == 0, result.failures()
    assert cases_passed(result.drawn.stdout) >= 200
    cases_passed(result.boundaries.stdout)  # every boundary case reached passed
    assert "returned only 401/403 responses" in result.drawn.stdout
