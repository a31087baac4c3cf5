"""Streaming a MOTION file into batches of documents, memory bounded by the batch, not the file.

A published MOTION day is a JSON array of trajectory documents (one per vehicle fragment) of many
GB, so it is never loaded whole (`json.load`): `split_documents` reads the file in chunks and finds
where each top-level document begins and ends by tracking only JSON's structure (braces,
brackets, strings and their escapes; numbers, the bulk of the bytes, are skipped by one table
lookup in numpy), and `parse_batch` hands a batch of whole documents to Arrow's JSON reader with
the MOTION schema, which parses the number arrays straight into columns, in blocks on every core,
without a Python object per number (ijson's C backend, the streaming parser the bench measures as
its baseline, builds one per number on one core).

A batch and a single document are read by the same reader with the same schema, so whether a
document is accepted cannot depend on its neighbours: DuckDB's JSON reader, used for batches
before, cast a number written as a string ("1.5"), a boolean among the positions and a fraction
where MOTION has an integer (vehicle class 1.6 became 2), which a lone document was refused for.

A file may also hold one document per line (JSON lines): the same scanner splits both.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import BinaryIO

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
# Arrow parses a batch in blocks of this size, one per core at a time (a block is widened to the
# largest document: Arrow refuses a document longer than a block).
BLOCK_BYTES = 4 * 1024 * 1024
# A refused value is quoted in the reason up to this many characters.
VALUE_SHOWN_CHARS = 40

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
# Documents one per line (the batch of a JSON-lines file, or of compact documents) are cut into
# blocks at newlines; pretty-printed ones need the slower layout-aware reading.
_PARSE_ONE_PER_LINE = pa_json.ParseOptions(
    explicit_schema=DOCUMENT_SCHEMA, newlines_in_values=False, unexpected_field_behavior="ignore"
)
_PARSE_ANY_LAYOUT = pa_json.ParseOptions(
    explicit_schema=DOCUMENT_SCHEMA, newlines_in_values=True, unexpected_field_behavior="ignore"
)
# What MOTION writes for each type of the schema: the JSON values Arrow takes for it (bool is not
# an int here: `type(True)` is bool) and how a reason names it.
_JSON_KINDS: dict[pa.DataType, tuple[tuple[type, ...], str]] = {
    pa.float64(): ((int, float), "a number"),
    pa.int64(): ((int,), "an integer"),
    pa.bool_(): ((bool,), "true or false"),
    pa.string(): ((str,), "a string"),
}


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
    # Where the structure broke: `scan` stops there and returns the documents that closed
    # before it, which the caller hands out before raising this.
    broken: MotionFileError | None = None

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
                    self.broken = MotionFileError(position, f"'{chr(code)}' closes nothing")
                    return ends
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
    a document over MAX_DOCUMENT_BYTES, the file ending inside a document or inside its
    top-level array), after yielding every whole document before the break.
    """
    scanner = _Scanner()
    pending = bytearray()  # the file's bytes from `pending_at` on, not yet handed out
    pending_at = 0
    # Where content that is no object began since the last document (a number, a string, the
    # wrong file given): its bytes are dropped as they are scanned, so memory stays bounded
    # whatever the file holds, and it is counted once, when the next document or the file ends.
    stray_at: int | None = None
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
            if gap.strip(b"[]" + _BLANK) or stray_at is not None:
                where = consumed if stray_at is None else stray_at
                batch.bad.append(BadDocument(index, where, "not a JSON object"))
                index += 1
                stray_at = None
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
        if scanner.broken is not None:
            yield from _before_the_break(batch, consumed, scanner.broken)
        del pending[: consumed - pending_at]
        pending_at = consumed
        if scanner.start is None:  # between documents: nothing here is handed out
            if stray_at is None and pending.strip(b"[]" + _BLANK):
                stray_at = pending_at
            pending.clear()
            pending_at = read_so_far
        if scanner.start is not None and read_so_far - scanner.start > MAX_DOCUMENT_BYTES:
            yield from _before_the_break(
                batch,
                consumed,
                MotionFileError(
                    scanner.start, f"a document larger than {MAX_DOCUMENT_BYTES // 2**20} MB"
                ),
            )
    if stray_at is not None and scanner.start is None and not scanner.in_string:
        batch.bad.append(BadDocument(index, stray_at, "not a JSON object"))
    batch.bytes_read = read_so_far
    if batch.texts or batch.bad:
        yield batch
    if scanner.start is not None or scanner.in_string:
        where = scanner.start if scanner.start is not None else read_so_far
        raise MotionFileError(where, "the file ends inside a document")
    if scanner.top_depth == 1 and scanner.depth > 0:
        # between two documents of an array never closed: a file cut short read as whole
        raise MotionFileError(read_so_far, "the file ends inside its top-level array (cut short)")


