"""The ping fast path: answer `POST /api/v1/pings` before FastAPI's routing.

Vehicles post a ping a second each, so this one endpoint carries nearly all of the API's
requests. Routing, dependency solving and response classes cost several times the work of
the ingest itself (measured in bench/ingest.py), so this middleware recognises the request by
method and path and answers it with `reply_to_pings`, the same function the declared FastAPI
route calls (that route documents the endpoint in OpenAPI). Outer middleware (body size limit,
request metrics) still applies.
"""

from __future__ import annotations

from starlette.types import ASGIApp, Receive, Scope, Send

from app.ingest.http import JSON, reply_to_pings

PINGS_PATH = "/api/v1/pings"


class RouteLabel:
    """What the request-metrics middleware reads as the matched route's template."""

    def __init__(self, path: str) -> None:
        self.path = path


_PINGS_ROUTE = RouteLabel(PINGS_PATH)


class PingFastPath:
    """ASGI middleware answering POST /api/v1/pings; everything else goes on to the app."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["path"] != PINGS_PATH or scope["method"] != "POST":
            await self.app(scope, receive, send)
            return
        scope["route"] = _PINGS_ROUTE
        chunks = []
        more = True
        while more:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            chunks.append(message.get("body", b""))
            more = message.get("more_body", False)
        authorization = encoding = None
        for name, value in scope["headers"]:
            if name == b"authorization":
                authorization = value.decode("latin-1")
            elif name == b"content-encoding":
                encoding = value.decode("latin-1")
        reply = await reply_to_pings(scope["app"].state, authorization, b"".join(chunks), encoding)
        headers = [JSON, (b"content-length", str(len(reply.body)).encode())]
        headers.extend(
            (name.lower().encode(), value.encode()) for name, value in reply.headers.items()
        )
        await send({"type": "http.response.start", "status": reply.status, "headers": headers})
        await send({"type": "http.response.body", "body": reply.body})
