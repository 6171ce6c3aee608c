"""What a Detection batch payload costs, read from its bytes before anything parses it, and
what a JSON parser would hide in it.

Parsing and validating cost time and memory in proportion to how many JSON values and keys a
payload holds, not to its size alone: four megabytes of ``{"x":0,"y":0},`` are 300,000
detections. So before the parser runs, :func:`check_cost` counts the payload's objects,
arrays, commas and colons. A byte count (:func:`shape_bound`: one pass of ``bytes.translate``
keeps the quotes and those four characters, then each is counted) is an upper bound, since
strings may hold them too; when it is within the limits the batch goes on. Otherwise
:func:`shape` counts them exactly, outside strings (a few passes of numpy over what the first
pass kept), and the batch is refused when a valid batch of that many detections could not
hold so much. What passes costs the parser and the validator at most what a valid batch of
``ingest.max_detections_per_batch`` detections with every field does. Counting costs about
a tenth of validating: 6 ms for 10,000 full detections (3 MB), when validating them takes 50.

JSON parsers keep the last of two equal keys in an object; :func:`duplicate_keys` finds the
pairs they dropped by comparing the payload's ``key: value`` separators with the fields the
validated batch has.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from itertools import repeat
from typing import Any

import numpy as np

from service.schemas import BatchError, DetectionBatchIn
from trackers.coverage import MAX_VERTICES

__all__ = [
    "DEFAULT_MAX_BATCH_BYTES",
    "DEFAULT_QUEUE_BYTES",
    "MAX_KEYS_PER_BATCH",
    "MAX_KEYS_PER_DETECTION",
    "MAX_VALUES_PER_BATCH",
    "MAX_VALUES_PER_DETECTION",
    "Shape",
    "check_cost",
    "duplicate_key_detail",
    "duplicate_keys",
    "max_keys",
    "max_values",
    "shape",
    "shape_bound",
    "too_large_detail",
]

#: The default ``max_batch_bytes``: 4 MiB holds 10,000 detections (the default
#: ``ingest.max_detections_per_batch``) with full covariances, range-rates, amplitudes and
#: 100-character ids, every number at full precision (3.0 MB).
DEFAULT_MAX_BATCH_BYTES = 4 * 1024 * 1024
#: The default ``ingest_queue_bytes``: payload bytes waiting for the tracker at most.
DEFAULT_QUEUE_BYTES = 32 * 1024 * 1024

#: JSON values of one detection at most: the object, x, y, the covariance (a list of two
#: lists of two numbers: 7 values), vr, amplitude and id.
MAX_VALUES_PER_DETECTION = 13
#: JSON values of a batch besides its detections at most: the object, sensor_id, time, the
#: detections list, cov (7), sensor_position (3), sensor_velocity (3), max_range, coverage
#: (a list of up to MAX_VERTICES lists of two numbers), pd and clutter_density.
MAX_VALUES_PER_BATCH = 21 + 3 * MAX_VERTICES
#: Keys of a detection and of a batch at most: their fields.
MAX_KEYS_PER_DETECTION = 6
MAX_KEYS_PER_BATCH = 10

_QUOTE = ord('"')
_KEEP = b'"{[,:'
_DELETE = bytes(b for b in range(256) if b not in _KEEP)
_STRUCTURAL = np.frombuffer(b"{[,:", dtype=np.uint8)  # in the order of Shape's fields
#: Payloads up to this size have their duplicate key named (a slower parse, on refusal only).
_NAME_DUPLICATES_UP_TO = 256 * 1024


@dataclass(frozen=True)
class Shape:
    """Counts of a JSON document's structural characters: ``objects`` (``{``), ``arrays``
    (``[``), ``commas`` and ``colons`` (one per ``key: value`` pair)."""

    objects: int
    arrays: int
    commas: int
    colons: int

    @property
    def values(self) -> int:
        """An upper bound on the document's values: each non-empty container holds one more
        element than it has commas, and the document itself is one."""
        return 1 + self.commas + self.objects + self.arrays


def too_large_detail(size: int, limit: int) -> str:
    """The Error report's detail for a payload of ``size`` bytes over ``limit``."""
    return f"payload: {size} bytes, more than max_batch_bytes = {limit}"


def max_values(detections: int) -> int:
    """The most JSON values a valid batch of ``detections`` detections holds."""
    return MAX_VALUES_PER_DETECTION * detections + MAX_VALUES_PER_BATCH


def max_keys(detections: int) -> int:
    """The most ``key: value`` pairs a valid batch of ``detections`` detections holds."""
    return MAX_KEYS_PER_DETECTION * detections + MAX_KEYS_PER_BATCH


def _reduce(payload: bytes) -> bytes:
    """The payload's quotes and the four structural characters, nothing else (one pass)."""
    return payload.translate(None, _DELETE)


def _count(reduced: bytes) -> Shape:
    return Shape(reduced.count(b"{"), reduced.count(b"["), reduced.count(b","), reduced.count(b":"))


def shape_bound(payload: bytes) -> Shape:
    """Upper bounds of :func:`shape`: the characters counted in strings too."""
    return _count(_reduce(payload))


def shape(payload: bytes) -> Shape | None:
    """The structural characters of ``payload``, counted outside strings; ``None`` when its
    quotes do not pair, so that it is no JSON.

    Escapes go first (``\\\\`` pairs, then ``\\"``, left to right as JSON reads them), so that
    every quote left opens or closes a string; then everything but quotes and the four
    characters is deleted, and the characters between an opening quote and the next are
    marked as inside a string. Cost: a few passes over the payload in C."""
    if b"\\" in payload:
        payload = payload.replace(b"\\\\", b"").replace(b'\\"', b"")
    return _exact(_reduce(payload))


def _exact(reduced: bytes) -> Shape | None:
    chars = np.frombuffer(reduced, dtype=np.uint8)
    quotes = np.flatnonzero(chars == _QUOTE)
    if quotes.size % 2:
        return None
    if quotes.size:
        # runs of characters, from 0, at each quote, to the end: outside, inside, outside...
        edges = np.empty(quotes.size + 2, dtype=np.intp)
        edges[0], edges[-1] = 0, chars.size
        edges[1:-1] = quotes
        inside = np.zeros(quotes.size + 1, dtype=np.uint8)
        inside[1::2] = 0x80  # moves a character inside a string out of the four
        chars = chars | np.repeat(inside, np.diff(edges))
    return Shape(*(int(np.count_nonzero(chars == c)) for c in _STRUCTURAL))


def check_cost(payload: bytes, max_detections: int) -> Shape | None:
    """Refuse a payload that holds more detections, JSON values or keys than a valid batch of
    at most ``max_detections`` detections, before it is parsed: raise
    :class:`~service.schemas.BatchError` (``too_many_detections``, ``invalid_batch`` or
    ``invalid_json``). A payload within those bounds costs the parser and the validator at
    most what a batch of ``max_detections`` full detections does. Returns the payload's
    exact :func:`shape` when it had to be counted (for :func:`duplicate_keys`), else ``None``.

    A payload of at most ``2 (max_detections + 1)`` bytes passes uncounted: it cannot hold
    more objects or values than that (each takes two bytes or more), nor cost more."""
    if len(payload) <= 2 * (max_detections + 1):
        return None
    reduced = _reduce(payload)
    bound = _count(reduced)
    if (
        bound.objects - 1 <= max_detections
        and bound.values <= max_values(max_detections)
        and bound.colons <= max_keys(max(bound.objects - 1, 0))
    ):
        return None
    exact = shape(payload) if b"\\" in payload else _exact(reduced)
    if exact is None:
        raise BatchError("invalid_json", "invalid JSON: a string is not closed")
    detections = exact.objects - 1  # every object but the batch is a detection
    if detections > max_detections:
        raise BatchError(
            "too_many_detections",
            f"detections: {detections} detections, more than ingest.max_detections_per_batch "
            f"= {max_detections}",
        )
    detections = max(detections, 0)
    if exact.values > max_values(detections) or exact.colons > max_keys(detections):
        raise BatchError(
            "invalid_batch",
            f"the payload holds {exact.colons} keys and up to {exact.values} JSON values, "
            f"more than a batch of {detections} detections can (unknown fields, repeated "
            "keys or overlong lists)",
        )
    return exact


def _string_colons(batch: DetectionBatchIn) -> int:
    """Colons in the batch's strings (its sensor id has none), counted in C."""
    ids = filter(None, map(dict.get, batch.detections, repeat("id")))
    return "".join(ids).count(":")  # type: ignore[arg-type]


def duplicate_keys(payload: bytes, batch: DetectionBatchIn, exact: Shape | None = None) -> int:
    """How many ``key: value`` pairs of ``payload`` its parser dropped because their key was
    repeated in the same object (``batch`` is ``payload`` validated, with no unknown field;
    ``exact``: its :func:`shape`, if counted already).

    Every colon outside strings separates one pair, and every pair that survived parsing is
    a field the batch or one of its detections has set. Colons inside strings are those of the
    detection ids, as long as none was written as ``\\u003a``; when one was, the colons are
    counted outside strings (:func:`shape`)."""
    pairs = len(batch.model_fields_set) + sum(map(len, batch.detections))
    if exact is not None:
        return max(exact.colons - pairs, 0)
    colons = payload.count(b":")
    if colons == pairs:
        return 0
    if b"\\u003a" in payload or b"\\u003A" in payload:
        counted = shape(payload)
        structural = colons if counted is None else counted.colons
    else:
        structural = colons - _string_colons(batch)
    return max(structural - pairs, 0)


def duplicate_key_detail(payload: bytes, count: int) -> str:
    """The Error report's detail for a payload with ``count`` duplicate keys: the first
    repeated key by name when the payload is small enough to parse again cheaply."""
    name = _first_duplicate(payload) if len(payload) <= _NAME_DUPLICATES_UP_TO else None
    if name is not None:
        return f"duplicate key {name!r} in one object (a JSON parser keeps only the last)"
    return f"{count} duplicate key(s) (a JSON parser keeps only the last of each)"


class _Duplicate(Exception):
    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _Duplicate(key)
        out[key] = value
    return out


def _first_duplicate(payload: bytes) -> str | None:
    try:
        json.loads(payload, object_pairs_hook=_no_duplicates)
    except _Duplicate as dup:
        return dup.key
    except (ValueError, RecursionError):
        return None
    return None
