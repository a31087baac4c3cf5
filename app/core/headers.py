"""Security headers on every response, and the API docs served from local assets.

The dashboard loads only its own scripts and styles (no CDN, nothing from the internet at run
time), so the Content-Security-Policy can say 'self'; charts draw SVG with a few inline style
attributes, allowed through style-src-attr only. The interactive API docs (/docs, /redoc) come
from the fastapi-offline package's copy of Swagger UI and ReDoc, whose start-up snippet is
inline, so those two pages alone also allow inline scripts.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send

DOCS_PATHS = ("/docs", "/redoc")
DOCS_ASSETS = "/static/apidocs"

_POLICY = (
    "default-src 'self'; img-src 'self' data:; style-src 'self'; "
    "style-src-attr 'unsafe-inline'; script-src 'self'{inline}; object-src 'none'; "
    "base-uri 'self'; form-action 'self'; frame-ancestors 'none'"
)
_COMMON = [
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"same-origin"),
    (b"cross-origin-opener-policy", b"same-origin"),
]
STRICT = [*_COMMON, (b"content-security-policy", _POLICY.format(inline="").encode())]
DOCS = [
    *_COMMON,
    (b"content-security-policy", _POLICY.format(inline=" 'unsafe-inline'").encode()),
]
# Answers are a car's config, a fleet's state, a logged-in page: no browser or proxy keeps
# them (a shared computer's cache showed the dashboard to whoever came next). The dashboard's
# and the docs' own assets (`/static/`) are not such answers, and stay cacheable; a response
# that says how it may be cached itself keeps its say.
NO_STORE = (b"cache-control", b"no-store")
ASSETS_PREFIX = "/static/"
# Browsers honour HSTS only over HTTPS; behind a TLS-terminating proxy (proxy_headers on) the
# scheme is https, and the header keeps later visits off plain HTTP.
HSTS = (b"strict-transport-security", b"max-age=31536000")


class SecurityHeaders:
    """Adds the headers to every HTTP response (API, fast ping path, dashboard)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = DOCS if scope["path"] in DOCS_PATHS else STRICT
        if not scope["path"].startswith(ASSETS_PREFIX):
            headers = [*headers, NO_STORE]
        if scope.get("scheme") == "https":
            headers = [*headers, HSTS]

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                present = {name.lower() for name, _ in message.get("headers", [])}
                extra = [(name, value) for name, value in headers if name not in present]
                message["headers"] = [*message.get("headers", []), *extra]
            await send(message)

        await self.app(scope, receive, send_with_headers)


def install_api_docs(app: FastAPI) -> None:
    """/docs and /redoc from local assets (create the app with docs_url=redoc_url=None)."""
    import fastapi_offline

    assets = Path(fastapi_offline.__file__).parent / "static"
    app.mount(DOCS_ASSETS, StaticFiles(directory=assets), name="apidocs")

    @app.get("/docs", include_in_schema=False)
    async def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url="/openapi.json",
            title=f"{app.title} API",
            swagger_js_url=f"{DOCS_ASSETS}/swagger-ui-bundle.js",
            swagger_css_url=f"{DOCS_ASSETS}/swagger-ui.css",
            swagger_favicon_url=f"{DOCS_ASSETS}/favicon.png",
        )

    @app.get("/redoc", include_in_schema=False)
    async def redoc() -> HTMLResponse:
        return get_redoc_html(
            openapi_url="/openapi.json",
            title=f"{app.title} API",
            redoc_js_url=f"{DOCS_ASSETS}/redoc.standalone.js",
            redoc_favicon_url=f"{DOCS_ASSETS}/favicon.png",
            with_google_fonts=False,
        )
