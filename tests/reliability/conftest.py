"""A private embedded PostgreSQL cluster per test, which the test may stop, start or freeze."""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import pytest

from app.core.embedded import bin_dir, embedded_server
from tests.support.databases import create_template


@dataclass
class Cluster:
    """A private embedded PostgreSQL that the test may stop and start."""

    pgdata: Path
    socket_dir: str
    url: str

    def pg_ctl(self, *args: str) -> None:
        user = "embedded_postgres" if os.geteuid() == 0 else None
        subprocess.run(
            [str(bin_dir() / "pg_ctl"), "-D", str(self.pgdata), *args],
            check=True,
            capture_output=True,
            user=user,
            timeout=60,
        )

    def stop(self) -> None:
        self.pg_ctl("-w", "-m", "fast", "stop")

    def start(self) -> None:
        self.pg_ctl(
            "-w",
            "-o",
            '-h ""',
            "-o",
            f"-k {self.socket_dir}",
            "-l",
            str(self.pgdata / "log"),
            "start",
        )

    def processes(self) -> list[int]:
        """The postmaster and every process it started (backends, checkpointer, ...)."""
        postmaster = int((self.pgdata / "postmaster.pid").read_text().splitlines()[0])
        children = []
        for entry in Path("/proc").iterdir():
            if not entry.name.isdigit():
                continue
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            # pid (comm) state ppid ...: comm may hold spaces, so split after its ')'.
            if int(stat.rsplit(")", 1)[1].split()[1]) == postmaster:
                children.append(int(entry.name))
        return [postmaster, *children]

    def freeze(self) -> None:
        """SIGSTOP the whole server: it accepts nothing and answers nothing, like a hung host."""
        for pid in self.processes():
            os.kill(pid, signal.SIGSTOP)

    def thaw(self) -> None:
        for pid in self.processes():
            os.kill(pid, signal.SIGCONT)


@pytest.fixture
def cluster() -> Iterator[Cluster]:
    pgdata = Path(tempfile.mkdtemp(prefix="smoothfleet-restart-")) / "pgdata"
    with embedded_server(pgdata, delete_on_exit=True) as server_url:
        socket_dir = parse_qs(urlsplit(server_url).query)["host"][0]
        url = create_template(server_url, "reliability", seeded=True)
        cluster = Cluster(pgdata, socket_dir, url)
        yield cluster
        # The wheel only stops the server it started; the restarted one is ours to stop.
        cluster.stop()
