"""The car's policy store: policies named by sha256, downloaded once, verified, kept.

An assignment names its RL policy by the sha256 of the file (`controller.params.policy_sha256`).
The agent looks for `<sha256>.npz` in its state dir; only when there is no good copy does it
download the file over the authenticated API (`ServerClient.policy`). Nothing reaches the disk
before it is checked: the bytes must hash to the name and load as a policy of the car's
actuation; then they are written to a temporary file and renamed into place, so a bad or
interrupted download never replaces a good file, and a policy once kept stays (files are tens of
kB; none is ever deleted by the agent). What a power cut leaves of a write in progress (a
`.part` file) is removed when the store next opens, once older than any write could be. A copy
on disk that no longer hashes to its name (a damaged SD card) is not good: it is downloaded
again, and replaced only by verified bytes.
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from vehicle_agent.controllers.policy import PolicyActuation, PolicyFileError, read_policy

log = logging.getLogger(__name__)

# A `.part` file older than this (s) is no write in progress but one a crash cut short: a write
# takes milliseconds, and another agent sharing the folder may be in the middle of one.
STALE_PART_S = 3600.0


class PolicyDigestMismatch(PolicyFileError):
    """Bytes whose sha256 is not the one they were asked for (a corrupted download)."""


class PolicyStore:
    """Policies by sha256 in one directory of the agent's state."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self._remove_stale_parts()

    def _remove_stale_parts(self) -> None:
        """Remove what crashed writes left (STALE_PART_S)."""
        now = time.time()
        try:
            for part in self.directory.glob("*.part"):
                try:
                    if now - part.stat().st_mtime > STALE_PART_S:
                        part.unlink()
                except FileNotFoundError:
                    continue  # another agent removed it first
        except OSError as error:
            # tidying is best effort: a card remounted read-only (ext4 after errors) crashed
            # the agent at start-up here; the policies kept on it still load
            log.warning(
                "policy store %s: leftover downloads not removed (%s)", self.directory, error
            )

    def path(self, sha256: str) -> Path:
        """Where the policy with this sha256 is kept."""
        return self.directory / f"{sha256}.npz"

    def holds(self, sha256: str) -> bool:
        """True when a copy that hashes to `sha256` is on disk."""
        try:
            content = self.path(sha256).read_bytes()
        except OSError:
            return False
        return hashlib.sha256(content).hexdigest() == sha256

    def keep(self, sha256: str, content: bytes, actuation: PolicyActuation) -> Path:
        """Check downloaded bytes and keep them under their name; the path.

        PolicyDigestMismatch when they do not hash to `sha256`, PolicyFileError when they are
        not a policy of `actuation`: either way nothing on disk changes.
        """
        actual = hashlib.sha256(content).hexdigest()
        if actual != sha256:
            raise PolicyDigestMismatch(
                f"policy {sha256}", f"the download's sha256 is {actual}; not kept"
            )
        read_policy(content, actuation, f"policy {sha256}")
        self.directory.mkdir(parents=True, exist_ok=True)
        target = self.path(sha256)
        handle, temporary = tempfile.mkstemp(dir=self.directory, suffix=".part")
        try:
            with os.fdopen(handle, "wb") as file:
                file.write(content)
                file.flush()
                os.fsync(file.fileno())
            os.replace(temporary, target)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise
        return target

    def fetch(
        self, sha256: str, actuation: PolicyActuation, download: Callable[[str], bytes]
    ) -> Path:
        """The path of a good copy of the policy, downloading it (`download(sha256)`) only when
        there is none. Raises what `download` raises, or `keep`'s errors."""
        if self.holds(sha256):
            return self.path(sha256)
        return self.keep(sha256, download(sha256), actuation)
