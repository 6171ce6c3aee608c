"""Wire models, split by direction: what comes in (``*In``) and what goes out (``*Out``).

The ``*In`` models are the contract's validation rules, enforced at the edge: a batch that
passes :meth:`DetectionBatchIn.model_validate_json` carries only finite numbers, symmetric
positive definite covariances and a well-formed sensor id. :func:`decode_batch` turns any
failure into a :class:`BatchError` whose ``detail`` names the place, like
``"detections[3].x: not a finite number"``.

The ``*Out`` models document the reports (OpenAPI and tests); the hot path builds the same
shapes as plain dicts (see :mod:`service.convert`) and serialises them with orjson.
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal, NotRequired

from pydantic import (
    AfterValidator,
    AllowInfNan,
    BaseModel,
    ConfigDict,
    Discriminator,
    FailFast,
    Field,
    Strict,
    Tag,
    ValidationError,
    model_validator,
    with_config,
)
from typing_extensions import TypedDict  # pydantic needs this one before Python 3.12

from trackers.coverage import MAX_VERTICES
from trackers.pipeline import MAX_ABS_POSITION, MAX_ABS_TIME, MAX_VARIANCE

__all__ = [
    "DETECTION_FIELDS",
    "ERROR_REASONS",
    "MAX_ABS_AMPLITUDE",
    "MAX_ABS_RANGE_RATE",
    "MAX_ABS_SPEED",
    "MAX_ID_LENGTH",
    "MAX_SEMI_AXIS",
    "MAX_SENSOR_SERIES",
    "SENSOR_ID_PATTERN",
    "TRACK_KINDS",
    "BatchError",
    "DetectionBatchIn",
    "DetectionIn",
    "ErrorReportOut",
    "ExtendedTrackIn",
    "ExtentAxesIn",
    "ExtentMatrixIn",
    "ExtentOut",
    "FormationIn",
    "IngestAcceptedOut",
    "IngestConfig",
    "PatternTrackIn",
    "ProcessingTimesOut",
    "SensorStatsOut",
    "StatsOut",
    "TrackOut",
    "TrackReportOut",
    "decode_batch",
    "decode_extended_track",
    "decode_formation",
    "decode_pattern_track",
    "format_validation_error",
    "parse_kinds",
    "valid_sensor_id",
]

SENSOR_ID_PATTERN = r"^[A-Za-z0-9_.\-]{1,64}$"
#: The longest ``ingest.reorder_window`` (s): batches are held in memory that long at most.
MAX_REORDER_WINDOW = 3600.0
_SENSOR_ID_RE = re.compile(SENSOR_ID_PATTERN)

#: The ``error`` codes of an Error report, and what each means.
ERROR_REASONS: dict[str, str] = {
    "invalid_json": "the payload is not a JSON document",
    "invalid_batch": "the batch breaks the contract's rules (missing, extra or bad field)",
    "sensor_mismatch": "the batch's sensor_id differs from the last chunk of its Zenoh key",
    "invalid_key": "the Zenoh key is not {prefix}/detections/{sensor_id} with one chunk that "
    "is a valid sensor id; reported on {prefix}/errors/unknown",
    "batch_too_large": "the payload is larger than max_batch_bytes; refused unread",
    "too_many_detections": "more detections than ingest.max_detections_per_batch",
    "duplicate_batch": "byte for byte the same payload as a batch of the same sensor accepted "
    "recently (one of its last 64): not processed twice",
    "out_of_sequence": "the batch is older than the last processed time",
    "time_jump": "the batch's time is further ahead of the last processed time than "
    "ingest.max_time_jump allows",
    "invalid_scan": "the tracker refused the batch's numbers",
    "overloaded": "the ingest queue stayed full: the batch was dropped, not processed",
    "internal_error": "the tracker failed on this batch; no track changed",
}


def valid_sensor_id(value: str) -> bool:
    """True when ``value`` is 1 to 64 of ``A-Z a-z 0-9 _ . -``."""
    return bool(_SENSOR_ID_RE.match(value))


# -- input ----------------------------------------------------------------------------------

#: A JSON number (not a bool, not a string), finite.
Finite = Annotated[float, Strict(), AllowInfNan(False)]

#: The largest magnitude of a batch's time (s): about 31,700 years from the epoch.
#: Nanoseconds or milliseconds since 1970 sent as seconds are beyond it.
#: (The tracker's own check, :func:`trackers.pipeline.check_scan`, uses the same bound.)
#: Positions and covariance entries have the tracker's bounds too: ``MAX_ABS_POSITION`` (m)
#: and ``MAX_VARIANCE`` (m²), beyond which the arithmetic of gating overflows.
#: The largest magnitude of a range-rate (m/s): about the speed of light.
MAX_ABS_RANGE_RATE = 3e8
#: The largest magnitude of an amplitude (any unit: dB or linear).
MAX_ABS_AMPLITUDE = 1e12
#: The longest detection id (characters); ids are echoed back in every Track report.
MAX_ID_LENGTH = 256


def _bounded(limit: float) -> Any:
    """A finite JSON number within ``[-limit, limit]``."""
    return Annotated[float, Strict(), AllowInfNan(False), Field(ge=-limit, le=limit)]


Time = _bounded(MAX_ABS_TIME)
Position = _bounded(MAX_ABS_POSITION)
Variance = _bounded(MAX_VARIANCE)
RangeRate = _bounded(MAX_ABS_RANGE_RATE)
Amplitude = _bounded(MAX_ABS_AMPLITUDE)


def _check_spd(cov: tuple[tuple[float, float], tuple[float, float]]) -> Any:
    (a, b), (c, d) = cov
    if abs(b - c) > 1e-9 * (1.0 + abs(b)) or a <= 0.0 or a * d - b * c <= 0.0:
        raise ValueError("not symmetric positive definite")
    return cov


def _check_area(polygon: list[tuple[float, float]]) -> Any:
    """A coverage polygon must enclose some area (shoelace formula, ``|Σ x_i y_{i+1} −
    x_{i+1} y_i| / 2 > 0``): one whose vertices lie on a line covers nothing."""
    twice = 0.0
    for (x0, y0), (x1, y1) in zip(polygon, polygon[1:] + polygon[:1], strict=True):
        twice += x0 * y1 - x1 * y0
    if not abs(twice) > 0.0:
        raise ValueError("the polygon encloses no area")
    return polygon


#: A 2x2 symmetric positive definite matrix given as ``[[a, b], [b, d]]``.
Cov2 = Annotated[
    tuple[tuple[Variance, Variance], tuple[Variance, Variance]], AfterValidator(_check_spd)
]

#: Unknown fields are refused, but found after validation (:meth:`DetectionBatchIn._after`):
#: refused field by field, a payload of many unknown keys would cost one error each. The
#: schema still says ``additionalProperties: false``.
_NO_EXTRA: dict[str, Any] = {"additionalProperties": False}


# A plain dict once validated (a third cheaper to validate than a model): an optional field
# is absent when the detection has none, or None.
@with_config(ConfigDict(extra="allow", json_schema_extra=_NO_EXTRA))
class DetectionIn(TypedDict):
    """One detection: a measured position with optional covariance, range-rate, amplitude, id."""

    x: Annotated[Position, Field(description="east position, m")]
    y: Annotated[Position, Field(description="north position, m")]
    cov: NotRequired[Annotated[Cov2 | None, Field(description="2x2 position covariance, m² (SPD)")]]
    vr: NotRequired[
        Annotated[RangeRate | None, Field(description="range-rate, m/s (needs sensor_position)")]
    ]
    amplitude: NotRequired[Amplitude | None]
    id: NotRequired[
        Annotated[
            Annotated[str, Strict(), Field(max_length=MAX_ID_LENGTH)] | None,
            Field(description="echoed back in tracks"),
        ]
    ]


DETECTION_FIELDS = frozenset(DetectionIn.__annotations__)


class DetectionBatchIn(BaseModel):
    """One sensor's detections at one time (the contract's Detection batch)."""

    model_config = ConfigDict(
        extra="allow",
        frozen=True,
        json_schema_extra={
            **_NO_EXTRA,
            "examples": [
                {
                    "sensor_id": "radar-1",
                    "time": 12.0,
                    "detections": [{"x": 10.0, "y": -3.5, "id": "d17"}],
                    "cov": [[25, 0], [0, 25]],
                    "pd": 0.9,
                }
            ],
        },
    )

    sensor_id: Annotated[str, Strict(), Field(pattern=SENSOR_ID_PATTERN)]
    time: Time = Field(description="seconds on the shared epoch")
    # fail fast: a list of bad detections costs one detection's errors, not one per item
    detections: Annotated[list[DetectionIn], FailFast()]
    cov: Cov2 | None = Field(default=None, description="default covariance of the detections, m²")
    sensor_position: tuple[Position, Position] | None = Field(
        default=None, description="[x, y] of the sensor, m (for range-rates)"
    )
    sensor_velocity: tuple[RangeRate, RangeRate] | None = Field(
        default=None,
        description="[vx, vy] of a moving sensor, m/s (its range-rates are seen from it;"
        " needs sensor_position)",
    )
    max_range: Annotated[Finite, Field(gt=0.0, le=MAX_ABS_POSITION)] | None = Field(
        default=None,
        description="the sensor looked out to this range from sensor_position, m: a track"
        " beyond it is not counted as missed (needs sensor_position)",
    )
    coverage: (
        Annotated[
            list[tuple[Position, Position]],
            Field(min_length=3, max_length=MAX_VERTICES),
            AfterValidator(_check_area),
        ]
        | None
    ) = Field(
        default=None,
        description="the polygon [[x, y], ...] the sensor looked at, m: a track outside it is"
        " not counted as missed",
    )
    pd: Annotated[Finite, Field(gt=0.0, le=1.0)] | None = None
    clutter_density: Annotated[Finite, Field(gt=0.0, le=1.0)] | None = Field(
        default=None, description="false-alarm density per m²"
    )

    @model_validator(mode="after")
    def _after(self) -> DetectionBatchIn:
        """No unknown field, in the batch or a detection; range-rates and the sensor's velocity
        only with the sensor's position."""
        extra = self.__pydantic_extra__
        if extra:
            raise ValueError(f"{next(iter(extra))}: unknown field")
        dets = self.detections
        keys = set().union(*dets)  # every key of every detection, gathered in C
        if not keys <= DETECTION_FIELDS:  # the place only when there is one
            for i, det in enumerate(dets):
                for key in det:
                    if key not in DETECTION_FIELDS:
                        raise ValueError(f"detections[{i}].{key}: unknown field")
        if self.sensor_position is None and self.sensor_velocity is not None:
            raise ValueError("sensor_velocity: needs the batch's sensor_position")
        if self.sensor_position is None and self.max_range is not None:
            raise ValueError("max_range: needs the batch's sensor_position")
        if self.sensor_position is None and "vr" in keys:
            for i, det in enumerate(dets):
                if det.get("vr") is not None:
                    raise ValueError(f"detections[{i}].vr: needs the batch's sensor_position")
        return self


