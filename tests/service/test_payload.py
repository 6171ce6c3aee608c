"""What a payload costs, read from its bytes: the structural counts (exact, against a walk of
the parsed document, whatever the strings and escapes hold), the refusals before parsing and
what they spare, and the duplicate keys a JSON parser would hide."""

from __future__ import annotations

import json
import math
import random
import tracemalloc
from typing import Any

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.ingest import check_batch
from service.payload import (
    DEFAULT_MAX_BATCH_BYTES,
    Shape,
    check_cost,
    duplicate_key_detail,
    duplicate_keys,
    max_keys,
    max_values,
    shape,
    shape_bound,
)
from service.schemas import BatchError, IngestConfig, decode_batch
from trackers.coverage import MAX_VERTICES


def _walk(doc: Any) -> Shape:
    """The counts of a parsed document, as :func:`shape` reads them from its text."""
    objects = arrays = commas = colons = 0
    stack = [doc]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            objects += 1
            colons += len(node)
            commas += max(len(node) - 1, 0)
            stack.extend(node.values())
        elif isinstance(node, list):
            arrays += 1
            commas += max(len(node) - 1, 0)
            stack.extend(node)
    return Shape(objects, arrays, commas, colons)


#: Strings with everything that could fool a byte count: quotes, backslashes, the four
#: structural characters, unicode.
_TEXT = st.text(alphabet=st.sampled_from(list('ab"\\{[,:}] \n\u00e9\u2603')), max_size=8)
_JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | _TEXT,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(_TEXT, inner, max_size=4),
    max_leaves=25,
)


@settings(max_examples=300, deadline=None)
@given(doc=_JSON, style=st.sampled_from(["compact", "ascii", "indent"]))
def test_shape_counts_exactly_what_the_document_holds(doc: Any, style: str) -> None:
    if style == "compact":
        text = json.dumps(doc, separators=(",", ":"), ensure_ascii=False).encode()
    elif style == "ascii":  # non-ASCII characters as \\u escapes
        text = json.dumps(doc, ensure_ascii=True).encode()
    else:
        text = json.dumps(doc, indent=2, ensure_ascii=False).encode()
    exact = shape(text)
    assert exact == _walk(json.loads(text))
    bound = shape_bound(text)
    for name in ("objects", "arrays", "commas", "colons"):
        assert getattr(bound, name) >= getattr(exact, name)
    assert exact.values >= 1


def test_shape_of_what_is_no_json() -> None:
    assert shape(b'{"a": "b}') is None  # a string not closed
    assert shape(b'{"a\\": 1}') is None  # the quote is escaped: still not closed
    assert shape(b'{"a\\\\": 1}') == Shape(1, 0, 0, 1)  # an escaped backslash, then the quote
    assert shape(b"") == Shape(0, 0, 0, 0)


def _full(i: int, id_length: int = 100) -> dict[str, Any]:
    """A detection with every field, every number at full precision."""
    rnd = random.Random(i)
    a, b = rnd.uniform(10, 99), rnd.uniform(-1, 1)
    return {
        "x": -rnd.uniform(1e5, 9e5),
        "y": -rnd.uniform(1e5, 9e5),
        "cov": [[a, b], [b, a + 0.123456789]],
        "vr": -rnd.uniform(100, 300),
        "amplitude": rnd.uniform(10, 99),
        "id": f"{i:08d}".ljust(id_length, "x"),
    }


def _batch(dets: list[dict[str, Any]], **extra: Any) -> dict[str, Any]:
    return {
        "sensor_id": "radar-1",
        "time": 1234567890.123456,
        "detections": dets,
        "cov": [[25.5, 0.25], [0.25, 25.5]],
        "sensor_position": [-123456.789, 987654.321],
        "sensor_velocity": [-123.456789, 98.7654321],
        "max_range": 123456.789,
        "coverage": [
            [123456.789 * math.cos(a), 987654.321 * math.sin(a)]
            for a in np.linspace(0.0, 2.0 * np.pi, MAX_VERTICES, endpoint=False).tolist()
        ],
        "pd": 0.9,
        "clutter_density": 1.5e-6,
        **extra,
    }


@pytest.fixture(scope="module")
def full_batch() -> bytes:
    """10,000 detections (the default limit) with every field and 100-character ids."""
    return orjson.dumps(_batch([_full(i) for i in range(10_000)]))


def test_the_default_limits_take_a_full_batch(full_batch: bytes) -> None:
    assert len(full_batch) < DEFAULT_MAX_BATCH_BYTES
    exact = shape(full_batch)
    assert exact is not None
    assert exact.values == max_values(10_000)  # every field there: the bound is tight
    assert exact.colons == max_keys(10_000)
    check_cost(full_batch, 10_000)
    batch = check_batch(full_batch, "radar-1", IngestConfig())
    assert len(batch.detections) == 10_000


