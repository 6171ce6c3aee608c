"""Detection batch validation at the edge, conversion to tracker types, and report shapes."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import orjson
import pytest

from service.convert import batch_to_scan, report_dict, track_to_dict
from service.schemas import (
    MAX_ABS_AMPLITUDE,
    MAX_ABS_RANGE_RATE,
    MAX_ID_LENGTH,
    BatchError,
    DetectionBatchIn,
    TrackOut,
    TrackReportOut,
    decode_batch,
)
from trackers.pipeline import MAX_ABS_POSITION, MAX_ABS_TIME, MAX_VARIANCE
from trackers.types import Extent, StepResult, TrackSnapshot

CONTRACT_EXAMPLE: dict[str, Any] = {
    "sensor_id": "radar-1",
    "time": 12.0,
    "detections": [
        {"x": 10.0, "y": -3.5, "cov": [[25, 0], [0, 25]], "vr": 3.1, "amplitude": 12.0, "id": "d17"}
    ],
    "cov": [[25, 0], [0, 25]],
    "sensor_position": [0.0, 0.0],
    "pd": 0.9,
    "clutter_density": 2.5e-6,
}


def _batch(**changes: Any) -> dict[str, Any]:
    base: dict[str, Any] = {
        "sensor_id": "radar-1",
        "time": 1.0,
        "detections": [{"x": float(i), "y": 2.0 * i} for i in range(5)],
    }
    base.update(changes)
    return base


def _det(i: int, **changes: Any) -> dict[str, Any]:
    dets: list[dict[str, Any]] = [{"x": float(k), "y": 1.0} for k in range(5)]
    dets[i] = {**dets[i], **changes}
    return _batch(detections=dets)


def test_contract_example_passes() -> None:
    batch = decode_batch(orjson.dumps(CONTRACT_EXAMPLE))
    assert batch.sensor_id == "radar-1"
    assert batch.detections[0]["vr"] == 3.1
    assert batch.detections[0]["id"] == "d17"
    assert batch.pd == 0.9


@pytest.mark.parametrize(
    "payload",
    [
        _batch(),
        _batch(detections=[]),
        _batch(time=-5),
        _batch(sensor_id="a" * 64),
        _batch(sensor_id="A.b_c-9"),
        _batch(pd=1.0),
        _batch(cov=[[4, 1], [1, 4]]),
        _batch(sensor_position=[1, 2], detections=[{"x": 1, "y": 2, "vr": -3}]),
        _batch(sensor_position=[1, 2], sensor_velocity=[-150.5, 20]),
        _batch(sensor_position=[1, 2], max_range=30e3),
        _batch(coverage=[[0, 0], [1e4, 0], [1e4, 1e4], [0, 1e4]]),
    ],
)
def test_good_batches_pass(payload: dict[str, Any]) -> None:
    decode_batch(orjson.dumps(payload))


BAD: list[tuple[bytes, str, str]] = [
    (b"{not json", "invalid_json", "invalid JSON"),
    (b"", "invalid_json", "invalid JSON"),
    (b"[1, 2]", "invalid_batch", "must be a JSON object"),
    (orjson.dumps(_batch(sensor_id=None)), "invalid_batch", "sensor_id: not a string"),
    (orjson.dumps({"time": 1.0, "detections": []}), "invalid_batch", "sensor_id: missing"),
    (orjson.dumps({"sensor_id": "r", "detections": []}), "invalid_batch", "time: missing"),
    (orjson.dumps({"sensor_id": "r", "time": 1.0}), "invalid_batch", "detections: missing"),
    (orjson.dumps(_batch(detections=[{"y": 1.0}])), "invalid_batch", "detections[0].x: missing"),
    (
        b'{"sensor_id": "r", "time": 1, "detections": [{"x": 1, "y": 1}, {"x": 1, "y": 1}, '
        b'{"x": 1, "y": 1}, {"x": NaN, "y": 1}]}',
        "invalid_batch",
        "detections[3].x: not a finite number",
    ),
    (
        b'{"sensor_id": "r", "time": Infinity, "detections": []}',
        "invalid_batch",
        "time: not a finite number",
    ),
    (
        b'{"sensor_id": "r", "time": 1, "detections": [{"x": 1, "y": -1e999}]}',
        "invalid_batch",
        "detections[0].y: not a finite number",
    ),
    (orjson.dumps(_batch(time="12.0")), "invalid_batch", "time: not a number"),
    (orjson.dumps(_det(2, x=True)), "invalid_batch", "detections[2].x: not a number"),
    (
        orjson.dumps(_det(1, cov=[[1, 2], [2, 1]])),
        "invalid_batch",
        "detections[1].cov: not symmetric positive definite",
    ),
    (
        orjson.dumps(_det(1, cov=[[1, 0.5], [0, 1]])),
        "invalid_batch",
        "detections[1].cov: not symmetric positive definite",
    ),
    (
        orjson.dumps(_det(0, cov=[[-1, 0], [0, -1]])),
        "invalid_batch",
        "detections[0].cov: not symmetric positive definite",
    ),
    (orjson.dumps(_det(0, cov=[[1, 0]])), "invalid_batch", "detections[0].cov[1]: missing"),
    (
        orjson.dumps(_det(0, cov=[625, 0, 0, 625])),
        "invalid_batch",
        "detections[0].cov: too many items (at most 2) (a cov is a 2x2 matrix,"
        " [[var_x, cov_xy], [cov_xy, var_y]] in m²)",
    ),
    (orjson.dumps(_batch(cov=[625, 0])), "invalid_batch", "[[var_x, cov_xy], [cov_xy, var_y]]"),
    (
        orjson.dumps(_batch(cov=[[0, 0], [0, 0]])),
        "invalid_batch",
        "cov: not symmetric positive definite",
    ),
    (
        orjson.dumps(_det(4, vr=2.0)),
        "invalid_batch",
        "detections[4].vr: needs the batch's sensor_position",
    ),
    (
        orjson.dumps(_batch(sensor_velocity=[200.0, 0.0])),
        "invalid_batch",
        "sensor_velocity: needs the batch's sensor_position",
    ),
    (
        b'{"sensor_id": "r", "time": 1, "detections": [], "sensor_position": [0, 0],'
        b' "sensor_velocity": [1, NaN]}',
        "invalid_batch",
        "sensor_velocity",
    ),
    (
        orjson.dumps(_batch(sensor_position=[0, 0], sensor_velocity=[1.0])),
        "invalid_batch",
        "sensor_velocity",
    ),
    (
        orjson.dumps(_batch(max_range=3e4)),
        "invalid_batch",
        "max_range: needs the batch's sensor_position",
    ),
    (
        orjson.dumps(_batch(sensor_position=[0, 0], max_range=0)),
        "invalid_batch",
        "max_range: must be > 0",
    ),
    (
        orjson.dumps(_batch(coverage=[[0, 0], [1, 1]])),
        "invalid_batch",
        "coverage: too few items (at least 3)",
    ),
    (
        orjson.dumps(_batch(coverage=[[0, 0], [1, 1], [2, 2]])),
        "invalid_batch",
        "coverage: the polygon encloses no area",
    ),
    (
        orjson.dumps(_batch(coverage=[[0, 0], [1, 0], [1, 2e9]])),
        "invalid_batch",
        "coverage[2][1]: must be <= 1e+09",
    ),
    (orjson.dumps(_batch(pd=0)), "invalid_batch", "pd: must be > 0"),
    (orjson.dumps(_batch(pd=1.5)), "invalid_batch", "pd: must be <= 1"),
    (orjson.dumps(_batch(clutter_density=0)), "invalid_batch", "clutter_density: must be > 0"),
    (orjson.dumps(_batch(clutter_density=-1e-6)), "invalid_batch", "clutter_density"),
    (orjson.dumps(_batch(colour="red")), "invalid_batch", "colour: unknown field"),
    (orjson.dumps(_det(3, z=1.0)), "invalid_batch", "detections[3].z: unknown field"),
    (orjson.dumps(_batch(sensor_id="")), "invalid_batch", "sensor_id: must be 1 to 64"),
    (orjson.dumps(_batch(sensor_id="a" * 65)), "invalid_batch", "sensor_id: must be 1 to 64"),
    (orjson.dumps(_batch(sensor_id="radar/1")), "invalid_batch", "sensor_id: must be 1 to 64"),
    (orjson.dumps(_batch(sensor_id="r*")), "invalid_batch", "sensor_id: must be 1 to 64"),
    (orjson.dumps(_batch(detections={"x": 1})), "invalid_batch", "detections: not a list"),
    (orjson.dumps(_det(0, id=17)), "invalid_batch", "detections[0].id: not a string"),
    (orjson.dumps(_batch(sensor_position=[0])), "invalid_batch", "sensor_position[1]: missing"),
]


@pytest.mark.parametrize(("payload", "reason", "detail"), BAD)
def test_bad_batches_are_refused_with_the_place(payload: bytes, reason: str, detail: str) -> None:
    with pytest.raises(BatchError) as info:
        decode_batch(payload)
    assert info.value.reason == reason
    assert detail in info.value.detail, info.value.detail


def test_detail_names_the_detection_exactly() -> None:
    dets = [{"x": 1.0, "y": 1.0} for _ in range(5)]
    payload = orjson.dumps(_batch(detections=dets)).replace(b'"x":1.0', b'"x":NaN', 4)
    payload = payload.replace(b'"x":NaN', b'"x":1.0', 3)
    with pytest.raises(BatchError) as info:
        decode_batch(payload)
    assert info.value.detail == "detections[3].x: not a finite number"


def test_covariance_precedence_and_arrays() -> None:
    batch = decode_batch(
        orjson.dumps(
            {
                "sensor_id": "s",
                "time": 3.0,
                "detections": [
                    {"x": 1, "y": 2, "cov": [[9, 1], [1, 9]], "id": "a", "vr": 1.5},
                    {"x": 3, "y": 4, "amplitude": 7.0},
                ],
                "cov": [[4, 0], [0, 4]],
                "sensor_position": [10, 20],
            }
        )
    )
    scan = batch_to_scan(batch, position_std=10.0)
    assert scan.z.tolist() == [[1, 2], [3, 4]]
    assert scan.R.tolist() == [[[9, 1], [1, 9]], [[4, 0], [0, 4]]]
    assert scan.detection_ids == ("a", None)
    assert scan.range_rate is not None and scan.range_rate[0] == 1.5
    assert math.isnan(scan.range_rate[1])
    assert scan.amplitude is not None and math.isnan(scan.amplitude[0])
    assert scan.amplitude[1] == 7.0
    assert scan.sensor_position is not None and scan.sensor_position.tolist() == [10, 20]
    assert scan.sensor_velocity is None  # a sensor at rest unless the batch says otherwise
    moving = batch_to_scan(
        decode_batch(orjson.dumps(_batch(sensor_position=[1, 2], sensor_velocity=[-150, 20]))),
        10.0,
    )
    assert moving.sensor_velocity is not None and moving.sensor_velocity.tolist() == [-150, 20]
    assert moving.subset(np.arange(5) < 2).sensor_velocity.tolist() == [-150, 20]
    assert moving.coverage is None  # a batch that says nothing of its coverage
    looked = batch_to_scan(
        decode_batch(
            orjson.dumps(
                _batch(sensor_position=[0, 0], max_range=100.0, coverage=[[0, 0], [50, 0], [0, 50]])
            )
        ),
        10.0,
    )
    assert looked.coverage is not None and not looked.coverage.learned
    inside = looked.coverage.contains(np.array([[10.0, 10.0], [40.0, 40.0], [-5.0, 5.0]]))
    assert inside.tolist() == [True, False, False]

    no_cov = batch_to_scan(decode_batch(orjson.dumps(_batch())), position_std=3.0)
    assert no_cov.R.shape == (5, 2, 2)
    assert np.allclose(no_cov.R, np.diag([9.0, 9.0]))
    assert no_cov.range_rate is None and no_cov.amplitude is None

    empty = batch_to_scan(decode_batch(orjson.dumps(_batch(detections=[]))), 10.0)
    assert empty.size == 0 and empty.R.shape == (0, 2, 2)


def test_fifty_detections_convert_to_arrays() -> None:
    rng = np.random.default_rng(1)
    xy = rng.uniform(-1000, 1000, (50, 2))
    payload = orjson.dumps(
        {
            "sensor_id": "radar-1",
            "time": 12.0,
            "detections": [
                {"x": float(x), "y": float(y), "cov": [[25.0, 0.0], [0.0, 25.0]], "id": f"d{i}"}
                for i, (x, y) in enumerate(xy)
            ],
            "sensor_position": [0.0, 0.0],
            "pd": 0.9,
            "clutter_density": 1e-6,
        }
    )
    scan = batch_to_scan(decode_batch(payload), 10.0)
    assert scan.size == 50
    assert np.array_equal(scan.z, xy)
    assert np.array_equal(scan.R, np.broadcast_to(np.diag([25.0, 25.0]), (50, 2, 2)))
    assert list(scan.detection_ids) == [f"d{i}" for i in range(50)]
    assert scan.pd == 0.9 and scan.clutter_density == 1e-6


def _snapshot(**changes: Any) -> TrackSnapshot:
    base: dict[str, Any] = {
        "id": "T1",
        "kind": "individual",
        "status": "confirmed",
        "time": np.float64(2.0),
        "position": (np.float64(1.0), 2.0),
        "velocity": (3.0, 4.0),
        "covariance": np.eye(4),
        "score": 9.5,
        "hits": np.int64(3),
        "created": 0.0,
        "updated": 2.0,
        "model_probabilities": {"cv": 0.9, "ct": 0.1},
        "detection_ids": ("d1",),
    }
    base.update(changes)
    return TrackSnapshot(**base)


def test_track_dict_omits_absent_optional_fields() -> None:
    d = track_to_dict(_snapshot())
    assert set(d) == {
        "id",
        "kind",
        "status",
        "time",
        "position",
        "velocity",
        "covariance",
        "score",
        "hits",
        "created",
        "updated",
        "model_probabilities",
        "detection_ids",
    }
    assert type(d["time"]) is float and type(d["hits"]) is int
    assert d["covariance"] == np.eye(4).tolist()
    TrackOut.model_validate(d)
    orjson.dumps(d)


def test_track_dict_carries_optional_fields() -> None:
    extent = Extent(matrix=np.diag([400.0, 25.0]), semi_axes=(20.0, 5.0), orientation=0.3)
    d = track_to_dict(
        _snapshot(
            kind="formation",
            extent=extent,
            attitude=0.78,
            shape_probabilities={"pattern-5": 0.9},
            members=("T3", "T4"),
            formation_id="F2",
        )
    )
    assert d["extent"] == {"matrix": [[400, 0], [0, 25]], "semi_axes": [20, 5], "orientation": 0.3}
    assert d["attitude"] == 0.78
    assert d["members"] == ["T3", "T4"]
    assert d["formation_id"] == "F2"
    TrackOut.model_validate(d)


def test_report_dict_matches_the_contract() -> None:
    snap = _snapshot()
    result = StepResult(
        time=2.0, sensor_id="radar-1", deleted=("T9",), snapshot=lambda confirmed: (snap,)
    )
    report = report_dict(7, result, 1.25, [track_to_dict(t) for t in result.confirmed()])
    assert set(report) == {"seq", "time", "sensor_id", "processing_ms", "tracks", "deleted"}
    assert report["seq"] == 7 and report["deleted"] == ["T9"]
    TrackReportOut.model_validate(report)


def test_batch_model_rejects_extra_fields_in_python_mode_too() -> None:
    with pytest.raises(ValueError):
        DetectionBatchIn.model_validate({**_batch(), "extra": 1})


HUGE = b"1" + b"0" * 399  # a 400-digit integer

BOUNDED: list[tuple[bytes, str]] = [
    # every number of a batch is bounded where it enters
    (orjson.dumps(_batch(time=1.7e18)), "time: must be <= 1e+12"),
    (orjson.dumps(_batch(time=-2e12)), "time: must be >= -1e+12"),
    (orjson.dumps(_det(2, x=1.5e9)), "detections[2].x: must be <= 1e+09"),
    (orjson.dumps(_det(0, y=-1e10)), "detections[0].y: must be >= -1e+09"),
    (
        orjson.dumps(_det(1, cov=[[1e15, 0], [0, 1e15]])),
        "detections[1].cov[0][0]: must be <= 1e+14",
    ),
    (orjson.dumps(_batch(cov=[[4, -2e14], [-2e14, 4]])), "cov[0][1]: must be >= -1e+14"),
    (
        orjson.dumps({**_det(0, vr=4e8), "sensor_position": [0, 0]}),
        "detections[0].vr: must be <= 3e+08",
    ),
    (orjson.dumps(_det(3, amplitude=-1e13)), "detections[3].amplitude: must be >= -1e+12"),
    (orjson.dumps(_det(4, id="d" * 257)), "detections[4].id: longer than 256 characters"),
    (orjson.dumps(_batch(sensor_position=[0, 2e9])), "sensor_position[1]: must be <= 1e+09"),
    (orjson.dumps(_batch(clutter_density=1.5)), "clutter_density: must be <= 1.0"),
    # integers of any length parse, and are no finite numbers
    (b'{"sensor_id": "r", "time": ' + HUGE + b', "detections": []}', "time: not a finite number"),
    (
        b'{"sensor_id": "r", "time": 1, "detections": [{"x": -' + HUGE + b', "y": 0}]}',
        "detections[0].x: not a finite number",
    ),
    (b'{"sensor_id": "r", "time": 1, "detections": [], "pd": ' + HUGE + b"}", "pd: not a finite"),
]


@pytest.mark.parametrize(("payload", "detail"), BOUNDED)
def test_every_number_is_bounded_where_it_enters(payload: bytes, detail: str) -> None:
    with pytest.raises(BatchError) as info:
        decode_batch(payload)
    assert info.value.reason == "invalid_batch"
    assert info.value.detail.startswith(detail), info.value.detail


def test_the_largest_numbers_allowed_pass() -> None:
    det = {
        "x": MAX_ABS_POSITION,
        "y": -MAX_ABS_POSITION,
        "cov": [[MAX_VARIANCE, 0], [0, MAX_VARIANCE]],
        "vr": -MAX_ABS_RANGE_RATE,
        "amplitude": MAX_ABS_AMPLITUDE,
        "id": "d" * MAX_ID_LENGTH,
    }
    batch = decode_batch(
        orjson.dumps(
            _batch(time=-MAX_ABS_TIME, detections=[det], sensor_position=[0, MAX_ABS_POSITION])
        )
    )
    assert batch.time == -MAX_ABS_TIME and batch.detections[0]["x"] == MAX_ABS_POSITION


def test_the_bounds_are_in_the_schema_and_match_the_tracker() -> None:
    """OpenAPI shows every bound; positions and covariances have the tracker's own
    (:func:`trackers.pipeline.check_scan`)."""
    schema = DetectionBatchIn.model_json_schema()
    props = schema["properties"]
    det = schema["$defs"]["DetectionIn"]["properties"]

    def number(node: dict[str, Any]) -> dict[str, Any]:
        return next(s for s in node.get("anyOf", [node]) if s.get("type") == "number")

    assert (number(props["time"])["minimum"], number(props["time"])["maximum"]) == (
        -MAX_ABS_TIME,
        MAX_ABS_TIME,
    )
    for name in ("x", "y"):
        assert number(det[name])["maximum"] == MAX_ABS_POSITION
        assert number(det[name])["minimum"] == -MAX_ABS_POSITION
    assert number(det["vr"])["maximum"] == MAX_ABS_RANGE_RATE
    assert number(det["amplitude"])["minimum"] == -MAX_ABS_AMPLITUDE
    string = next(s for s in det["id"]["anyOf"] if s.get("type") == "string")
    assert string["maxLength"] == MAX_ID_LENGTH
    cov = next(s for s in det["cov"]["anyOf"] if s.get("type") == "array")
    entry = cov["prefixItems"][0]["prefixItems"][1]
    assert (entry["minimum"], entry["maximum"]) == (-MAX_VARIANCE, MAX_VARIANCE)
    position = next(s for s in props["sensor_position"]["anyOf"] if s.get("type") == "array")
    assert position["prefixItems"][0]["maximum"] == MAX_ABS_POSITION
    pd = number(props["pd"])
    assert (pd["exclusiveMinimum"], pd["maximum"]) == (0.0, 1.0)
    clutter = number(props["clutter_density"])
    assert (clutter["exclusiveMinimum"], clutter["maximum"]) == (0.0, 1.0)
    # unknown fields are refused, and the schema says so
    assert schema["additionalProperties"] is False
    assert schema["$defs"]["DetectionIn"]["additionalProperties"] is False


def test_validation_stops_at_the_first_bad_detection() -> None:
    """Ten thousand bad detections cost the errors of one."""
    dets = [{"x": "a", "y": None, "cov": 1, "vr": [], "amplitude": {}, "id": 5}] * 10_000
    with pytest.raises(BatchError) as info:
        decode_batch(orjson.dumps(_batch(detections=dets)))
    assert info.value.detail.startswith("detections[0].x: not a number; detections[0].y: ")
    assert "detections[1]" not in info.value.detail


def test_unknown_fields_are_named_after_the_rest_is_valid() -> None:
    payload = orjson.dumps({**_det(2, colour="red", z=1), "vr_unit": "m/s"})
    with pytest.raises(BatchError) as info:
        decode_batch(payload)
    assert info.value.detail == "vr_unit: unknown field"
    with pytest.raises(BatchError) as info:
        decode_batch(orjson.dumps(_det(2, colour="red", z=1)))
    assert info.value.detail == "detections[2].colour: unknown field"


def test_only_a_covariance_shape_error_gets_the_shape_hint() -> None:
    for payload in (_det(0, cov=[[1, 2], [2, 1]]), _batch(pd=2), _batch(sensor_position=[0])):
        with pytest.raises(BatchError) as info:
            decode_batch(orjson.dumps(payload))
        assert "2x2 matrix" not in info.value.detail, info.value.detail