class BatchError(Exception):
    """A batch refused at the edge: ``reason`` is one of :data:`ERROR_REASONS`."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


_MESSAGES = {
    "finite_number": "not a finite number",
    "float_type": "not a number",
    "float_parsing": "not a number",
    "missing": "missing",
    "extra_forbidden": "unknown field",
    "string_type": "not a string",
    "string_pattern_mismatch": "must be 1 to 64 of A-Z a-z 0-9 _ . -",
    "list_type": "not a list",
    "tuple_type": "not a list",
    "model_type": "not an object",
    "model_attributes_type": "not an object",
    "dict_type": "not an object",
    "too_long": "too many items (at most {max_length})",
    "too_short": "too few items (at least {min_length})",
    "string_too_long": "longer than {max_length} characters",
    "greater_than": "must be > {gt}",
    "less_than_equal": "must be <= {le}",
    "greater_than_equal": "must be >= {ge}",
}


#: What a batch's refused ``time`` most likely is (a newcomer sent milliseconds, and a date).
_UNIT_HINT = " (seconds: a time in milliseconds, microseconds or nanoseconds is out of range)"
_DATE_HINT = " (seconds on the sensors' shared time line, such as Unix time; not a date)"
_TIME_HINTS = {
    "less_than_equal": _UNIT_HINT,
    "greater_than_equal": _UNIT_HINT,
    "float_type": _DATE_HINT,
    "float_parsing": _DATE_HINT,
}


#: Added to an error in the shape of a covariance (a flat list of four numbers, say).
COV_SHAPE_HINT = "a cov is a 2x2 matrix, [[var_x, cov_xy], [cov_xy, var_y]] in m²"


def _location(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else part
    return out


def _shown(value: Any) -> Any:
    """A bound as an error message shows it: ``1.0``, but ``1e+09`` rather than
    ``1000000000.0``."""
    if isinstance(value, float) and abs(value) >= 1e6:
        return f"{value:g}"
    return value


def format_validation_error(exc: ValidationError, errors: list[Any] | None = None) -> str:
    """The first error of ``exc`` as ``"place: what is wrong"`` (``"; "``-joined if several,
    at most three). ``errors``: ``exc.errors()``, if the caller has it already."""
    parts: list[str] = []
    if errors is None:
        errors = exc.errors(include_url=False, include_input=False)
    for err in errors[:3]:
        kind = err["type"]
        loc = err["loc"]
        if kind == "json_invalid":
            parts.append(f"invalid JSON: {err.get('ctx', {}).get('error', err['msg'])}")
            continue
        if kind == "value_error":
            msg = str(err.get("ctx", {}).get("error", err["msg"]))
        else:
            template = _MESSAGES.get(kind)
            try:
                ctx = {k: _shown(v) for k, v in err.get("ctx", {}).items()}
                msg = template.format(**ctx) if template else err["msg"]
            except (KeyError, IndexError):
                msg = err["msg"]
        # A cov's SPD check reports at the cov itself; a tuple's shape errors one level down.
        place = _location(tuple(loc))
        if place == "time":
            msg += _TIME_HINTS.get(kind, "")
        parts.append(f"{place}: {msg}" if place else msg)
    if len(errors) > 3:
        parts.append(f"and {len(errors) - 3} more")
    if any("cov" in err["loc"] and err["type"] != "value_error" for err in errors[:3]):
        parts[-1] += f" ({COV_SHAPE_HINT})"
    return "; ".join(parts)


def decode_batch(payload: bytes | str) -> DetectionBatchIn:
    """Parse and validate one Detection batch; raise :class:`BatchError` when it is refused.

    JSON ``NaN``/``Infinity`` literals parse, then fail the finiteness rule with a precise
    place; unparseable text is ``invalid_json``; everything else is ``invalid_batch``.
    Validation stops at the first bad detection, so the errors of one payload are few; what
    the payload may cost before that is bounded by :func:`service.payload.check_cost`.
    """
    try:
        return DetectionBatchIn.model_validate_json(payload)
    except ValidationError as exc:
        errors = exc.errors(include_url=False, include_input=False)
        if errors and errors[0]["type"] == "json_invalid":
            raise BatchError("invalid_json", format_validation_error(exc, errors)) from None
        if errors and errors[0]["type"] == "model_type" and not errors[0]["loc"]:
            raise BatchError("invalid_batch", "the batch must be a JSON object") from None
        raise BatchError("invalid_batch", format_validation_error(exc, errors)) from None


# -- starting an extended track by hand (POST /api/v1/tracks/extended) ----------------------

#: The longest semi-axis of a hand-started extended track's extent (m), and the shortest.
MAX_SEMI_AXIS = 1e5
MIN_SEMI_AXIS = 1e-3
#: The largest magnitude of a hand-started track's velocity components (m/s).
MAX_ABS_SPEED = 1e5
_MAX_EXTENT_ENTRY = MAX_SEMI_AXIS**2
_MIN_EXTENT_EIGENVALUE = MIN_SEMI_AXIS**2

ExtentEntry = _bounded(_MAX_EXTENT_ENTRY)
Speed = _bounded(MAX_ABS_SPEED)


def _check_extent_matrix(m: tuple[tuple[float, float], tuple[float, float]]) -> Any:
    (a, b), (c, d) = m
    if abs(b - c) > 1e-9 * (1.0 + abs(b)) or a <= 0.0 or a * d - b * c <= 0.0:
        raise ValueError("not symmetric positive definite")
    mean, half = 0.5 * (a + d), math.hypot(0.5 * (a - d), 0.5 * (b + c))
    if mean - half < _MIN_EXTENT_EIGENVALUE:
        raise ValueError(
            f"its smaller eigenvalue must be >= {_MIN_EXTENT_EIGENVALUE:g} m² "
            f"(a semi-axis of {MIN_SEMI_AXIS:g} m)"
        )
    return m


class ExtentMatrixIn(BaseModel):
    """An extent as its shape matrix ``X``: the ellipse ``(p − c)ᵀ X⁻¹ (p − c) ≤ 1``."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    matrix: Annotated[
        tuple[tuple[ExtentEntry, ExtentEntry], tuple[ExtentEntry, ExtentEntry]],
        AfterValidator(_check_extent_matrix),
    ] = Field(
        description=(
            "2x2 symmetric positive definite matrix [[a, b], [b, c]], m²; its eigenvalues are "
            f"the squared semi-axes (from {MIN_SEMI_AXIS:g} m to {MAX_SEMI_AXIS:g} m)"
        )
    )


