"""Tracker configuration: frozen dataclasses, validated on construction.

Every value has a unit and a default that suits a surveillance radar with a few metres of
position noise. ``TrackerConfig.from_dict`` builds a config from nested plain dicts (as
they come from JSON) and ``to_dict`` gives them back; an invalid value raises
``ValueError`` naming the field, and nothing is built.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from typing import Any, get_args, get_origin, get_type_hints

__all__ = [
    "ASSOCIATION_METHODS",
    "INITIATION_METHODS",
    "AssociationConfig",
    "GatingConfig",
    "InitiationConfig",
    "MeasurementConfig",
    "MotionConfig",
    "TrackManagementConfig",
    "TrackerConfig",
]


def _positive(name: str, value: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name}: must be a finite number > 0, got {value!r}")


def _at_most(name: str, value: float, limit: float) -> None:
    if value > limit:
        raise ValueError(f"{name}: must be at most {limit:g}, got {value!r}")


def _probability(name: str, value: float, *, include_one: bool = False) -> None:
    ok = isinstance(value, int | float) and (0 < value <= 1 if include_one else 0 < value < 1)
    if not ok:
        interval = "(0, 1]" if include_one else "(0, 1)"
        raise ValueError(f"{name}: must be in {interval}, got {value!r}")


@dataclass(frozen=True)
class MotionConfig:
    """IMM motion models over the state ``[x, y, vx, vy, ω]``.

    ``models`` names the modes, a subset of ``("cv", "ct")`` in that order. ``q_cv`` and
    ``q_ct`` are the white-noise acceleration power spectral densities (m²/s³) of the nearly
    constant velocity and coordinated turn modes; ``q_turn_rate`` the turn-rate noise PSD
    (rad²/s³) of the coordinated turn mode. ``sojourn_times`` are the mean times (s) spent in
    each mode; they give the mode transition matrix for any interval ``T`` as
    ``π_jj = exp(−T/τ_j)``, the rest spread evenly over the other modes.
    """

    models: tuple[str, ...] = ("cv", "ct")
    q_cv: float = 0.5
    q_ct: float = 2.0
    q_turn_rate: float = 1e-3
    sojourn_times: tuple[float, ...] = (30.0, 10.0)
    initial_mode_probabilities: tuple[float, ...] = (0.9, 0.1)

    def __post_init__(self) -> None:
        models = tuple(self.models)
        object.__setattr__(self, "models", models)
        object.__setattr__(self, "sojourn_times", tuple(float(t) for t in self.sojourn_times))
        object.__setattr__(
            self,
            "initial_mode_probabilities",
            tuple(float(p) for p in self.initial_mode_probabilities),
        )
        if not models or len(set(models)) != len(models) or not set(models) <= {"cv", "ct"}:
            raise ValueError(f"motion.models: a non-empty subset of ('cv', 'ct'), got {models!r}")
        _positive("motion.q_cv", self.q_cv)
        _positive("motion.q_ct", self.q_ct)
        _positive("motion.q_turn_rate", self.q_turn_rate)
        if len(self.sojourn_times) != len(models):
            raise ValueError("motion.sojourn_times: one per model")
        for t in self.sojourn_times:
            _positive("motion.sojourn_times", t)
        mu = self.initial_mode_probabilities
        if len(mu) != len(models) or any(not (0 <= p <= 1) for p in mu) or abs(sum(mu) - 1) > 1e-9:
            raise ValueError(
                "motion.initial_mode_probabilities: one per model, each in [0, 1], summing to 1"
            )


@dataclass(frozen=True)
class MeasurementConfig:
    """``position_std`` (m): the position noise used when neither detection nor batch has a cov."""

    position_std: float = 10.0

    def __post_init__(self) -> None:
        _positive("measurement.position_std", self.position_std)


INITIATION_METHODS = ("two_point", "single_point")


@dataclass(frozen=True)
class InitiationConfig:
    """How new tracks start (see :mod:`trackers.initiation`).

    ``method`` ``"two_point"`` (the default) is the velocity-gated two-point initiation of
    Blackman and Popoli: a free detection opens a *candidate*; a free detection of a later scan
    within ``max_speed · Δt`` (plus the gate) of it gives it a velocity and starts a tentative
    track, scored by the LLR and confirmed or deleted by the sequential test. The velocity
    prior of a pair is a mixture: with probability ``slow_target_fraction`` a slow target,
    ``N(0, velocity_std²)`` per axis, otherwise any velocity up to ``max_speed`` (m/s),
    uniform over the disc. A candidate is offered to the scans of the next
    ``candidate_max_age`` seconds and makes at most ``max_pairs_per_candidate`` tracks a scan
    (the likeliest), so the number of new tracks stays bounded in dense clutter.

    ``method`` ``"single_point"`` starts a tentative track at each free detection with zero
    velocity of std ``velocity_std`` per axis: it cannot start a target moving much faster than
    ``sqrt(γ) · velocity_std`` per second of revisit (γ the gate threshold).

    Either way a new track has turn rate 0 with std ``turn_rate_std`` (rad/s).
    """

    method: str = "two_point"
    max_speed: float = 700.0
    velocity_std: float = 15.0
    slow_target_fraction: float = 0.8
    turn_rate_std: float = 0.05
    candidate_max_age: float = 12.0
    max_pairs_per_candidate: int = 8

    def __post_init__(self) -> None:
        if self.method not in INITIATION_METHODS:
            raise ValueError(
                f"initiation.method: one of {list(INITIATION_METHODS)}, got {self.method!r}"
            )
        _positive("initiation.max_speed", self.max_speed)
        _at_most("initiation.max_speed", self.max_speed, 1e5)
        _positive("initiation.velocity_std", self.velocity_std)
        _at_most("initiation.velocity_std", self.velocity_std, 1e5)
        _probability("initiation.slow_target_fraction", self.slow_target_fraction)
        _positive("initiation.turn_rate_std", self.turn_rate_std)
        _at_most("initiation.turn_rate_std", self.turn_rate_std, 10.0)
        _positive("initiation.candidate_max_age", self.candidate_max_age)
        _at_most("initiation.candidate_max_age", self.candidate_max_age, 3600.0)
        n = self.max_pairs_per_candidate
        if not (isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= 1000):
            raise ValueError(
                f"initiation.max_pairs_per_candidate: an integer in [1, 1000], got {n!r}"
            )


@dataclass(frozen=True)
class GatingConfig:
    """Chi-square gate on the innovation, two degrees of freedom: a true detection falls in it
    with probability ``gate_probability``."""

    gate_probability: float = 0.9999

    def __post_init__(self) -> None:
        _probability("gating.gate_probability", self.gate_probability)

    @property
    def threshold(self) -> float:
        """γ with P(χ²₂ ≤ γ) = P_G: for two degrees of freedom γ = −2 ln(1 − P_G)."""
        return -2.0 * math.log1p(-self.gate_probability)


@dataclass(frozen=True)
class TrackManagementConfig:
    """Log-likelihood-ratio scoring and the sequential test (Blackman and Popoli, ch. 6).

    ``pd`` and ``clutter_density`` (λ_fa, per m²) are used when a scan does not carry its own.
    ``new_target_density`` is λ_nt per m² per scan. The confirmation threshold is
    ``ln((1 − β)/α)`` and the deletion threshold ``ln(β/(1 − α))`` with α =
    ``p_false_confirm`` and β = ``p_true_delete``. A confirmed track is also deleted when its
    score falls ``delete_drop_from_peak`` below its peak, or when it has had no detection for
    ``max_coast_time`` seconds.
    """

    pd: float = 0.9
    clutter_density: float = 1e-6
    new_target_density: float = 1e-7
    p_false_confirm: float = 1e-5
    p_true_delete: float = 1e-3
    delete_drop_from_peak: float = 15.0
    max_coast_time: float = 10.0

    def __post_init__(self) -> None:
        _probability("track_management.pd", self.pd, include_one=True)
        _positive("track_management.clutter_density", self.clutter_density)
        _positive("track_management.new_target_density", self.new_target_density)
        _probability("track_management.p_false_confirm", self.p_false_confirm)
        _probability("track_management.p_true_delete", self.p_true_delete)
        _positive("track_management.delete_drop_from_peak", self.delete_drop_from_peak)
        _positive("track_management.max_coast_time", self.max_coast_time)
        if self.confirm_threshold <= self.delete_threshold:
            raise ValueError("track_management: confirmation threshold must exceed deletion's")

    @property
    def confirm_threshold(self) -> float:
        """T_c = ln((1 − β)/α)."""
        return math.log((1 - self.p_true_delete) / self.p_false_confirm)

    @property
    def delete_threshold(self) -> float:
        """T_d = ln(β/(1 − α))."""
        return math.log(self.p_true_delete / (1 - self.p_false_confirm))


#: The point trackers the pipeline can run (see ``trackers.pipeline.POINT_TRACKERS``).
ASSOCIATION_METHODS = ("gnn",)


@dataclass(frozen=True)
class AssociationConfig:
    """``method``: the point tracker, ``"gnn"`` (global nearest neighbour over independent
    clusters, confirmed tracks first)."""

    method: str = "gnn"

    def __post_init__(self) -> None:
        if self.method not in ASSOCIATION_METHODS:
            raise ValueError(
                f"association.method: one of {list(ASSOCIATION_METHODS)}, got {self.method!r}"
            )


@dataclass(frozen=True)
class TrackerConfig:
    """Everything the trackers can be told."""

    association: AssociationConfig = field(default_factory=AssociationConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    measurement: MeasurementConfig = field(default_factory=MeasurementConfig)
    initiation: InitiationConfig = field(default_factory=InitiationConfig)
    gating: GatingConfig = field(default_factory=GatingConfig)
    track_management: TrackManagementConfig = field(default_factory=TrackManagementConfig)

    def to_dict(self) -> dict[str, Any]:
        """Nested plain dicts and lists, JSON-ready."""
        return _listify(asdict(self))

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrackerConfig:
        """Build from nested dicts; missing fields keep their defaults, unknown ones raise."""
        return _build(cls, data, "")

    def merged(self, patch: dict[str, Any]) -> TrackerConfig:
        """A new config: this one with the nested fields of ``patch`` replaced."""
        return TrackerConfig.from_dict(_deep_merge(self.to_dict(), patch))


def _listify(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _listify(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_listify(v) for v in value]
    return value


def _build(cls: type, data: Any, path: str) -> Any:
    if not isinstance(data, dict):
        raise ValueError(f"{path or 'config'}: expected an object, got {type(data).__name__}")
    hints = get_type_hints(cls)
    names = {f.name for f in fields(cls)}
    unknown = set(data) - names
    if unknown:
        raise ValueError(f"{path or 'config'}: unknown field(s) {sorted(unknown)}")
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        hint = hints[name]
        sub = f"{path}.{name}" if path else name
        if is_dataclass(hint):
            kwargs[name] = _build(hint, value, sub)  # type: ignore[arg-type]
        else:
            kwargs[name] = _typed(hint, value, sub)
    try:
        return cls(**kwargs)
    except TypeError as exc:  # a wrong type reached a comparison
        raise ValueError(f"{path or 'config'}: {exc}") from None


def _typed(hint: Any, value: Any, path: str) -> Any:
    """``value`` as the field's type: a JSON number for ``float`` (never a bool or a string),
    a string for ``str``, a list of those for ``tuple[..., ...]``. Raises ``ValueError``."""
    if hint is float:
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
        raise ValueError(f"{path}: expected a number, got {value!r}")
    if hint is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        raise ValueError(f"{path}: expected an integer, got {value!r}")
    if hint is str:
        if isinstance(value, str):
            return value
        raise ValueError(f"{path}: expected a string, got {value!r}")
    if get_origin(hint) is tuple:
        if not isinstance(value, list | tuple):
            raise ValueError(f"{path}: expected a list, got {value!r}")
        item = get_args(hint)[0]
        return tuple(_typed(item, v, f"{path}[{i}]") for i, v in enumerate(value))
    raise TypeError(f"{path}: unsupported field type {hint!r}")


def _deep_merge(base: dict[str, Any], patch: dict[str, Any]) -> dict[str, Any]:
    if not isinstance(patch, dict):
        raise ValueError("config patch: expected an object")
    out = dict(base)
    for key, value in patch.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _deep_merge(out[key], value)
        else:
            out[key] = value
    return out
