"""Wire models <-> tracker types.

:func:`batch_to_scan` turns a validated :class:`~service.schemas.DetectionBatchIn` into a
:class:`~trackers.types.Scan` with its arrays built in one go; :func:`track_to_dict` and
:func:`report_dict` turn tracker snapshots into the contract's Track and Track report shapes
(plain dicts, ready for orjson). Optional Track fields that do not apply are left out.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np
import orjson

from service.schemas import DetectionBatchIn, DetectionIn
from trackers.coverage import Coverage
from trackers.types import Scan, StepResult, TrackSnapshot

__all__ = [
    "batch_to_scan",
    "dumps",
    "empty_report",
    "error_report",
    "report_dict",
    "track_to_dict",
]

_NAN = math.nan


def batch_to_scan(batch: DetectionBatchIn, position_std: float) -> Scan:
    """The batch as a Scan. Each detection's covariance is its own ``cov``, else the batch's
    ``cov``, else ``position_std² I``; range-rates and amplitudes are NaN where absent (and the
    arrays are ``None`` when no detection has one); its coverage from ``coverage`` and
    ``max_range``."""
    dets = batch.detections
    n = len(dets)
    if batch.cov is not None:
        default: Any = batch.cov
    else:
        var = float(position_std) ** 2
        default = ((var, 0.0), (0.0, var))
    if n == 0:
        z = np.empty((0, 2))
        R = np.empty((0, 2, 2))
        return Scan(
            sensor_id=batch.sensor_id,
            time=batch.time,
            z=z,
            R=R,
            detection_ids=(),
            pd=batch.pd,
            clutter_density=batch.clutter_density,
            sensor_position=_opt_array(batch.sensor_position),
            sensor_velocity=_opt_array(batch.sensor_velocity),
            coverage=_coverage(batch),
        )
    z = np.array([(d["x"], d["y"]) for d in dets], dtype=float)
    R = np.array([d.get("cov") or default for d in dets], dtype=float)
    range_rate = _optional(dets, "vr")
    amplitude = _optional(dets, "amplitude")
    return Scan(
        sensor_id=batch.sensor_id,
        time=batch.time,
        z=z,
        R=R,
        detection_ids=tuple(d.get("id") for d in dets),
        pd=batch.pd,
        clutter_density=batch.clutter_density,
        sensor_position=_opt_array(batch.sensor_position),
        sensor_velocity=_opt_array(batch.sensor_velocity),
        coverage=_coverage(batch),
        range_rate=range_rate,
        amplitude=amplitude,
    )


def _coverage(batch: DetectionBatchIn) -> Coverage | None:
    """The batch's ``coverage`` polygon and ``max_range`` about ``sensor_position`` (both
    validated), or ``None`` when it gives neither."""
    if batch.coverage is None and batch.max_range is None:
        return None
    return Coverage(
        polygon=None if batch.coverage is None else np.array(batch.coverage, dtype=float),
        centre=_opt_array(batch.sensor_position),
        max_range=batch.max_range,
    )


def _optional(dets: list[DetectionIn], name: str) -> np.ndarray | None:
    """The detections' ``name`` values (NaN where absent), or ``None`` if none has one."""
    values = [d.get(name) for d in dets]
    if not any(v is not None for v in values):
        return None
    return np.array([_NAN if v is None else v for v in values], dtype=float)


def _opt_array(value: tuple[float, float] | None) -> np.ndarray | None:
    return None if value is None else np.array(value, dtype=float)


def _floats(values: Iterable[Any]) -> list[float]:
    return [float(v) for v in values]


def track_to_dict(t: TrackSnapshot) -> dict[str, Any]:
    """One Track as the contract's JSON object (optional fields only when present).

    Called for every confirmed track of every batch, so it does as little as it can: the
    tracker's snapshots already hold plain Python numbers, and ``float``/``list`` only copy
    what might be a numpy scalar or a tuple.
    """
    out: dict[str, Any] = {
        "id": t.id,
        "kind": t.kind,
        "status": t.status,
        "time": float(t.time),
        "position": [float(t.position[0]), float(t.position[1])],
        "velocity": [float(t.velocity[0]), float(t.velocity[1])],
        "covariance": np.asarray(t.covariance, dtype=float).tolist(),
        "score": float(t.score),
        "hits": int(t.hits),
        "created": float(t.created),
        "updated": float(t.updated),
        "model_probabilities": dict(t.model_probabilities or {}),
        "detection_ids": [d for d in t.detection_ids if d is not None],
    }
    if t.extent is not None:
        out["extent"] = {
            "matrix": np.asarray(t.extent.matrix, dtype=float).tolist(),
            "semi_axes": _floats(t.extent.semi_axes),
            "orientation": float(t.extent.orientation),
        }
    if t.attitude is not None:
        out["attitude"] = float(t.attitude)
    if t.shape_probabilities is not None:
        out["shape_probabilities"] = {str(k): float(v) for k, v in t.shape_probabilities.items()}
    if t.members is not None:
        out["members"] = [str(m) for m in t.members]
    if t.formation_id is not None:
        out["formation_id"] = str(t.formation_id)
    return out


def report_dict(
    seq: int, result: StepResult, processing_ms: float, tracks: list[dict[str, Any]]
) -> dict[str, Any]:
    """The Track report of one processed batch; ``tracks`` are the confirmed tracks as dicts."""
    return {
        "seq": seq,
        "time": float(result.time),
        "sensor_id": result.sensor_id,
        "processing_ms": round(float(processing_ms), 4),
        "tracks": tracks,
        "deleted": [str(d) for d in result.deleted],
    }


def empty_report() -> dict[str, Any]:
    """The answer before any batch has been processed."""
    return {
        "seq": 0,
        "time": None,
        "sensor_id": None,
        "processing_ms": 0.0,
        "tracks": [],
        "deleted": [],
    }


def error_report(
    sensor_id: str, time: float | None, error: str, detail: str, received_bytes: int
) -> dict[str, Any]:
    """The contract's Error report."""
    return {
        "sensor_id": sensor_id,
        "time": time,
        "error": error,
        "detail": detail,
        "received_bytes": int(received_bytes),
    }


def dumps(obj: Any) -> bytes:
    """JSON bytes (numpy values allowed; NaN becomes null)."""
    return orjson.dumps(obj, option=orjson.OPT_SERIALIZE_NUMPY)
