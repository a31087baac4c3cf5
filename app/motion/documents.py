"""Streaming a MOTION file into batches of documents, memory bounded by the batch, not the file.

A published MOTION day is a JSON array of trajectory documents (one per vehicle fragment) of many
GB, so it is never loaded whole (`json.load`): `split_documents` reads the file in chunks and finds
where each top-level document begins and ends by tracking only JSON's structure (braces,
brackets, strings and their escapes; numbers, the bulk of the bytes, are skipped by one table
lookup in numpy), and `parse_batch` hands a batch of whole documents to DuckDB's JSON reader, which
parses the number arrays straight into columns, on every core, without a Python object per
number (ijson's C backend, the streaming parser the bench measures as its baseline, builds one
per number on one core).

A file may also hold one document per line (JSON lines): the same scanner splits both.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import BinaryIO

import duckdb
import numpy as np
import pyarrow as pa
import pyarrow.json as pa_json
from numpy.typing import NDArray

# Read this much of the file at a time.
CHUNK_BYTES = 16 * 1024 * 1024
# A batch is parsed once its documents hold this many bytes of JSON (a few M points).
BATCH_BYTES = 48 * 1024 * 1024
# One vehicle fragment is a few hundred kB; a "document" beyond this is refused, not buffered.
MAX_DOCUMENT_BYTES = 256 * 1024 * 1024

_OPEN_BRACE, _CLOSE_BRACE, _OPEN_BRACKET = ord("{"), ord("}"), ord("[")
_QUOTE, _BACKSLASH = ord('"'), ord("\\")
_OPENING = frozenset((ord("{"), ord("[")))
_CLOSING = frozenset((ord("}"), ord("]")))
_STRUCTURAL = np.zeros(256, dtype=bool)
_STRUCTURAL[[ord(char) for char in '{}[]"\\']] = True
_BLANK = b" \t\r\n,"

# The fields the import reads, as Arrow types (others in the documents are ignored).
DOCUMENT_SCHEMA = pa.schema(
    [
        pa.field("_id", pa.struct([pa.field("$oid", pa.string())])),
        pa.field("timestamp", pa.list_(pa.float64())),
        pa.field("x_position", pa.list_(pa.float64())),
        pa.field("y_position", pa.list_(pa.float64())),
        pa.field("length", pa.float64()),
        pa.field("width", pa.float64()),
        pa.field("height", pa.float64()),
        pa.field("coarse_vehicle_class", pa.int64()),
        pa.field("direction", pa.int64()),
        pa.field("x_score", pa.float64()),
        pa.field("y_score", pa.float64()),
        pa.field("flags", pa.list_(pa.string())),
        pa.field("smoothfleet_fleet", pa.bool_()),
    ]
)
_PARSE_OPTIONS = pa_json.ParseOptions(
    explicit_schema=DOCUMENT_SCHEMA, newlines_in_values=True, unexpected_field_behavior="ignore"
)
_DUCKDB_TYPES = {
    pa.float64(): "DOUBLE",
    pa.int64(): "BIGINT",
    pa.bool_(): "BOOLEAN",
    pa.list_(pa.float64()): "DOUBLE[]",
    pa.list_(pa.string()): "VARCHAR[]",
    pa.struct([pa.field("$oid", pa.string())]): 'STRUCT("$oid" VARCHAR)',
}
_DUCKDB_COLUMNS = (
    "{" + ", ".join(f"'{f.name}': '{_DUCKDB_TYPES[f.type]}'" for f in DOCUMENT_SCHEMA) + "}"
)


class MotionFileError(ValueError):
    """The file's JSON structure is broken at a byte offset; documents before it are whole."""

    def __init__(self, offset: int, reason: str) -> None:
        super().__init__(f"byte {offset}: {reason}")
        self.offset = offset
        self.reason = reason


@dataclass(frozen=True, slots=True)
class BadDocument:
    """A document the import refused, with where it starts in the file and why."""

    index: int
    offset: int
    reason: str


@dataclass(slots=True)
class DocumentBatch:
    """Whole documents from the file, in order: their index, where each starts, its JSON."""

    indices: list[int] = field(default_factory=list)
    offsets: list[int] = field(default_factory=list)
    texts: list[bytes] = field(default_factory=list)
    bad: list[BadDocument] = field(default_factory=list)
    bytes_read: int = 0


@dataclass(slots=True)
class _Scanner:
    """JSON structure state carried from one chunk to the next (offsets are in the file)."""

    depth: int = 0
    in_string: bool = False
    escaped_at: int = -1  # the byte after a backslash inside a string
    top_depth: int | None = None  # 1 inside a top-level array, 0 for JSON lines
    start: int | None = None  # where the current document began

    def scan(self, chunk: bytes, chunk_at: int) -> list[tuple[int, int]]:
        """(start, end) of every top-level object that closes in this chunk."""
        ends: list[tuple[int, int]] = []
        # The structural bytes are found by one table lookup over the whole chunk; only they
        # (a few dozen per document, against tens of thousands of number bytes) reach Python.
        found = np.flatnonzero(_STRUCTURAL[np.frombuffer(chunk, dtype=np.uint8)])
        for offset, code in zip(found.tolist(), chunk_codes(chunk, found), strict=True):
            position = chunk_at + offset
            if self.in_string:
                if position == self.escaped_at:
                    continue
                if code == _BACKSLASH:
                    self.escaped_at = position + 1
                elif code == _QUOTE:
                    self.in_string = False
                continue
            if code == _QUOTE:
                self.in_string = True
            elif code in _OPENING:
                if self.top_depth is None:
                    self.top_depth = 1 if code == _OPEN_BRACKET else 0
                if code == _OPEN_BRACE and self.depth == self.top_depth:
                    self.start = position
                self.depth += 1
            elif code in _CLOSING:
                self.depth -= 1
                if self.depth < 0:
                    raise MotionFileError(position, f"'{chr(code)}' closes nothing")
                if code == _CLOSE_BRACE and self.depth == self.top_depth and self.start is not None:
                    ends.append((self.start, position + 1))
                    self.start = None
        return ends


