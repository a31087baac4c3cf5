"""The agent's side of the server contract (docs/interfaces.md): config, corridor, plan,
pings and status, over an injected httpx client (a real one in the car, the demo's in-process
transport or a test server elsewhere). Every call has a short timeout and raises `ServerError`
(with the status code when there was one) instead of letting transport errors escape.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import httpx
from pydantic import ValidationError

from contract.corridor import CorridorGeometry
from contract.vehicles import PingAnswer, VehicleConfig
from vehicle_agent.plan import Plan, PlanError, parse_plan


class ServerError(Exception):
    """A call failed: no answer, an error status, or an answer that is not what was agreed."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class PlanFetch:
    """The outcome of one plan poll."""

    status: Literal["new", "unchanged", "unavailable"]
    plan: Plan | None = None
    etag: str | None = None
    retry_after_s: float | None = None


class ServerClient:
    """Calls for one vehicle with its bearer token."""

    def __init__(
        self, http: httpx.Client, vehicle_id: str, token: str, timeout_s: float = 3.0
    ) -> None:
        self.http = http
        self.vehicle_id = vehicle_id
        self.timeout = httpx.Timeout(timeout_s)
        self.headers = {"Authorization": f"Bearer {token}"}
        self.last_rtt_ms: float | None = None

    def _request(
        self,
        method: str,
        path: str,
        *,
        json: Any = None,
        headers: Mapping[str, str] | None = None,
    ) -> httpx.Response:
        started = time.perf_counter()
        try:
            response = self.http.request(
                method,
                path,
                json=json,
                headers={**self.headers, **(headers or {})},
                timeout=self.timeout,
            )
        except httpx.HTTPError as error:
            raise ServerError(f"{method} {path}: {type(error).__name__}: {error}") from None
        self.last_rtt_ms = (time.perf_counter() - started) * 1000.0
        return response

    @staticmethod
    def _fail(response: httpx.Response, what: str) -> ServerError:
        try:
            detail = response.json().get("detail")
        except ValueError:
            detail = response.text[:200]
        return ServerError(f"{what}: HTTP {response.status_code} {detail}", response.status_code)

    def config(self) -> VehicleConfig:
        """What this vehicle should run."""
        response = self._request("GET", f"/api/v1/vehicles/{self.vehicle_id}/config")
        if response.status_code != 200:
            raise self._fail(response, "config")
        try:
            return VehicleConfig.model_validate_json(response.content)
        except ValidationError as error:
            raise ServerError(
                f"config: not a vehicle config ({error.errors()[0]['msg']})"
            ) from None

    def corridor(self, corridor_id: str) -> CorridorGeometry:
        """The corridor's geometry, for map-matching and the geofence."""
        response = self._request("GET", f"/api/v1/corridors/{corridor_id}")
        if response.status_code != 200:
            raise self._fail(response, "corridor")
        try:
            body = response.json()
            return CorridorGeometry.from_segments(corridor_id, int(body["lanes"]), body["segments"])
        except (ValueError, KeyError, TypeError) as error:
            raise ServerError(f"corridor: unusable geometry ({error})") from None

    def plan(self, etag: str | None) -> PlanFetch:
        """Poll the vehicle's plan with If-None-Match; 503 means no valid plan exists."""
        headers = {"If-None-Match": etag} if etag else None
        response = self._request("GET", f"/api/v1/vehicles/{self.vehicle_id}/plan", headers=headers)
        if response.status_code == 304:
            return PlanFetch("unchanged", etag=etag)
        if response.status_code == 503:
            retry = response.headers.get("Retry-After")
            try:
                retry_after = float(retry) if retry is not None else None
            except ValueError:
                retry_after = None
            return PlanFetch("unavailable", retry_after_s=retry_after)
        if response.status_code != 200:
            raise self._fail(response, "plan")
        try:
            plan = parse_plan(response.content)
        except PlanError as error:
            raise ServerError(str(error)) from None
        return PlanFetch("new", plan=plan, etag=response.headers.get("ETag"))

    def post_pings(self, pings: Sequence[Mapping[str, Any]]) -> PingAnswer:
        """Upload a batch; the answer comes only after the server committed the accepted rows."""
        response = self._request("POST", "/api/v1/pings", json={"pings": list(pings)})
        if response.status_code != 200:
            raise self._fail(response, "pings")
        try:
            return PingAnswer.model_validate_json(response.content)
        except ValidationError as error:
            raise ServerError(f"pings: unexpected answer ({error.errors()[0]['msg']})") from None

    def post_status(self, report: Mapping[str, Any]) -> None:
        """Post a piStatus report."""
        response = self._request(
            "POST", f"/api/v1/vehicles/{self.vehicle_id}/status", json=dict(report)
        )
        if response.status_code != 200:
            raise self._fail(response, "status")