def _before_the_break(
    batch: DocumentBatch, consumed: int, error: MotionFileError
) -> Iterator[DocumentBatch]:
    """Hand out the documents read before the structure broke, then raise `error`: the batch
    being built and the documents of the chunk the break is in were lost with the error, while
    the importer recorded the file as imported and said the documents before it were."""
    batch.bytes_read = consumed
    if batch.texts or batch.bad:
        yield batch
    raise error


def parse_batch(batch: DocumentBatch) -> tuple[pa.Table, list[int]]:
    """Parse a batch's documents into columns; return the table and each row's document index.

    The batch is read in one go. If any document is not a MOTION document (a value of the wrong
    type, a broken value), each document of the batch is read on its own by the same reader, so
    exactly the documents it refuses are refused, each with the reason of `_type_problem` (or
    Arrow's message when the document is not JSON at all), and the others are kept.
    """
    if not batch.texts:  # a batch of content that is no object only
        return DOCUMENT_SCHEMA.empty_table(), []
    try:
        return _read(batch.texts), list(batch.indices)
    except pa.ArrowInvalid:
        pass
    tables: list[pa.Table] = []
    indices: list[int] = []
    for index, offset, text in zip(batch.indices, batch.offsets, batch.texts, strict=True):
        try:
            tables.append(_read([text]))
        except pa.ArrowInvalid as error:
            reason = _type_problem(text) or str(error)
            batch.bad.append(BadDocument(index, offset, reason))
            continue
        indices.append(index)
    if not tables:
        return DOCUMENT_SCHEMA.empty_table(), []
    return pa.concat_tables(tables), indices


def _read(texts: list[bytes]) -> pa.Table:
    """Documents read by Arrow with the MOTION schema (fields outside it are ignored)."""
    text = b"\n".join(texts)
    options = pa_json.ReadOptions(block_size=max(BLOCK_BYTES, max(map(len, texts)) + 1))
    one_per_line = text.count(b"\n") == len(texts) - 1
    parse = _PARSE_ONE_PER_LINE if one_per_line else _PARSE_ANY_LAYOUT
    return pa_json.read_json(BytesIO(text), read_options=options, parse_options=parse)


def _type_problem(text: bytes) -> str | None:
    """The first value of a refused document whose JSON type is not MOTION's, in words.

    Arrow's own message gives a column path and "row 0" (the document's row in its own read),
    and for an integer field not even the field; an analyst fixing the file needs the field, the
    point and the value. None when the text is not JSON or has no such value.
    """
    try:
        document = json.loads(text)
    except ValueError:
        return None
    if not isinstance(document, dict):
        return None
    for schema_field in DOCUMENT_SCHEMA:
        if schema_field.name in document:
            problem = _mismatch(document[schema_field.name], schema_field.type, schema_field.name)
            if problem:
                return problem
    return None


def _mismatch(value: object, expected: pa.DataType, path: str) -> str | None:
    """Why `value` at `path` is not of the schema's type `expected` (None when it is; null is
    allowed anywhere: the import's own checks say what a missing value means)."""
    if value is None:
        return None
    if pa.types.is_list(expected):
        if not isinstance(value, list):
            return f"{path} is {_described(value)} where MOTION has an array"
        for position, item in enumerate(value):
            problem = _mismatch(item, expected.value_type, f"{path}[{position}]")
            if problem:
                return problem
        return None
    if pa.types.is_struct(expected):
        if not isinstance(value, dict):
            return f"{path} is {_described(value)} where MOTION has an object"
        for child in expected:
            if child.name in value:
                problem = _mismatch(value[child.name], child.type, f"{path}.{child.name}")
                if problem:
                    return problem
        return None
    kinds, name = _JSON_KINDS[expected]
    if type(value) not in kinds:
        return f"{path} is {_described(value)} where MOTION has {name}"
    return None


def _described(value: object) -> str:
    """A JSON value as a reason names it: its type and, if short, the value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        shown = json.dumps(value)
        if len(shown) > VALUE_SHOWN_CHARS:
            shown = shown[: VALUE_SHOWN_CHARS - 4] + '..."'
        return f"a string ({shown})"
    if isinstance(value, int | float):
        return f"the number {value!r}"
    return "an array" if isinstance(value, list) else "an object"


def open_motion_file(path: Path) -> BinaryIO:
    """The file opened for reading in binary; a missing or unreadable file says which."""
    try:
        return path.open("rb")
    except OSError as error:
        raise MotionFileError(0, f"cannot read {path}: {error.strerror}") from None
