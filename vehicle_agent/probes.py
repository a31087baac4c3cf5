"""The Raspberry Pi's health for piStatus: disk, CPU temperature, UPS (where readable)."""

from __future__ import annotations

import shutil
from pathlib import Path

THERMAL_ZONE = Path("/sys/class/thermal/thermal_zone0/temp")


def disk_free_mb(path: Path) -> float | None:
    """Free space (MB) on the file system holding `path`."""
    try:
        return shutil.disk_usage(path).free / 1_000_000
    except OSError:
        return None


def cpu_temp_c(zone: Path = THERMAL_ZONE) -> float | None:
    """CPU temperature (degrees C) from the kernel's thermal zone, None where there is none."""
    try:
        return int(zone.read_text().strip()) / 1000.0
    except (OSError, ValueError):
        return None
