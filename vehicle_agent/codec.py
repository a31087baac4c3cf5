"""CAN frames to signals and back through a make's DBC, with its checksums.

Decoding refuses what must not reach the car state: a frame shorter or longer than its DBC
length, a checksum that does not match, a payload cantools cannot decode. Each refusal is a
`FrameError` with a kind the agent counts ("length", "checksum", "decode").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, cast

import cantools

from vehicle_agent.dbc import load_dbc


class FrameError(ValueError):
    """A frame that must not be used; `kind` is what was wrong with it."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


class Checksum(Protocol):
    """A message's checksum: which signal carries it and how it is computed."""

    @property
    def signal(self) -> str:
        """The signal holding the checksum."""

    def compute(self, frame_id: int, data: bytes, signals: Mapping[str, float]) -> int:
        """The checksum for a payload; must ignore the checksum field's own bits."""


@dataclass(frozen=True)
class ToyotaChecksum:
    """Toyota's 8-bit sum in the last byte: the payload bytes before it, the length and the
    identifier's bytes, modulo 256 (checked against the recorded RAV4 SPEED frames)."""

    signal: str = "CHECKSUM"

    def compute(self, frame_id: int, data: bytes, signals: Mapping[str, float]) -> int:
        """Sum of id bytes, length and payload (without the last byte), modulo 256."""
        total = len(data) + sum(data[:-1])
        while frame_id:
            total += frame_id & 0xFF
            frame_id >>= 8
        return total & 0xFF


@dataclass(frozen=True)
class GmSteeringButtonChecksum:
    """GM Global A steering-wheel button checksum (12 bits): linear in the rolling counter, the
    ACC button code and the distance button, as observed on the powertrain bus."""

    signal: str = "SteeringButtonChecksum"

    def compute(self, frame_id: int, data: bytes, signals: Mapping[str, float]) -> int:
        """0xF0 + 0xF a + counter (0x4EF if a else 0x3F0) - (button - 1) * 16 - 2 distance."""
        always_one = int(signals.get("ACCAlwaysOne", 1))
        counter = int(signals.get("RollingCounter", 0))
        button = int(signals.get("ACCButtons", 1))
        distance = int(signals.get("DistanceButton", 0))
        value = 0xF0 + 0xF * always_one + counter * (0x4EF if always_one else 0x3F0)
        return (value - ((button - 1) << 4) - 2 * distance) & 0xFFF


class Codec:
    """Encode and decode one make's messages."""

    def __init__(
        self,
        dbc_name: str,
        database: cantools.database.can.Database,
        checksums: Mapping[str, Checksum],
    ) -> None:
        self.dbc_name = dbc_name
        self.database = database
        self.checksums = dict(checksums)
        self._by_name = {message.name: message for message in database.messages}
        self._by_id = {message.frame_id: message for message in database.messages}

    def frame_id(self, name: str) -> int:
        """The arbitration id of message `name`."""
        return int(self._by_name[name].frame_id)

    def length(self, name: str) -> int:
        """The DBC length of message `name` (bytes)."""
        return int(self._by_name[name].length)

    def encode(self, name: str, signals: Mapping[str, float]) -> bytes:
        """The payload for `signals` (missing signals are 0), checksum filled in."""
        message = self._by_name[name]
        values: dict[str, float] = {signal.name: 0 for signal in message.signals}
        values.update(signals)
        checksum = self.checksums.get(name)
        if checksum is None:
            return bytes(message.encode(values, strict=False))
        values[checksum.signal] = 0
        draft = bytes(message.encode(values, strict=False))
        values[checksum.signal] = checksum.compute(message.frame_id, draft, values)
        return bytes(message.encode(values, strict=False))

    def decode(self, frame_id: int, data: bytes | bytearray) -> tuple[str, dict[str, float]]:
        """(message name, physical signal values) of a frame, or FrameError."""
        message = self._by_id.get(frame_id)
        if message is None:
            raise FrameError("unknown", f"id {frame_id:#x} is not in {self.dbc_name}")
        if len(data) != message.length:
            raise FrameError(
                "length", f"{message.name}: {len(data)} bytes, the DBC says {message.length}"
            )
        try:
            signals = cast(dict[str, float], message.decode(bytes(data), decode_choices=False))
        except (ValueError, KeyError) as error:
            raise FrameError("decode", f"{message.name}: {error}") from None
        checksum = self.checksums.get(message.name)
        if checksum is not None:
            expected = checksum.compute(message.frame_id, bytes(data), signals)
            if int(signals[checksum.signal]) != expected:
                found = int(signals[checksum.signal])
                raise FrameError(
                    "checksum", f"{message.name}: checksum {found}, expected {expected}"
                )
        return str(message.name), signals


def codec_for(
    dbc_name: str, checksums: Mapping[str, Checksum], cache_dir: Path | None = None
) -> Codec:
    """A codec over the DBC `dbc_name`, shipped or generated from opendbc (parsed once per
    process)."""
    return Codec(dbc_name, load_dbc(dbc_name, cache_dir), checksums)