SemiAxis = Annotated[float, Strict(), AllowInfNan(False), Field(ge=MIN_SEMI_AXIS, le=MAX_SEMI_AXIS)]


class ExtentAxesIn(BaseModel):
    """An extent as an ellipse: its semi-axes and the orientation of the first one."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    semi_axes: tuple[SemiAxis, SemiAxis] = Field(
        description="[major, minor] semi-axes, m (the first along `orientation`)"
    )
    orientation: Annotated[Finite, Field(ge=-2 * math.pi, le=2 * math.pi)] = Field(
        default=0.0, description="angle of the first semi-axis from the x axis (east), rad"
    )

    def matrix(self) -> list[list[float]]:
        """The shape matrix ``R diag(a², b²) Rᵀ``."""
        (a, b), t = self.semi_axes, self.orientation
        c, s = math.cos(t), math.sin(t)
        a2, b2 = a * a, b * b
        off = (a2 - b2) * c * s
        return [[a2 * c * c + b2 * s * s, off], [off, a2 * s * s + b2 * c * c]]


_EXTENT_FORMS = (
    'give exactly one form: {"matrix": [[a, b], [b, c]]} or '
    '{"semi_axes": [major, minor], "orientation": rad}'
)


def _extent_form(value: Any) -> str | None:
    if isinstance(value, BaseModel):
        return "matrix" if isinstance(value, ExtentMatrixIn) else "axes"
    if not isinstance(value, dict):
        return None
    has_matrix = "matrix" in value
    has_axes = "semi_axes" in value or "orientation" in value
    if has_matrix == has_axes:
        return None
    return "matrix" if has_matrix else "axes"


ExtentIn = Annotated[
    Annotated[ExtentMatrixIn, Tag("matrix")] | Annotated[ExtentAxesIn, Tag("axes")],
    Discriminator(
        _extent_form, custom_error_type="extent_form", custom_error_message=_EXTENT_FORMS
    ),
]


class ExtendedTrackIn(BaseModel):
    """A confirmed extended track to start by hand: its centroid, velocity and extent prior."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        json_schema_extra={
            "examples": [
                {
                    "position": [1200.0, -350.0],
                    "velocity": [8.0, 2.0],
                    "extent": {"semi_axes": [60.0, 15.0], "orientation": 0.3},
                    "position_std": 20.0,
                }
            ]
        },
    )

    position: tuple[Position, Position] = Field(description="[x, y] of the centroid, m")
    velocity: tuple[Speed, Speed] = Field(
        default=(0.0, 0.0), description="[vx, vy] of the centroid, m/s"
    )
    extent: ExtentIn = Field(
        description="the extent prior: its shape matrix, or its semi-axes and orientation"
    )
    position_std: Annotated[Finite, Field(gt=0.0, le=1e6)] = Field(
        default=20.0, description="standard deviation of the centroid per axis, m"
    )
    velocity_std: Annotated[Finite, Field(gt=0.0, le=1e4)] = Field(
        default=5.0, description="standard deviation of the velocity per axis, m/s"
    )
    expected_detections: Annotated[Finite, Field(gt=0.0, le=1e4)] = Field(
        default=3.0, description="detections of the object expected per scan"
    )
    time: Time | None = Field(
        default=None,
        description=(
            "when the track starts, s: by default the last processed batch's time; required "
            "before the first batch; never before the last processed batch"
        ),
    )

    def extent_matrix(self) -> list[list[float]]:
        """The extent's shape matrix, m²."""
        ext = self.extent
        if isinstance(ext, ExtentMatrixIn):
            return [list(row) for row in ext.matrix]
        return ext.matrix()


