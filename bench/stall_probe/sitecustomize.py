"""Stall probe for bench/ingest.py --probe-stalls: what holds a server process's event loop.

Python imports `sitecustomize` at start-up from PYTHONPATH, so putting this directory first on a
server's PYTHONPATH makes every process of it (uvicorn's workers too) note, in
SMOOTHFLEET_STALL_LOG.<pid>, each garbage collection longer than 2 ms and each event-loop
callback longer than 10 ms (with what it was), stamped with the wall clock. The benchmark reads
these notes back for the time its load ran. Not imported by anything else.
"""

from __future__ import annotations

import asyncio.events
import gc
import os
import time
from typing import Any

_PATH = os.environ.get("SMOOTHFLEET_STALL_LOG")
GC_NOTE_MS = 2.0
CALLBACK_NOTE_MS = 10.0

if _PATH:
    _notes = open(f"{_PATH}.{os.getpid()}", "w", buffering=1)  # noqa: SIM115 - lives with the process
    _gc_started = [0.0]

    def _note_collection(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            _gc_started[0] = time.perf_counter()
            return
        held_ms = (time.perf_counter() - _gc_started[0]) * 1000
        if held_ms > GC_NOTE_MS:
            _notes.write(f"{time.time():.3f}\tgc gen{info['generation']}\t{held_ms:.1f}\n")

    gc.callbacks.append(_note_collection)
    _run_callback = asyncio.events.Handle._run

    def _timed_run(self: asyncio.events.Handle) -> None:
        started = time.perf_counter()
        _run_callback(self)
        held_ms = (time.perf_counter() - started) * 1000
        if held_ms > CALLBACK_NOTE_MS:
            what = repr(getattr(self, "_callback", self))[:120].replace("\t", " ")
            _notes.write(f"{time.time():.3f}\tcallback {what}\t{held_ms:.1f}\n")

    asyncio.events.Handle._run = _timed_run  # type: ignore[method-assign]
