"""The car's policy store: verify before keeping, never replace a good copy with a bad download,
download only what it does not hold; and the controller refuses a file other than the one named."""

from __future__ import annotations

import hashlib
import os
import time
from pathlib import Path

import pytest

from contract.controllers import RlParams
from vehicle_agent.controllers import build_controller
from vehicle_agent.controllers.policy import PolicyFileError
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES
from vehicle_agent.policies import PolicyDigestMismatch, PolicyStore

ACC = (BUNDLED_POLICIES / "rl_acc.npz").read_bytes()
ACCEL = (BUNDLED_POLICIES / "rl_accel.npz").read_bytes()
ACC_SHA256 = hashlib.sha256(ACC).hexdigest()
ACCEL_SHA256 = hashlib.sha256(ACCEL).hexdigest()


def corrupted(content: bytes) -> bytes:
    damaged = bytearray(content)
    damaged[len(damaged) // 2] ^= 0x01
    return bytes(damaged)


class Downloads:
    """A download function serving given bytes and counting the calls."""

    def __init__(self, content: bytes) -> None:
        self.content = content
        self.calls = 0

    def __call__(self, sha256: str) -> bytes:
        self.calls += 1
        return self.content


def test_a_verified_download_is_kept_under_its_sha256(tmp_path: Path) -> None:
    store = PolicyStore(tmp_path / "policies")

    path = store.keep(ACC_SHA256, ACC, "acc")

    assert path == tmp_path / "policies" / f"{ACC_SHA256}.npz"
    assert path.read_bytes() == ACC
    assert store.holds(ACC_SHA256)
    assert [p.name for p in (tmp_path / "policies").iterdir()] == [path.name]  # no temp left


def test_a_corrupted_download_never_replaces_the_good_copy(tmp_path: Path) -> None:
    store = PolicyStore(tmp_path)
    good = store.keep(ACC_SHA256, ACC, "acc")

    with pytest.raises(PolicyDigestMismatch, match="the download's sha256 is"):
        store.keep(ACC_SHA256, corrupted(ACC), "acc")

    assert good.read_bytes() == ACC
    assert sorted(p.name for p in tmp_path.iterdir()) == [good.name]


def test_bytes_of_the_right_hash_that_are_no_policy_of_the_car_are_not_kept(
    tmp_path: Path,
) -> None:
    store = PolicyStore(tmp_path)
    with pytest.raises(PolicyFileError, match="actuation accel, not acc"):
        store.keep(ACCEL_SHA256, ACCEL, "acc")
    garbage = b"<html>a captive portal</html>"
    with pytest.raises(PolicyFileError, match="not an .npz archive"):
        store.keep(hashlib.sha256(garbage).hexdigest(), garbage, "acc")
    assert list(tmp_path.iterdir()) == []


def test_a_policy_held_is_never_downloaded_again(tmp_path: Path) -> None:
    store = PolicyStore(tmp_path)
    download = Downloads(ACC)

    first = store.fetch(ACC_SHA256, "acc", download)
    second = store.fetch(ACC_SHA256, "acc", download)

    assert first == second
    assert download.calls == 1


def test_a_damaged_copy_on_disk_is_downloaded_again_and_replaced_only_by_good_bytes(
    tmp_path: Path,
) -> None:
    store = PolicyStore(tmp_path)
    path = store.keep(ACC_SHA256, ACC, "acc")
    path.write_bytes(corrupted(ACC))  # the SD card lost a bit
    assert not store.holds(ACC_SHA256)

    with pytest.raises(PolicyDigestMismatch):
        store.fetch(ACC_SHA256, "acc", Downloads(corrupted(ACC)))
    assert store.fetch(ACC_SHA256, "acc", Downloads(ACC)) == path

    assert path.read_bytes() == ACC


def test_the_controller_runs_only_the_policy_its_params_name(tmp_path: Path) -> None:
    named = build_controller("rl_acc", "acc", {"policy_sha256": ACC_SHA256})
    assert named.policy_sha256 == ACC_SHA256  # the bundled file is the one named
    other = tmp_path / "other.npz"
    other.write_bytes(ACC)
    with pytest.raises(PolicyFileError, match=f"the assignment names {ACCEL_SHA256}"):
        build_controller("rl_acc", "acc", {"policy": str(other), "policy_sha256": ACCEL_SHA256})
    assert build_controller("microaccel_acc", "acc", {}).policy_sha256 is None


def test_a_policy_sha256_must_be_lowercase_hex() -> None:
    with pytest.raises(ValueError, match="String should match pattern"):
        RlParams(policy_sha256="../../etc/passwd")


def test_what_a_crash_left_of_a_write_is_removed_when_the_store_opens(tmp_path: Path) -> None:
    """A power cut during a write left its `.part` file in the folder for good."""
    store = PolicyStore(tmp_path)
    kept = store.keep(ACC_SHA256, ACC, "acc")
    crashed = tmp_path / "tmpa1b2c3.part"
    crashed.write_bytes(ACC[:1000])
    yesterday = time.time() - 86400
    os.utime(crashed, (yesterday, yesterday))
    in_progress = tmp_path / "tmpd4e5f6.part"  # another agent sharing the folder, writing now
    in_progress.write_bytes(ACCEL[:1000])

    PolicyStore(tmp_path)

    assert sorted(tmp_path.iterdir()) == sorted([kept, in_progress])