def decode_extended_track(payload: bytes | str) -> ExtendedTrackIn:
    """Parse and validate a request to start an extended track; raise ``ValueError`` whose
    message names the field (``"extent.matrix: not symmetric positive definite"``)."""
    try:
        return ExtendedTrackIn.model_validate_json(payload)
    except ValidationError as exc:
        errors = exc.errors(include_url=False, include_input=False)
        if errors and errors[0]["type"] == "model_type" and not errors[0]["loc"]:
            raise ValueError("the body must be a JSON object") from None
        for err in errors:  # the extent's form is no place of its own: drop its tag
            loc = tuple(err["loc"])
            if len(loc) > 2 and loc[0] == "extent" and loc[1] in ("matrix", "axes"):
                err["loc"] = (loc[0], *loc[2:])
        raise ValueError(format_validation_error(exc, errors)) from None


# -- starting a point-pattern track by hand (POST /api/v1/tracks/pattern) -------------------


class PatternTrackIn(BaseModel):
    """A confirmed point-pattern track to start by hand: the pattern it shows, where its frame's
    origin is, how it moves and its attitude."""

    model_config = ConfigDict(
        extra="forbid",
        frozen=True,
        json_schema_extra={
            "examples": [
                {
                    "pattern": "frigate",
                    "position": [1200.0, -350.0],
                    "velocity": [8.0, 2.0],
                    "attitude": 0.3,
                }
            ]
        },
    )

    pattern: Annotated[str, Strict(), Field(min_length=1, max_length=64)] = Field(
        description="the name of a pattern of the configuration's `point_patterns.patterns`"
    )
    position: tuple[Position, Position] = Field(
        description="[x, y] of the target frame's origin, m"
    )
    velocity: tuple[Speed, Speed] = Field(default=(0.0, 0.0), description="[vx, vy], m/s")
    attitude: Annotated[Finite, Field(ge=-2 * math.pi, le=2 * math.pi)] = Field(
        default=0.0,
        description="angle of the target frame's x axis from the global x axis, rad",
    )
    attitude_rate: Annotated[Finite, Field(ge=-10.0, le=10.0)] = Field(
        default=0.0, description="rate of change of the attitude, rad/s"
    )
    position_std: Annotated[Finite, Field(gt=0.0, le=1e6)] = Field(
        default=10.0, description="standard deviation of the position per axis, m"
    )
    velocity_std: Annotated[Finite, Field(gt=0.0, le=1e4)] = Field(
        default=5.0, description="standard deviation of the velocity per axis, m/s"
    )
    attitude_std: Annotated[Finite, Field(gt=0.0, le=10.0)] = Field(
        default=0.1, description="standard deviation of the attitude, rad"
    )
    time: Time | None = Field(
        default=None,
        description=(
            "when the track starts, s: by default the last processed batch's time; required "
            "before the first batch; never before the last processed batch"
        ),
    )


