"""The agent's side of the server contract (docs/interfaces.md): config, corridor, plan,
pings and status, over an injected httpx client (a real one in the car, the demo's in-process
transport or a test server elsewhere). Every call has a short timeout.

A failed call raises one `ServerError` subclass per cause, each with one effect on the agent
(docs/agent.md, "When the server is away"):

| error | cause | effect |
|---|---|---|
| `ServerUnreachable` | no connection (refused, DNS, reset) | keep the plan, retry with backoff |
| `ServerTimeout` | no answer within the timeout | keep the plan, retry with backoff |
| `ServerUnavailable` | 5xx, 503 `database_unavailable` | keep the plan, retry after Retry-After |
| `NotAuthorized` | 401 / 403 | keep the plan, log an error, retry (a token to fix) |
| `UnexpectedAnswer` | another status, or a body not in the contract | keep the plan, retry |
| `RequestRefused` | 409, 413 or 422: this request refused as a whole | a ping batch is split |

A plan poll answers one of three outcomes instead: `NewPlan` (200), `PlanUnchanged` (304) and
`NoValidPlan` (503 with code `no_valid_plan`), the only answer that ends the plan the car follows
before its own `valid_until`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from email.utils import parsedate_to_datetime
from typing import Any

import httpx
from pydantic import ValidationError

from contract.corridor import CorridorGeometry
from contract.errors import NO_VALID_PLAN, ErrorResponse
from contract.vehicles import CONFIG_VERSION_HEADER, PingAnswer, VehicleConfig
from vehicle_agent.plan import Plan, PlanError, parse_plan


class ServerError(Exception):
    """A call failed; the subclass says how, `status` is the HTTP status when there was one."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status


class ServerUnreachable(ServerError):
    """No connection to the server (refused, unresolvable, reset before an answer)."""


class ServerTimeout(ServerError):
    """The server did not answer within the call's timeout."""


class ServerUnavailable(ServerError):
    """A 5xx: the server is up but cannot serve now (e.g. its database is away)."""

    def __init__(self, message: str, status: int, retry_after_s: float | None) -> None:
        super().__init__(message, status)
        self.retry_after_s = retry_after_s


class NotAuthorized(ServerError):
    """401 or 403: the token is missing, revoked, or may not do this."""


class UnexpectedAnswer(ServerError):
    """Any other status, or a body that is not what the contract says."""


class PlanNotServed(UnexpectedAnswer):
    """A 404 to the plan poll of a known vehicle: its corridor has no such lane (the car was
    moved to another corridor). `config_version` is the version the server named with it (the
    car then reads its new config at once, not at its next refresh)."""

    def __init__(self, message: str, status: int, config_version: int) -> None:
        super().__init__(message, status)
        self.config_version = config_version


class RequestRefused(UnexpectedAnswer):
    """409, 413 or 422: the server refused this request as a whole, and would refuse the same
    bytes again (`too_large` for 413, the body over a size limit)."""

    @property
    def too_large(self) -> bool:
        """True when the body was refused for its size (413)."""
        return self.status == 413


# Each outcome of a plan poll carries the vehicle's config version the server named with it
# (`X-Config-Version`; None from a server that names none): a version other than the one the
# car runs makes it fetch its config at once.


@dataclass(frozen=True)
class NewPlan:
    """200: a plan (new, or changed since the ETag the car sent), and when the server sent it
    by its own clock (the answer's `Date`, to the second; None without one)."""

    plan: Plan
    etag: str | None
    served_at: datetime | None = None
    config_version: int | None = None


@dataclass(frozen=True)
class PlanUnchanged:
    """304: the plan held (by its ETag) is still the latest."""

    config_version: int | None = None


@dataclass(frozen=True)
class NoValidPlan:
    """503 `no_valid_plan`: the server holds no valid plan; the car hands back."""

    retry_after_s: float | None
    config_version: int | None = None


PlanFetch = NewPlan | PlanUnchanged | NoValidPlan