def chunk_codes(chunk: bytes, offsets: NDArray[np.intp]) -> list[int]:
    """The byte values at `offsets`."""
    codes: list[int] = np.frombuffer(chunk, dtype=np.uint8)[offsets].tolist()
    return codes


def split_documents(
    stream: BinaryIO, batch_bytes: int = BATCH_BYTES, chunk_bytes: int = CHUNK_BYTES
) -> Iterator[DocumentBatch]:
    """Yield batches of whole top-level documents read from `stream`, in file order.

    Raises MotionFileError where the structure breaks (a closing bracket without its opening,
    or the file ending inside a document); the batches yielded before are complete.
    """
    scanner = _Scanner()
    pending = bytearray()  # the file's bytes from `pending_at` on, not yet handed out
    pending_at = 0
    index = 0
    batch = DocumentBatch()
    batch_size = 0
    read_so_far = 0
    while chunk := stream.read(chunk_bytes):
        ends = scanner.scan(chunk, read_so_far)
        read_so_far += len(chunk)
        pending += chunk
        view = memoryview(pending)
        consumed = pending_at
        for start, end in ends:
            gap = bytes(view[consumed - pending_at : start - pending_at]).strip(_BLANK)
            if gap.strip(b"[]" + _BLANK):
                batch.bad.append(BadDocument(index, consumed, "not a JSON object"))
                index += 1
            batch.indices.append(index)
            batch.offsets.append(start)
            batch.texts.append(bytes(view[start - pending_at : end - pending_at]))
            batch_size += end - start
            index += 1
            consumed = end
            if batch_size >= batch_bytes:
                batch.bytes_read = consumed
                yield batch
                batch = DocumentBatch()
                batch_size = 0
        view.release()
        del pending[: consumed - pending_at]
        pending_at = consumed
        if scanner.start is not None and read_so_far - scanner.start > MAX_DOCUMENT_BYTES:
            raise MotionFileError(
                scanner.start, f"a document larger than {MAX_DOCUMENT_BYTES // 2**20} MB"
            )
    if pending.strip(b"[]" + _BLANK) and scanner.start is None and not scanner.in_string:
        batch.bad.append(BadDocument(index, pending_at, "not a JSON object"))
    batch.bytes_read = read_so_far
    if batch.texts or batch.bad:
        yield batch
    if scanner.start is not None or scanner.in_string:
        where = scanner.start if scanner.start is not None else read_so_far
        raise MotionFileError(where, "the file ends inside a document")


def parse_batch(batch: DocumentBatch, scratch: Path) -> tuple[pa.Table, list[int]]:
    """Parse a batch's documents into columns; return the table and each row's document index.

    DuckDB's JSON reader parses the batch (written to `scratch`, a file of the import's own
    staging folder); it is several times faster than Arrow's on these number arrays. If any
    document is not a MOTION document (a string among the positions, a broken value), each
    document of the batch is read on its own with Arrow, whose message becomes the refused
    document's reason, and the others are kept.
    """
    text = b"\n".join(batch.texts)
    scratch.write_bytes(text)
    try:
        table = _read_with_duckdb(scratch, one_per_line=text.count(b"\n") == len(batch.texts) - 1)
        return table, list(batch.indices)
    except duckdb.Error:
        pass
    finally:
        scratch.unlink()
    tables: list[pa.Table] = []
    indices: list[int] = []
    for index, offset, text in zip(batch.indices, batch.offsets, batch.texts, strict=True):
        try:
            tables.append(_read(text))
        except pa.ArrowInvalid as error:
            batch.bad.append(BadDocument(index, offset, str(error)))
            continue
        indices.append(index)
    if not tables:
        return DOCUMENT_SCHEMA.empty_table(), []
    return pa.concat_tables(tables), indices


def _read_with_duckdb(path: Path, *, one_per_line: bool) -> pa.Table:
    """The documents of a file (one per line, or any layout) in the MOTION schema."""
    layout = "newline_delimited" if one_per_line else "unstructured"
    escaped = str(path).replace("'", "''")
    query = (
        f"SELECT * FROM read_json('{escaped}', format = '{layout}', columns = {_DUCKDB_COLUMNS}, "
        f"maximum_object_size = {MAX_DOCUMENT_BYTES})"
    )
    with duckdb.connect(":memory:") as connection:
        return connection.sql(query).to_arrow_table().cast(DOCUMENT_SCHEMA)


def _read(text: bytes) -> pa.Table:
    """One document read by Arrow with the MOTION schema."""
    options = pa_json.ReadOptions(block_size=len(text) + 1, use_threads=False)
    return pa_json.read_json(BytesIO(text), read_options=options, parse_options=_PARSE_OPTIONS)


def open_motion_file(path: Path) -> BinaryIO:
    """The file opened for reading in binary; a missing or unreadable file says which."""
    try:
        return path.open("rb")
    except OSError as error:
        raise MotionFileError(0, f"cannot read {path}: {error.strerror}") from None