def test_too_many_detections_are_refused_before_parsing() -> None:
    """A payload under the size limit that holds 250,000 detections is refused from its
    bytes: validating it would build every detection (over 200 MB)."""
    payload = orjson.dumps(_batch([{"x": 0, "y": 0}] * 250_000))
    assert len(payload) < DEFAULT_MAX_BATCH_BYTES
    tracemalloc.start()
    try:
        with pytest.raises(BatchError) as info:
            check_batch(payload, None, IngestConfig())
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert info.value.reason == "too_many_detections"
    assert info.value.detail == (
        "detections: 250000 detections, more than ingest.max_detections_per_batch = 10000"
    )
    assert peak < 32 * 1024 * 1024, peak  # the counting's own arrays, not the batch


@pytest.mark.parametrize(
    ("payload", "detail"),
    [
        # two million values in a list of detections: each would be an error
        (
            orjson.dumps({"sensor_id": "a", "time": 1.0, "detections": [0] * 2_000_000}),
            "3 keys and up to 2000004 JSON values, more than a batch of 0 detections",
        ),
        # one detection of 60,000 unknown keys
        (
            orjson.dumps(
                {"sensor_id": "a", "time": 1.0, "detections": [{f"k{i}": 0 for i in range(60_000)}]}
            ),
            "60003 keys and up to 60005 JSON values, more than a batch of 1 detections",
        ),
        # nested a million deep
        (b"[" * 1_000_000, "0 keys and up to 1000001 JSON values"),
    ],
)
def test_more_values_or_keys_than_a_batch_can_hold(payload: bytes, detail: str) -> None:
    with pytest.raises(BatchError) as info:
        check_cost(payload, 10_000)
    assert info.value.reason == "invalid_batch"
    assert detail in info.value.detail


def test_structure_in_strings_is_not_counted() -> None:
    """Ids full of braces, commas and colons: over the byte counts' bounds, within the exact
    ones."""
    dets = [{"x": 1.0, "y": 2.0, "id": "{[,:" * 4} for _ in range(50)]
    payload = orjson.dumps({"sensor_id": "a", "time": 1.0, "detections": dets})
    assert shape_bound(payload).objects - 1 > 60
    check_cost(payload, 60)
    with pytest.raises(BatchError) as info:
        check_cost(payload, 49)
    assert info.value.reason == "too_many_detections"
    assert info.value.detail.startswith("detections: 50 detections")
    unclosed = b'{"sensor_id": "a", "detections": [' + b'{"x": 1, "y": 2, "id": "{{{{{{{{{{"},' * 9
    with pytest.raises(BatchError) as bad:
        check_cost(unclosed + b'"', 5)
    assert (bad.value.reason, bad.value.detail) == (
        "invalid_json",
        "invalid JSON: a string is not closed",
    )


@pytest.mark.parametrize(
    ("payload", "dropped", "named"),
    [
        (b'{"sensor_id": "a", "time": 1, "detections": []}', 0, None),
        (b'{"sensor_id": "a", "time": 1, "time": 2, "detections": []}', 1, "time"),
        (b'{"sensor_id": "a", "time": 1, "detections": [{"x": 1, "y": 2, "x": 3}]}', 1, "x"),
        # the same key written as an escape
        (b'{"sensor_id": "a", "time": 1, "detections": [{"x": 1, "y": 2, "\\u0078": 3}]}', 1, "x"),
        # colons in ids, written as they are or as escapes, are no keys
        (b'{"sensor_id": "a", "time": 1, "detections": [{"x": 1, "y": 2, "id": "a:b:"}]}', 0, None),
        (
            b'{"sensor_id": "a", "time": 1, "detections": [{"x": 1, "y": 2, "id": "a\\u003a"}]}',
            0,
            None,
        ),
        (
            b'{"sensor_id": "a", "time": 1, "detections": '
            b'[{"x": 1, "y": 2, "id": "a\\u003A", "y": 5}, {"x": 1, "y": 2, "y": 3}]}',
            2,
            "y",
        ),
    ],
)
def test_duplicate_keys(payload: bytes, dropped: int, named: str | None) -> None:
    batch = decode_batch(payload)  # the parser takes them, the last one winning
    assert duplicate_keys(payload, batch) == dropped
    if named is not None:
        assert duplicate_key_detail(payload, dropped) == (
            f"duplicate key {named!r} in one object (a JSON parser keeps only the last)"
        )
        with pytest.raises(BatchError) as info:
            check_batch(payload, None, IngestConfig())
        assert info.value.reason == "invalid_batch"
        assert info.value.detail == duplicate_key_detail(payload, dropped)
    else:
        check_batch(payload, None, IngestConfig())


def test_a_large_payload_counts_its_duplicates_without_naming_them(full_batch: bytes) -> None:
    payload = full_batch.replace(b'"pd":0.9', b'"pd":0.9,"pd":0.8', 1)
    batch = decode_batch(payload)
    assert batch.pd == 0.8
    assert duplicate_keys(payload, batch) == 1
    assert duplicate_key_detail(payload, 1) == (
        "1 duplicate key(s) (a JSON parser keeps only the last of each)"
    )