def _retry_after(response: httpx.Response) -> float | None:
    value = response.headers.get("Retry-After")
    try:
        return float(value) if value is not None else None
    except ValueError:
        return None


def _served_at(response: httpx.Response) -> datetime | None:
    """The answer's `Date` (RFC 9110: the server's clock when it answered), or None."""
    value = response.headers.get("Date")
    if value is None:
        return None
    try:
        served = parsedate_to_datetime(value)
    except (TypeError, ValueError, IndexError):
        return None
    return served if served.tzinfo is not None else served.replace(tzinfo=UTC)


def _config_version(response: httpx.Response) -> int | None:
    """The config version the answer names (`X-Config-Version`), or None without a readable
    one: a positive integer, as `VehicleConfig.config_version`."""
    value = response.headers.get(CONFIG_VERSION_HEADER, "")
    if not value.isascii() or not value.isdecimal():
        return None
    version = int(value)
    return version if version >= 1 else None


def _error_body(response: httpx.Response) -> ErrorResponse | None:
    try:
        return ErrorResponse.model_validate_json(response.content)
    except ValidationError:
        return None


class ServerClient:
    """Calls for one vehicle with its bearer token."""

    def __init__(
        self, http: httpx.Client, vehicle_id: str, token: str, timeout_s: float = 3.0
    ) -> None:
        self.http = http
        self.vehicle_id = vehicle_id
        self.timeout_s = timeout_s
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
        # httpx's timeout bounds each read, not the answer: a body dripped a byte a second held
        # the network thread 19 s against a 3 s timeout (an audit). The body's bytes as they
        # come (before any decoding: a gzip header dripped yields nothing decoded) are read
        # against a deadline of the timeout from the request's start, so an answer ends within
        # the timeout and one read's (the status line and headers still by each read's).
        deadline = started + self.timeout_s
        try:
            with self.http.stream(
                method,
                path,
                json=json,
                headers={**self.headers, **(headers or {})},
                timeout=self.timeout,
            ) as streamed:
                if streamed.is_stream_consumed:
                    # an in-process transport's answer (the demo's), whole and decoded already
                    response = streamed
                else:
                    raw = bytearray()
                    for chunk in streamed.iter_raw():
                        raw += chunk
                        if time.perf_counter() > deadline:
                            raise ServerTimeout(
                                f"{method} {path}: the answer took over {self.timeout_s:g} s"
                            )
                    # decoded here, as its Content-Encoding says (DecodingError if it is not)
                    response = httpx.Response(
                        streamed.status_code,
                        headers=streamed.headers,
                        content=bytes(raw),
                        request=streamed.request,
                    )
        except httpx.TimeoutException as error:
            raise ServerTimeout(f"{method} {path}: no answer ({type(error).__name__})") from None
        except httpx.TransportError as error:
            raise ServerUnreachable(f"{method} {path}: {type(error).__name__}: {error}") from None
        except httpx.HTTPError as error:
            # an answer httpx could not read (a body that is not the Content-Encoding it names,
            # a proxy's redirect loop): not what the contract says, so the callers' handling of
            # a bad answer applies (a policy download's failure hands the car back) instead of
            # an error none of them expects leaving the car on the policy assigned before
            raise UnexpectedAnswer(f"{method} {path}: {type(error).__name__}: {error}") from None
        self.last_rtt_ms = (time.perf_counter() - started) * 1000.0
        return response

    @staticmethod
    def _fail(response: httpx.Response, what: str) -> ServerError:
        """The typed error for an answer that is not the call's success."""
        body = _error_body(response)
        detail = body.detail if body is not None else response.text[:200]
        status = response.status_code
        message = f"{what}: HTTP {status} {detail}"
        if status in (401, 403):
            return NotAuthorized(message, status)
        if status >= 500:
            return ServerUnavailable(message, status, _retry_after(response))
        if status in (409, 413, 422):
            return RequestRefused(message, status)
        return UnexpectedAnswer(message, status)

    def config(self) -> VehicleConfig:
        """What this vehicle should run."""
        response = self._request("GET", f"/api/v1/vehicles/{self.vehicle_id}/config")
        if response.status_code != 200:
            raise self._fail(response, "config")
        try:
            return VehicleConfig.model_validate_json(response.content)
        except ValidationError as error:
            first = error.errors(include_url=False)[0]
            where = ".".join(str(part) for part in first["loc"])
            raise UnexpectedAnswer(
                f"config: not a vehicle config ({where}: {first['msg']})"
            ) from None

    def corridor(self, corridor_id: str) -> CorridorGeometry:
        """The corridor's geometry, for map-matching and the geofence."""
        response = self._request("GET", f"/api/v1/corridors/{corridor_id}")
        if response.status_code != 200:
            raise self._fail(response, "corridor")
        try:
            body = response.json()
            return CorridorGeometry.from_segments(corridor_id, int(body["lanes"]), body["segments"])
        # OverflowError: "lanes": 1e400 (infinity, which int() cannot take)
        except (ValueError, KeyError, TypeError, OverflowError) as error:
            raise UnexpectedAnswer(f"corridor: unusable geometry ({error})") from None

    def plan(self, lane: int, etag: str | None) -> PlanFetch:
        """Poll the plan of the lane this car's config assigns, with If-None-Match (see the
        module's table of outcomes). Asking for the lane explicitly means the plan always matches
        the config the car runs, even while a new assignment is on its way to the car."""
        headers = {"If-None-Match": etag} if etag else None
        path = f"/api/v1/vehicles/{self.vehicle_id}/plan?lane={lane}"
        response = self._request("GET", path, headers=headers)
        config_version = _config_version(response)
        if response.status_code == 304:
            return PlanUnchanged(config_version)
        if response.status_code == 503:
            body = _error_body(response)
            if body is not None and body.code == NO_VALID_PLAN:
                return NoValidPlan(_retry_after(response), config_version)
        if response.status_code == 404 and config_version is not None:
            failed = self._fail(response, "plan")
            raise PlanNotServed(str(failed), response.status_code, config_version)
        if response.status_code != 200:
            raise self._fail(response, "plan")
        try:
            plan = parse_plan(response.content)
        except PlanError as error:
            raise UnexpectedAnswer(str(error), response.status_code) from None
        return NewPlan(plan, response.headers.get("ETag"), _served_at(response), config_version)

    def policy(self, sha256: str) -> bytes:
        """The bytes of the policy file with this sha256 (the caller verifies them before use:
        `vehicle_agent.policies.PolicyStore`)."""
        response = self._request("GET", f"/api/v1/policies/{sha256}")
        if response.status_code != 200:
            raise self._fail(response, "policy")
        return response.content

    def post_pings(self, pings: Sequence[Mapping[str, Any]]) -> PingAnswer:
        """Upload a batch; the answer comes only after the server committed the accepted rows."""
        response = self._request("POST", "/api/v1/pings", json={"pings": list(pings)})
        if response.status_code != 200:
            raise self._fail(response, "pings")
        try:
            answer = PingAnswer.model_validate_json(response.content)
        except ValidationError as error:
            raise UnexpectedAnswer(
                f"pings: unexpected answer ({error.errors()[0]['msg']})"
            ) from None
        # the agent forgets the batch on this answer: it must account for every ping once
        indexes = [rejection.index for rejection in answer.rejected]
        outside = any(not 0 <= index < len(pings) for index in indexes)
        if outside or len(set(indexes)) < len(indexes):
            raise UnexpectedAnswer(f"pings: rejections {indexes} for a batch of {len(pings)}")
        counted = answer.accepted + answer.duplicates + len(indexes)
        if counted != len(pings):
            raise UnexpectedAnswer(f"pings: the answer accounts for {counted} of {len(pings)}")
        return answer

    def post_status(self, report: Mapping[str, Any]) -> None:
        """Post a piStatus report."""
        response = self._request(
            "POST", f"/api/v1/vehicles/{self.vehicle_id}/status", json=dict(report)
        )
        if response.status_code != 200:
            raise self._fail(response, "status")
