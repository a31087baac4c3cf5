"""Real servers for tests: uvicorn in a thread, or `smoothfleet serve` as a process."""

from __future__ import annotations

import os
import resource
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import uvicorn

from app.core.config import load_settings
from smoothfleet.server import create_app

# How long a server may take to exit after SIGTERM (docker stop waits 10 s by default; this
# is the bound on a loaded 2-core CI machine, not the expectation).
SHUTDOWN_WITHIN_S = 60


def free_port() -> int:
    """A TCP port nobody listens on right now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@contextmanager
def live_server(database_url: str, **settings: Any) -> Iterator[str]:
    """The real app on a real socket (uvicorn in a thread); yields its base URL."""
    app = create_app(load_settings(database_url=database_url, **settings))
    port = free_port()
    server = uvicorn.Server(
        # As `smoothfleet serve` runs it: forwarded-for headers are the app's to believe.
        uvicorn.Config(
            app,
            host="127.0.0.1",
            port=port,
            log_level="warning",
            lifespan="on",
            proxy_headers=False,
        )
    )
    thread = threading.Thread(target=server.run, name="live-server", daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            raise RuntimeError("live server did not start")
        time.sleep(0.02)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=30)


def cli_env(**extra: str) -> dict[str, str]:
    """The environment for running the CLI in a subprocess (no inherited SMOOTHFLEET_*)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("SMOOTHFLEET_")}
    env.update(extra)
    return env


def smoothfleet_command() -> list[str]:
    """How to invoke the installed CLI from this interpreter."""
    script = Path(sys.executable).parent / "smoothfleet"
    return [str(script)] if script.exists() else [sys.executable, "-m", "smoothfleet.cli"]


def run_cli(
    *args: str,
    env: dict[str, str],
    timeout: float = 120,
    stdin: str | None = None,
    file_size_limit_bytes: int | None = None,
) -> subprocess.CompletedProcess[str]:
    """Run `smoothfleet ARGS...` (optionally feeding `stdin`) and capture its output.

    `file_size_limit_bytes` caps every file the command writes (RLIMIT_FSIZE), so a write
    fails half-way as it would on a full disk."""

    limit = file_size_limit_bytes

    def limit_file_size() -> None:
        assert limit is not None
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run(
        [*smoothfleet_command(), *args],
        env=env,
        input=stdin,
        capture_output=True,
        text=True,
        timeout=timeout,
        # only where asked: a preexec_fn is not safe in a process that runs threads
        preexec_fn=None if limit is None else limit_file_size,
    )


def stop_gracefully(process: subprocess.Popen[Any], log: Path | None = None) -> None:
    """SIGTERM, as a service manager stops it, and wait for the process to exit by itself.

    One that is still running after `SHUTDOWN_WITHIN_S` fails its test, naming its log's tail,
    and is killed first: a hung shutdown is the test's finding, not the next test's
    leftover process."""
    if process.poll() is not None:
        return
    process.terminate()
    try:
        process.wait(timeout=SHUTDOWN_WITHIN_S)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
        tail = log.read_text(errors="replace")[-3000:] if log is not None else ""
        raise AssertionError(
            f"{process.args} still running {SHUTDOWN_WITHIN_S} s after SIGTERM\n{tail}"
        ) from None


def wait_until_ready(base_url: str, timeout_s: float = 60) -> None:
    """Poll /readyz until it answers 200."""
    deadline = time.monotonic() + timeout_s
    last: object = None
    while time.monotonic() < deadline:
        try:
            response = httpx.get(f"{base_url}/readyz", timeout=2)
            if response.status_code == 200:
                return
            last = response.text
        except httpx.HTTPError as error:
            last = error
        time.sleep(0.1)
    raise TimeoutError(f"{base_url} not ready: {last}")
