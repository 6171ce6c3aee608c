"""Helpers of the service tests: collecting Zenoh samples and reports, waiting, checking
reports, feeding an engine."""

from __future__ import annotations

import math
import re
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson
import zenoh

from service.schemas import TrackOut, TrackReportOut

if TYPE_CHECKING:
    from service.engine import Engine
    from service.ingest import IngestResult

TRACK_REQUIRED: dict[str, type | tuple[type, ...]] = {
    "id": str,
    "kind": str,
    "status": str,
    "time": float,
    "position": list,
    "velocity": list,
    "covariance": list,
    "score": float,
    "hits": int,
    "created": float,
    "updated": float,
    "model_probabilities": dict,
    "detection_ids": list,
}
TRACK_OPTIONAL = {
    "extent",
    "attitude",
    "shape_probabilities",
    "members",
    "formation_id",
}


class Collector:
    """Collects the payloads (and keys) of every sample on ``key``."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self.items: list[tuple[str, bytes]] = []
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(key, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        item = (str(sample.key_expr), sample.payload.to_bytes())
        with self._cond:
            self.items.append(item)
            self._cond.notify_all()

    def wait_for(self, n: int, timeout: float = 10.0) -> list[tuple[str, bytes]]:
        """Wait until at least ``n`` samples arrived; return them all."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while len(self.items) < n:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"got {len(self.items)} samples, expected {n}")
                self._cond.wait(left)
            return list(self.items)

    def json(self) -> list[dict[str, Any]]:
        with self._cond:
            return [orjson.loads(p) for _, p in self.items]

    def close(self) -> None:
        self._sub.undeclare()


def wait_until(pred: Callable[[], bool], timeout: float = 10.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


def declare_publisher(session: zenoh.Session, key: str, timeout: float = 5.0) -> zenoh.Publisher:
    """A reliable BLOCK publisher, once a subscriber matches it."""
    pub = session.declare_publisher(
        key,
        encoding=zenoh.Encoding.APPLICATION_JSON,
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )
    status = lambda: bool(pub.matching_status.matching)  # type: ignore[attr-defined]  # noqa: E731
    wait_until(status, timeout, f"a subscriber on {key}")
    return pub


def check_track(track: dict[str, Any]) -> None:
    """Every contract field is present with the right type; nothing else."""
    for name, kind in TRACK_REQUIRED.items():
        assert name in track, f"track misses {name}"
        value = track[name]
        if kind is float:
            assert isinstance(value, float | int) and not isinstance(value, bool), name
            assert math.isfinite(value), name
        else:
            assert isinstance(value, kind), f"{name}: {type(value).__name__}"
    assert set(track) <= set(TRACK_REQUIRED) | TRACK_OPTIONAL, set(track)
    assert track["kind"] in ("individual", "extended", "formation")
    assert track["status"] in ("tentative", "confirmed")
    assert len(track["position"]) == 2 and len(track["velocity"]) == 2
    cov = np.array(track["covariance"], dtype=float)
    assert cov.shape == (4, 4)
    assert np.allclose(cov, cov.T, atol=1e-6 * (1 + np.abs(cov).max()))
    assert all(isinstance(d, str) for d in track["detection_ids"])
    assert all(isinstance(v, float | int) for v in track["model_probabilities"].values())
    TrackOut.model_validate(track)


def check_report(report: dict[str, Any]) -> None:
    assert set(report) == {"seq", "time", "sensor_id", "processing_ms", "tracks", "deleted"}
    assert isinstance(report["seq"], int) and report["seq"] >= 1
    assert isinstance(report["time"], float)
    assert isinstance(report["sensor_id"], str)
    assert isinstance(report["processing_ms"], float) and report["processing_ms"] >= 0
    assert isinstance(report["deleted"], list)
    for track in report["tracks"]:
        check_track(track)
        assert track["status"] == "confirmed"
    TrackReportOut.model_validate(report)


def match_truth(
    tracks: list[dict[str, Any]], truth: np.ndarray, sigmas: float = 5.0, floor: float = 5.0
) -> tuple[int, list[float]]:
    """How many truth positions ``(k, 2+)`` have a track within ``sigmas`` of its position
    standard deviation (at least ``floor`` m); each track used once (greedy by distance)."""
    if not tracks or truth.size == 0:
        return 0, []
    pos = np.array([t["position"] for t in tracks])
    std = np.array(
        [math.sqrt(max(np.linalg.eigvalsh(np.array(t["covariance"])[:2, :2]))) for t in tracks]
    )
    d = np.linalg.norm(pos[:, None, :] - truth[None, :, :2], axis=2)
    used_t: set[int] = set()
    used_g: set[int] = set()
    errors: list[float] = []
    for flat in np.argsort(d, axis=None):
        i, j = np.unravel_index(flat, d.shape)
        if i in used_t or j in used_g:
            continue
        if d[i, j] > max(sigmas * std[i], floor):
            continue
        used_t.add(int(i))
        used_g.add(int(j))
        errors.append(float(d[i, j]))
    return len(used_g), errors


class ListSink:
    """A report sink that keeps every report, decoded."""

    def __init__(self) -> None:
        self.tracks: list[dict[str, Any]] = []
        self.errors: list[tuple[str, dict[str, Any]]] = []
        self._lock = threading.Lock()

    def publish_tracks(self, data: bytes) -> None:
        with self._lock:
            self.tracks.append(orjson.loads(data))

    def publish_error(self, sensor_id: str, data: bytes) -> None:
        with self._lock:
            self.errors.append((sensor_id, orjson.loads(data)))


def batch_payload(scan: Any, **changes: Any) -> bytes:
    """A simulated scan as a Detection batch's JSON, with some fields changed."""
    return orjson.dumps({**scan.to_batch(), **changes})


def run_batches(
    engine: Engine, payloads: list[bytes], key: str | None = "radar-1"
) -> list[IngestResult]:
    """Submit ``payloads`` and wait for what became of each."""
    futures = [engine.submit(p, key, "test") for p in payloads]
    return [f.result(timeout=30) for f in futures]


_LABEL = r'[a-zA-Z_][a-zA-Z0-9_]*="(?:[^"\\\n]|\\[\\"n])*"'
PROM_LINE = re.compile(
    rf"^(?P<name>[a-zA-Z_:][a-zA-Z0-9_:]*)(\{{(?P<labels>{_LABEL}(,{_LABEL})*)\}})? "
    r"(?P<value>\S+)$"
)


def parse_prometheus(text: str) -> dict[str, float]:
    """A strict little parser of the text format: HELP/TYPE before samples, valid names."""
    samples: dict[str, float] = {}
    typed: dict[str, str] = {}
    for line in text.splitlines():
        if not line:
            continue
        if line.startswith("# HELP "):
            continue
        if line.startswith("# TYPE "):
            _, _, name, kind = line.split(" ", 3)
            assert kind in ("counter", "gauge", "summary", "histogram", "untyped"), line
            typed[name] = kind
            continue
        assert not line.startswith("#"), line
        m = PROM_LINE.match(line)
        assert m, f"not a sample line: {line!r}"
        name = m["name"]
        base = re.sub(r"_(sum|count|bucket)$", "", name)
        assert name in typed or base in typed, f"{name} has no TYPE"
        if typed.get(name) == "counter":
            assert name.endswith("_total"), name
        samples[name + ((m["labels"] and "{" + m["labels"] + "}") or "")] = float(m["value"])
    return samples
