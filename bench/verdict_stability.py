"""Does a busy dashboard flip cars' clearance? The demo's fleet watched with and without a browser.

    .venv/bin/python -m bench.verdict_stability [--vehicles 100] [--settle 90] [--window 120]

Runs `smoothfleet demo` (its own embedded PostgreSQL in a temporary directory, a fresh port),
lets the fleet start and settle for `--settle` seconds, then watches every car's verdict on the
fleet page (`/fleet/live`, polled every 2 s by a logged-in client) over two windows of
`--window` seconds each:
- baseline: nothing else loads the server;
- browser: real Chromium (/usr/bin/chromium through Playwright) loads every page of the menu,
  and a car's page, one after another in a loop, as fast as they come.
It prints, per window, the verdict changes seen (any car, any direction), the cleared count's
range, and for the browser window the pages loaded.
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import httpx
from playwright.sync_api import TimeoutError as PlaywrightTimeout
from playwright.sync_api import sync_playwright

from smoothfleet.cli.demo_status import VerdictTracker

CHROMIUM = "/usr/bin/chromium"
POLL_S = 2.0
VERDICT = re.compile(r'data-vehicle="([^"]+)" data-verdict="([^"]+)"')
PASSWORD = re.compile(r"login: admin / (\S+)")


@dataclass
class Window:
    """What one watch window saw."""

    name: str
    tracker: VerdictTracker = field(default_factory=VerdictTracker)
    cleared: list[int] = field(default_factory=list)
    polls: int = 0
    pages: int = 0
    slowest: tuple[float, str] = (0.0, "")
    slow_pages: list[str] = field(default_factory=list)

    def line(self) -> str:
        pages = ""
        if self.pages or self.slow_pages:
            pages = (
                f", {self.pages} pages loaded by Chromium (slowest {self.slowest[0]:.1f} s: "
                f"{self.slowest[1]}; not answered: {', '.join(self.slow_pages) or 'none'})"
            )
        low, high = (min(self.cleared), max(self.cleared)) if self.cleared else (0, 0)
        return (
            f"{self.name:9s}: {len(self.tracker.changes)} verdict changes over {self.polls} polls "
            f"of {len(self.tracker.verdicts)} cars; cleared {low}-{high}{pages}"
        )


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
    return port


def log_in(client: httpx.Client, password: str) -> None:
    form = client.get("/login").text
    token = re.search(r'name="csrf_token" value="([^"]+)"', form)
    assert token is not None, "no login form"
    answer = client.post(
        "/login",
        data={"username": "admin", "password": password, "csrf_token": token.group(1)},
    )
    if answer.status_code != 303:
        raise SystemExit(f"login failed: HTTP {answer.status_code}")


def watch(client: httpx.Client, window: Window, seconds: float) -> None:
    """Poll the fleet page's verdicts for `seconds`."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        verdicts = dict(VERDICT.findall(client.get("/fleet/live").text))
        window.tracker.update(datetime.now(UTC), verdicts)
        window.cleared.append(sum(v == "cleared" for v in verdicts.values()))
        window.polls += 1
        time.sleep(POLL_S)


def browse(base: str, password: str, window: Window, stop: threading.Event) -> None:
    """Chromium loads every page of the menu and a car's page in a loop until stopped."""
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=CHROMIUM, headless=True, args=["--no-sandbox", "--disable-gpu"]
        )
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.goto(f"{base}/login")
        page.get_by_label("Username").fill("admin")
        page.get_by_label("Password").fill(password)
        page.get_by_role("button", name="Log in").click()
        page.wait_for_url(f"{base}/fleet")
        menu = page.eval_on_selector_all("header nav a", "links => links.map(a => a.href)")
        paths = [*menu, f"{base}/vehicles/SF-001"]
        while not stop.is_set():
            for path in paths:
                started = time.monotonic()
                try:
                    page.goto(path, wait_until="load", timeout=60_000)
                except PlaywrightTimeout:
                    window.slow_pages.append(f"{path} (no answer in 60 s)")
                    continue
                window.pages += 1
                took = time.monotonic() - started
                window.slowest = max(window.slowest, (took, path))
                if stop.is_set():
                    break
        browser.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--settle", type=float, default=90.0)
    parser.add_argument("--window", type=float, default=120.0)
    args = parser.parse_args()
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory(prefix="sf-verdicts-") as data_dir:
        env = {key: value for key, value in os.environ.items() if key != "SMOOTHFLEET_DATABASE_URL"}
        env["SMOOTHFLEET_DATA_DIR"] = data_dir
        duration = args.settle + 2 * args.window + 60.0
        command = [
            str(Path(sys.executable).parent / "smoothfleet"),
            *("demo", "--port", str(port), "--vehicles", str(args.vehicles)),
            *("--duration", str(duration)),
        ]
        log_path = Path(data_dir) / "demo.log"
        with log_path.open("w") as log:
            demo = subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT)
        try:
            password = None
            while password is None or "fleet:" not in log_path.read_text():
                if demo.poll() is not None:
                    raise SystemExit(f"the demo ended early:\n{log_path.read_text()}")
                found = PASSWORD.search(log_path.read_text())
                password = found.group(1) if found else None
                time.sleep(1.0)
            print(f"demo up with {args.vehicles} vehicles; settling {args.settle:.0f} s")
            time.sleep(args.settle)
            with httpx.Client(base_url=base, timeout=60.0) as client:
                log_in(client, password)
                baseline = Window("baseline")
                watch(client, baseline, args.window)
                loaded = Window("browser")
                stop = threading.Event()
                browser = threading.Thread(target=browse, args=(base, password, loaded, stop))
                browser.start()
                try:
                    watch(client, loaded, args.window)
                finally:
                    stop.set()
                    browser.join(timeout=120)
            print(baseline.line())
            print(loaded.line())
            for window in (baseline, loaded):
                for at, vehicle_id, before, after in window.tracker.changes:
                    print(f"  {window.name} {at:%H:%M:%S} {vehicle_id}: {before} -> {after}")
        finally:
            demo.terminate()
            demo.wait(timeout=180)
        status = [line for line in log_path.read_text().splitlines() if " · fleet step " in line]
        if status:
            print("last demo status line:", status[-1])


if __name__ == "__main__":
    main()