def decode_pattern_track(payload: bytes | str) -> PatternTrackIn:
    """Parse and validate a request to start a point-pattern track; raise ``ValueError`` whose
    message names the field."""
    try:
        return PatternTrackIn.model_validate_json(payload)
    except ValidationError as exc:
        errors = exc.errors(include_url=False, include_input=False)
        if errors and errors[0]["type"] == "model_type" and not errors[0]["loc"]:
            raise ValueError("the body must be a JSON object") from None
        raise ValueError(format_validation_error(exc, errors)) from None


# -- forming a formation by hand (POST /api/v1/tracks/formation) ---------------------------

#: The most members a formation asked for by hand may have.
MAX_FORMATION_MEMBERS = 100


class FormationIn(BaseModel):
    """A formation to form by hand from live individual tracks."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, json_schema_extra={"examples": [{"members": ["T3", "T4"]}]}
    )

    members: list[Annotated[str, Field(min_length=1, max_length=64)]] = Field(
        min_length=2,
        max_length=MAX_FORMATION_MEMBERS,
        description="ids of live individual tracks, each in no formation yet",
    )


def decode_formation(payload: bytes | str) -> FormationIn:
    """Parse and validate a request to form a formation; raise ``ValueError`` whose message
    names the field."""
    try:
        return FormationIn.model_validate_json(payload)
    except ValidationError as exc:
        errors = exc.errors(include_url=False, include_input=False)
        if errors and errors[0]["type"] == "model_type" and not errors[0]["loc"]:
            raise ValueError("the body must be a JSON object") from None
        raise ValueError(format_validation_error(exc, errors)) from None


# -- output ---------------------------------------------------------------------------------


class ExtentOut(BaseModel):
    matrix: list[list[float]] = Field(description="2x2 extent matrix, m²")
    semi_axes: list[float] = Field(description="ellipse semi-axes, m")
    orientation: float = Field(description="rad")


TRACK_KINDS = ("individual", "extended", "formation")


def parse_kinds(value: str) -> set[str]:
    """``individual,extended`` -> the set of kinds; an unknown kind (they are lower case)
    raises ``ValueError`` naming the ones there are (it matched no track, silently)."""
    kinds = {k.strip() for k in value.split(",") if k.strip()}
    unknown = sorted(kinds.difference(TRACK_KINDS))
    if unknown:
        raise ValueError(
            f"kind: each one of {', '.join(TRACK_KINDS)}, got {', '.join(map(repr, unknown))}"
        )
    return kinds


class TrackOut(BaseModel):
    """One track (the contract's Track); optional fields are absent when they do not apply."""

    model_config = ConfigDict(extra="forbid")

    id: str
    kind: Literal["individual", "extended", "formation"] | str
    status: Literal["tentative", "confirmed"]
    time: float
    position: list[float] = Field(description="[x, y], m")
    velocity: list[float] = Field(description="[vx, vy], m/s")
    covariance: list[list[float]] = Field(description="4x4 over x, y, vx, vy")
    score: float = Field(description="log-likelihood-ratio score")
    hits: int
    created: float
    updated: float
    model_probabilities: dict[str, float]
    detection_ids: list[str]
    extent: ExtentOut | None = None
    attitude: float | None = None
    shape_probabilities: dict[str, float] | None = None
    members: list[str] | None = None
    formation_id: str | None = None
    instance: str | None = Field(
        default=None,
        description="the instance that holds the track (only in a federated answer)",
    )


class FederationOut(BaseModel):
    """Who answered a federated track query (``GET /api/v1/tracks`` with ``federate``)."""

    answered: list[str] = Field(description="instances whose tracks are in the answer")
    missing: list[str] = Field(
        description=(
            "instances alive (liveliness token) that did not answer within timeout_s, and "
            "those whose token went away in the last ten minutes"
        )
    )
    timeout_s: float


class TrackReportOut(BaseModel):
    """What the service publishes on ``{prefix}/tracks`` after each processed batch.

    Before the first batch the queryable and REST answer ``seq`` 0 with ``time`` and
    ``sensor_id`` null and no tracks.
    """

    seq: int
    time: float | None
    sensor_id: str | None
    processing_ms: float
    tracks: list[TrackOut]
    deleted: list[str]
    instances: FederationOut | None = Field(
        default=None,
        description=(
            "a federated answer (setting federate): which instances answered; every track "
            "then names its instance"
        ),
    )


class ErrorReportOut(BaseModel):
    """What the service publishes on ``{prefix}/errors/{sensor_id}`` for a refused batch.

    ``time`` is null when the payload could not be read. ``error`` is one of the codes in
    :data:`ERROR_REASONS`.
    """

    sensor_id: str
    time: float | None
    error: str
    detail: str
    received_bytes: int


class IngestAcceptedOut(BaseModel):
    accepted: bool
    seq: int | None = Field(description="the Track report's seq; null if still held back")


class ProcessingTimesOut(BaseModel):
    p50: float
    p90: float
    p99: float
    max: float
    mean: float
    window: int = Field(description="how many of the last batches these are over (<= 2048)")


#: The sensors whose last batch ``/api/v1/stats`` and ``/metrics`` show: the most recently
#: heard, those with 10 batches or more kept over newer one-off ids, so that a stream of
#: one-off sensor ids can neither grow them without bound nor push out a radar gone quiet.
MAX_SENSOR_SERIES = 64


class SensorStatsOut(BaseModel):
    sensor_id: str
    seconds_since_last_batch: float = Field(
        description="wall-clock seconds since this sensor's last batch was processed"
    )
    last_time: float = Field(description="the time stamp of that batch")
    batches: int = Field(description="its batches processed since it was last listed here")


class StatsOut(BaseModel):
    instance_id: str
    uptime_s: float
    seq: int
    last_time: float | None
    seconds_since_last_batch: float | None = Field(
        description=(
            "wall-clock seconds since the last batch was processed (null: none since start-up "
            "and none restored); the tracks are as of that batch"
        )
    )
    sensors: list[SensorStatsOut] = Field(
        description=(
            f"the {MAX_SENSOR_SERIES} most recently heard sensors, the most recent first "
            "(those with 10 batches or more kept over newer one-off ids)"
        )
    )
    batches_received: int
    batches_processed: int
    batches_rejected: int
    rejected_by_reason: dict[str, int]
    batches_dropped: int
    detections_received: int
    detections_processed: int
    tracks_confirmed: int
    tracks_tentative: int
    queue_depth: int
    queue_capacity: int
    held_for_reorder: int
    processing_ms: ProcessingTimesOut
    viewers: int = Field(description="live view streams connected (GET /api/v1/stream)")
    view_frames_dropped: int = Field(
        description="live view frames replaced by a newer one before their viewer took them"
    )


class IngestConfig(BaseModel):
    """How the engine takes batches in."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    max_detections_per_batch: Annotated[int, Strict(), Field(ge=1)] = 10000
    reorder_window: Annotated[Finite, Field(ge=0.0, le=MAX_REORDER_WINDOW)] = Field(
        default=0.0, description="seconds a batch may be held back to put late ones in time order"
    )
    sensor_wait: Annotated[Finite, Field(ge=0.0, le=60.0)] = Field(
        default=0.2,
        description=(
            "seconds a batch may wait, when there is no reorder window, for another sensor "
            "due to send one of its time or earlier (its last time plus its usual interval): "
            "two sensors on one tick, delayed differently on the network, are then taken in "
            "time order instead of refusing the later-stamped one's slower rival; 0: none"
        ),
    )
    max_time_jump: Annotated[Finite, Field(gt=0.0, le=MAX_REORDER_WINDOW)] = Field(
        default=10.0,
        description=(
            "seconds a batch's time may run ahead of the last processed time, beyond the wall "
            "time that has passed since (a sensor may also run ahead by twice its usual "
            "interval between batches, and by the reorder window): a sensor whose clock runs "
            "ahead would otherwise coast every sensor's tracks to its time, deleting them, "
            "and put every later batch out of sequence"
        ),
    )
