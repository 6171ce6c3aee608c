"""Fuzzing the batch decoder: payload bytes, through a running engine with the real tracking
pipeline, to a Track report or an Error report.

The rule checked for every payload hypothesis makes, valid, broken, hostile or random: it
has exactly one outcome (accepted with one Track report, or refused with exactly one Error
report of a known reason); a refused payload changes no track; the counters agree (received
= processed + rejected + dropped); and what is accepted, a strict reading of the JSON (no
duplicate key, no NaN, no unknown field, every number within its bounds) takes too.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from typing import Any

import orjson
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from service.engine import Engine
from service.schemas import ERROR_REASONS, DetectionBatchIn, ErrorReportOut, IngestConfig

from .helpers import ListSink

pytestmark = pytest.mark.timeout(300)

SENSOR = "fuzz-1"
MAX_DETECTIONS = 40
MAX_BYTES = 16 * 1024
HUGE = "1" + "0" * 399

_BATCH_FIELDS = set(DetectionBatchIn.model_fields)
_DETECTION_FIELDS = {"x", "y", "cov", "vr", "amplitude", "id"}


@pytest.fixture(scope="module")
def fuzzed() -> Iterator[tuple[Engine, ListSink, list[bytes]]]:
    """The engine, its reports, and the payloads it accepted."""
    sink = ListSink()
    eng = Engine(
        sink=sink,
        ingest=IngestConfig(max_detections_per_batch=MAX_DETECTIONS, max_time_jump=100.0),
        max_batch_bytes=MAX_BYTES,
    )
    eng.start()
    try:
        yield eng, sink, []
    finally:
        eng.stop()


_NUMBER = st.floats(-2e4, 2e4, allow_nan=False)
_JSON = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**63 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=6),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner),
    max_leaves=12,
)


@st.composite
def _detection(draw: st.DrawFn) -> dict[str, Any]:
    det: dict[str, Any] = {"x": draw(_NUMBER), "y": draw(_NUMBER)}
    if draw(st.booleans()):
        a, d = draw(st.floats(1.0, 400.0)), draw(st.floats(1.0, 400.0))
        b = draw(st.floats(-0.9, 0.9)) * math.sqrt(a * d)
        det["cov"] = [[a, b], [b, d]]
    if draw(st.booleans()):
        det["vr"] = draw(st.floats(-500, 500))
    if draw(st.booleans()):
        det["amplitude"] = draw(st.floats(-50, 50))
    if draw(st.booleans()):
        det["id"] = draw(st.text(max_size=12))
    return det


@st.composite
def _batch(draw: st.DrawFn, time: float) -> dict[str, Any]:
    batch: dict[str, Any] = {
        "sensor_id": SENSOR,
        "time": time,
        "detections": draw(st.lists(_detection(), max_size=12)),
        "sensor_position": [0.0, 0.0],
    }
    if draw(st.booleans()):
        batch["pd"] = draw(st.floats(0.05, 1.0))
    if draw(st.booleans()):
        batch["clutter_density"] = draw(st.floats(1e-9, 1e-3))
    return batch


def _replace_number(text: bytes, literal: bytes, data: st.DataObject) -> bytes:
    """One number of ``text`` (a key's value) written as ``literal``."""
    keys = [k for k in (b'"x":', b'"y":', b'"time":', b'"vr":', b'"pd":') if k in text]
    if not keys:
        return text
    key = data.draw(st.sampled_from(keys))
    head, _, tail = text.partition(key)
    end = 0
    while end < len(tail) and tail[end : end + 1] not in b",}]":
        end += 1
    return head + key + literal + tail[end:]


@st.composite
def _payload(draw: st.DrawFn, time: float, last_payload: bytes | None) -> bytes:
    data = draw(st.data())
    batch = draw(_batch(time))
    text = orjson.dumps(batch)
    kind = draw(
        st.sampled_from(
            [
                "valid",
                "valid",
                "valid",
                "field",
                "detection_field",
                "unknown",
                "duplicate_key",
                "number",
                "truncated",
                "bytes",
                "json",
                "deep",
                "many",
                "large",
                "again",
            ]
        )
    )
    if kind == "valid":
        return text
    if kind == "field":
        name = draw(st.sampled_from(sorted(_BATCH_FIELDS)))
        return orjson.dumps({**batch, name: draw(_JSON)})
    if kind == "detection_field" and batch["detections"]:
        i = draw(st.integers(0, len(batch["detections"]) - 1))
        name = draw(st.sampled_from(sorted(_DETECTION_FIELDS)))
        batch["detections"][i] = {**batch["detections"][i], name: draw(_JSON)}
        return orjson.dumps(batch)
    if kind == "unknown":
        return orjson.dumps({**batch, draw(st.text(min_size=1, max_size=5)): draw(_JSON)})
    if kind == "duplicate_key":
        key = draw(st.sampled_from([b'"time":', b'"sensor_id":', b'"x":', b'"detections":']))
        if key in text:
            value = {b'"time":': b"1.5", b'"sensor_id":': b'"fuzz-1"', b'"x":': b"3"}
            return text.replace(key, key + value.get(key, b"[]") + b"," + key, 1)
        return text
    if kind == "number":
        literal = draw(
            st.sampled_from([HUGE, "-" + HUGE, "1e999", "NaN", "-Infinity", "1e300", "5e-324"])
        )
        return _replace_number(text, literal.encode(), data)
    if kind == "truncated":
        return text[: draw(st.integers(0, max(len(text) - 1, 0)))]
    if kind == "bytes":
        return draw(st.binary(max_size=200))
    if kind == "json":
        return orjson.dumps(draw(_JSON))
    if kind == "deep":
        depth = draw(st.integers(1, 5000))
        return b'{"sensor_id": "fuzz-1", "time": 1, "detections": ' + b"[" * depth
    if kind == "many":
        n = draw(st.integers(MAX_DETECTIONS + 1, 3 * MAX_DETECTIONS))
        return orjson.dumps({**batch, "detections": [{"x": 1.0, "y": 2.0}] * n})
    if kind == "large":
        return orjson.dumps({**batch, "detections": [], "pad": "x" * MAX_BYTES})
    if kind == "again" and last_payload is not None:
        return last_payload
    return text


def _strict(payload: bytes) -> dict[str, Any]:
    """The payload read strictly: no duplicate key, no NaN or Infinity."""

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        keys = [k for k, _ in items]
        assert len(set(keys)) == len(keys), f"duplicate key in {keys}"
        return dict(items)

    def constant(name: str) -> Any:
        raise AssertionError(f"{name} accepted")

    obj = json.loads(payload, object_pairs_hook=pairs, parse_constant=constant)
    assert isinstance(obj, dict)
    return obj


def _check_accepted(payload: bytes) -> None:
    obj = _strict(payload)
    assert set(obj) <= _BATCH_FIELDS
    assert abs(obj["time"]) <= 1e12
    assert len(obj["detections"]) <= MAX_DETECTIONS
    for det in obj["detections"]:
        assert set(det) <= _DETECTION_FIELDS
        assert abs(det["x"]) <= 1e9 and abs(det["y"]) <= 1e9
    assert len(payload) <= MAX_BYTES


def _state(engine: Engine) -> tuple[int, bytes, Any]:
    return engine.seq, engine.latest_report_bytes(), engine.tracks("all")["tracks"]


@settings(
    max_examples=250,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(data=st.data())
def test_every_payload_has_one_outcome_and_a_refusal_changes_nothing(
    fuzzed: tuple[Engine, ListSink, list[bytes]], data: st.DataObject
) -> None:
    engine, sink, accepted = fuzzed
    last = engine.latest_report()["time"]
    # mostly newer, sometimes older, now and then too far ahead
    step = st.integers(0, 9).flatmap(
        lambda k: st.just(1000.0) if k == 0 else st.floats(-2.0 if k == 1 else 0.0, 10.0)
    )
    time = data.draw(step.map(lambda dt: dt if last is None else last + dt), label="time")
    payload = data.draw(_payload(time, accepted[-1] if accepted else None), label="payload")
    key = data.draw(st.sampled_from([SENSOR, SENSOR, None, "fuzz-2"]), label="key")

    before = _state(engine)
    tracks_before, errors_before = len(sink.tracks), len(sink.errors)
    received_before = engine.stats.snapshot()["batches_received"]

    result = engine.submit(payload, key, "fuzz").result(timeout=60)
    event("accepted" if result.accepted else (result.error or {}).get("error", "?"))

    if result.accepted:
        assert result.error is None and result.seq == before[0] + 1
        assert len(sink.tracks) == tracks_before + 1 and len(sink.errors) == errors_before
        assert sink.tracks[-1]["seq"] == result.seq
        _check_accepted(payload)
        accepted.append(payload)
    else:
        report = result.error
        assert report is not None and report["error"] in ERROR_REASONS
        ErrorReportOut.model_validate(report)
        assert report["received_bytes"] == len(payload)
        assert len(sink.errors) == errors_before + 1 and sink.errors[-1][1] == report
        assert len(sink.tracks) == tracks_before
        assert _state(engine) == before  # no track changed
    stats = engine.stats.snapshot()
    assert stats["batches_received"] == received_before + 1
    assert stats["batches_received"] == (
        stats["batches_processed"] + stats["batches_rejected"] + stats["batches_dropped"]
    )
