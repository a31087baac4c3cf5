"""Splitting a MOTION file into whole documents without loading it."""

from __future__ import annotations

import io
import json
import tracemalloc

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.motion.documents import MotionFileError, split_documents


def _documents(data: bytes, chunk_bytes: int = 7) -> list[dict[str, object]]:
    found = []
    for batch in split_documents(io.BytesIO(data), batch_bytes=50, chunk_bytes=chunk_bytes):
        assert not batch.bad
        for text, offset in zip(batch.texts, batch.offsets, strict=True):
            assert data[offset : offset + len(text)] == text
            found.append(json.loads(text))
    return found


def test_an_array_of_documents_split_across_tiny_chunks() -> None:
    docs = [{"_id": {"$oid": "a"}, "x_position": [1.5, 2]}, {"_id": {"$oid": "b"}}]
    assert _documents(json.dumps(docs, indent=1).encode()) == docs


def test_json_lines_are_split_too() -> None:
    docs = [{"a": [1, [2]]}, {"b": {"c": {}}}]
    assert _documents(b"\n".join(json.dumps(d).encode() for d in docs) + b"\n") == docs


def test_braces_quotes_and_backslashes_inside_strings_do_not_count() -> None:
    docs = [{"note": 'a } b { "c" \\ ] ['}, {"note": "\\\\"}, {"note": 'x\\"}'}]
    assert _documents(json.dumps(docs).encode(), chunk_bytes=3) == docs


@settings(max_examples=60, deadline=None)
@given(
    docs=st.lists(
        st.dictionaries(
            st.text(max_size=5),
            st.recursive(
                st.none() | st.booleans() | st.floats(allow_nan=False) | st.text(max_size=8),
                lambda inner: (
                    st.lists(inner, max_size=3)
                    | st.dictionaries(st.text(max_size=3), inner, max_size=3)
                ),
                max_leaves=8,
            ),
            max_size=4,
        ),
        max_size=6,
    ),
    chunk_bytes=st.integers(min_value=1, max_value=40),
    indent=st.sampled_from([None, 1]),
)
def test_any_array_of_objects_comes_back_document_by_document(
    docs: list[dict[str, object]], chunk_bytes: int, indent: int | None
) -> None:
    assert _documents(json.dumps(docs, indent=indent).encode(), chunk_bytes) == docs


def test_an_item_that_is_not_an_object_is_a_bad_document_and_the_rest_are_kept() -> None:
    data = b'[{"a": 1}, 17, "text", {"b": 2}]'
    batches = list(split_documents(io.BytesIO(data), chunk_bytes=5))
    bad = [entry for batch in batches for entry in batch.bad]
    texts = [text for batch in batches for text in batch.texts]
    assert texts == [b'{"a": 1}', b'{"b": 2}']
    assert [(entry.index, entry.reason) for entry in bad] == [(1, "not a JSON object")]


def test_content_between_documents_is_not_held_in_memory() -> None:
    """A large array of numbers (the wrong file given) was buffered whole until a document
    ended: 988 MB for a 396 MB file (analytics audit). Now it is dropped as it is scanned and
    counted once, where it began."""
    numbers = b"[" + b",".join([b"123456.789"] * 800_000) + b', {"a": 1}, 5]'  # 8.8 MB
    tracemalloc.start()
    try:
        batches = list(split_documents(io.BytesIO(numbers), chunk_bytes=2**20))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 4 * 2**20, peak  # a few chunks, not the file
    texts = [text for batch in batches for text in batch.texts]
    bad = [(entry.index, entry.offset, entry.reason) for batch in batches for entry in batch.bad]
    assert texts == [b'{"a": 1}']
    end_of_document = numbers.index(b'{"a"') + len(b'{"a": 1}')
    assert bad == [(0, 0, "not a JSON object"), (2, end_of_document, "not a JSON object")]


def test_a_file_cut_inside_a_document_says_where_after_the_whole_ones() -> None:
    data = b'[{"a": 1}, {"b": [1, 2'
    stream = split_documents(io.BytesIO(data), chunk_bytes=4)
    assert next(stream).texts == [b'{"a": 1}']
    with pytest.raises(MotionFileError, match="byte 11: the file ends inside a document"):
        next(stream)


def test_a_closing_bracket_without_its_opening_is_refused() -> None:
    with pytest.raises(MotionFileError, match="'}' closes nothing"):
        list(split_documents(io.BytesIO(b'{"a": 1}}')))


def read_texts(stream: io.BytesIO, chunk_bytes: int, texts: list[bytes]) -> None:
    """Every document's text into `texts`, as far as the file lets `split_documents` go."""
    for batch in split_documents(stream, chunk_bytes=chunk_bytes):
        texts.extend(batch.texts)


@pytest.mark.parametrize("chunk_bytes", [4, 2**20])
def test_the_documents_before_a_break_are_handed_out_before_it_is_raised(
    chunk_bytes: int,
) -> None:
    """A break ("closes nothing", a document over the size limit) raised out of the scan with
    the documents of its chunk and the batch being built: lost, while the importer recorded
    the file and said the documents before the break were imported."""
    data = b'[{"a": 1}, {"b": 2}, {"c": 3}]]'
    texts: list[bytes] = []
    with pytest.raises(MotionFileError, match=f"byte {len(data) - 1}: ']' closes nothing"):
        read_texts(io.BytesIO(data), chunk_bytes, texts)
    assert texts == [b'{"a": 1}', b'{"b": 2}', b'{"c": 3}']


def test_a_file_cut_between_two_documents_of_its_array_is_refused_after_them() -> None:
    """A file cut right after a document's closing brace imported as whole, exit 0."""
    data = b'[{"a": 1}, {"b": 2},'
    texts: list[bytes] = []
    with pytest.raises(MotionFileError, match="ends inside its top-level array"):
        read_texts(io.BytesIO(data), 2**20, texts)
    assert texts == [b'{"a": 1}', b'{"b": 2}']
