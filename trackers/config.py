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

from scipy.special import ndtri

__all__ = [
    "ASSOCIATION_METHODS",
    "INITIATION_METHODS",
    "POINT_PATTERN_FILTERS",
    "AssociationConfig",
    "ExtendedConfig",
    "FormationConfig",
    "GatingConfig",
    "InitiationConfig",
    "MeasurementConfig",
    "MotionConfig",
    "PointPatternConfig",
    "TrackManagementConfig",
    "TrackerConfig",
]


def _field(
    default: Any,
    description: str,
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    choices: tuple[str, ...] | None = None,
    length: tuple[int, int] | None = None,
) -> Any:
    """A config field with its default, its description and its bounds (or allowed values),
    read by :func:`_check_bounds` and by whoever shows the configuration (the service derives
    its document schema from them). A number outside its bounds is one the tracker cannot
    run with, so every number has them; a list has its ``length`` bounds (fewest, most)."""
    meta: dict[str, Any] = {"description": description}
    for key, bound in (("gt", gt), ("ge", ge), ("lt", lt), ("le", le)):
        if bound is not None:
            meta[key] = bound
    if choices is not None:
        meta["choices"] = tuple(choices)
    if length is not None:
        meta["length"] = length
    return field(default=default, metadata=meta)


_BOUND_TEXT = {"gt": "> {}", "ge": ">= {}", "lt": "< {}", "le": "<= {}"}
_BOUND_OK = {
    "gt": lambda v, b: v > b,
    "ge": lambda v, b: v >= b,
    "lt": lambda v, b: v < b,
    "le": lambda v, b: v <= b,
}


def _check_bounds(obj: Any, section: str) -> None:
    """Raise ``ValueError`` naming ``section.field`` for a ``bool`` field that is not a boolean,
    an ``int`` field that is not an integer, and a number (or a list item) that is not a
    finite number within the field's bounds."""
    for f in fields(obj):
        value = getattr(obj, f.name)
        if f.type in ("bool", bool) and not isinstance(value, bool):
            raise ValueError(f"{section}.{f.name}: expected true or false, got {value!r}")
        if f.type in ("int", int) and (not isinstance(value, int) or isinstance(value, bool)):
            raise ValueError(f"{section}.{f.name}: expected an integer, got {value!r}")
        bounds = [(k, f.metadata[k]) for k in _BOUND_TEXT if k in f.metadata]
        if not bounds:
            continue
        for v in value if isinstance(value, tuple | list) else (value,):
            ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            if not (ok and all(_BOUND_OK[k](v, b) for k, b in bounds)):
                want = " and ".join(_BOUND_TEXT[k].format(b) for k, b in bounds)
                raise ValueError(f"{section}.{f.name}: must be a finite number {want}, got {v!r}")


@dataclass(frozen=True)
class MotionConfig:
    """IMM motion models over the state ``[x, y, vx, vy, ω]``.

    ``models`` names the modes, a subset of ``("cv", "ct")`` in that order. ``q_cv`` and
    ``q_ct`` are the white-noise acceleration power spectral densities (m²/s³) of the nearly
    constant velocity and coordinated turn modes; ``q_turn_rate`` the turn-rate noise PSD
    (rad²/s³) of the coordinated turn mode; ``q_ct_along`` a white acceleration noise PSD along
    the velocity that the coordinated turn mode adds (it is the manoeuvre mode: speeding up and
    slowing down as well as turning) when a confirmed track is updated with a detection alone in
    its gate, in sparse clutter, outside every peer's resolution cell (README, *Targets that
    speed up or slow down*). Beside a coordinated-turn mode the
    constant velocity mode resets the turn rate to 0 with std ``cv_turn_rate_std`` (rad/s) at
    each prediction, so that a finished turn's rate does not live on in it; a track at speed
    ``v`` of 25 m/s or more gets at least ``min(0.5, a / v, 0.2 / T)``, ``T`` the track's
    revisit (its mean interval between detections times ``track_management.pd``) or the
    prediction step if longer, with ``a`` = ``agile_acceleration``: the rate at which a
    lateral acceleration ``a`` turns it (a drone turns faster than an airliner), within
    0.2 rad a revisit. The manoeuvre search (``gating``) looks for turns at
    ``min(0.5, a / v, 1 / τ)`` too, ``τ`` the time since the track's last detection.
    ``sojourn_times`` are the mean times (s) spent in each mode; they give the mode transition
    matrix for any interval ``T`` as ``π_jj = exp(−T/τ_j)``, the rest spread evenly over the
    other modes.
    """

    models: tuple[str, ...] = _field(
        ("cv", "ct"),
        'the IMM modes: "cv" (nearly constant velocity) and/or "ct" (coordinated turn), in order',
        choices=("cv", "ct"),
        length=(1, 2),
    )
    q_cv: float = _field(
        0.5, "acceleration noise PSD of the constant-velocity mode, m²/s³", gt=0, le=1e4
    )
    q_ct: float = _field(
        2.0, "acceleration noise PSD of the coordinated-turn mode, m²/s³", gt=0, le=1e4
    )
    q_turn_rate: float = _field(
        3e-5, "turn-rate noise PSD of the coordinated-turn mode, rad²/s³", gt=0, le=1.0
    )
    q_ct_along: float = _field(
        6.0,
        "acceleration noise PSD along the velocity, added to the coordinated-turn mode's when"
        " a confirmed track takes a detection alone in its gate, in sparse clutter, outside"
        " every resolution cell (a target speeding up or slowing down), m²/s³; 0: none",
        ge=0,
        le=1e4,
    )
    cv_turn_rate_std: float = _field(
        0.05,
        "beside a coordinated-turn mode, the constant-velocity mode's turn rate is 0 with this"
        " std at every prediction: the prior rate of a turn that starts from straight flight,"
        " rad/s",
        gt=0,
        le=10.0,
    )
    agile_acceleration: float = _field(
        12.0,
        "a target of 25 m/s or more may start a turn at the rate of this lateral acceleration"
        " (a / speed, at most 0.5 rad/s: 0.3 for a 40 m/s drone): its constant-velocity"
        " mode's turn-rate std is at least that within 0.2 rad a revisit of the track (0.2"
        " rad/s at 1 s), and so is the manoeuvre search's turn rate within 1 rad since the"
        " track's last detection, m/s² (0: off)",
        ge=0,
        le=1e3,
    )
    sojourn_times: tuple[float, ...] = _field(
        (60.0, 20.0), "mean time spent in each mode, s (one per model)", gt=0, le=1e6, length=(1, 2)
    )
    initial_mode_probabilities: tuple[float, ...] = _field(
        (0.9, 0.1),
        "a new track's mode probabilities (one per model, summing to 1)",
        ge=0,
        le=1,
        length=(1, 2),
    )

    def __post_init__(self) -> None:
        _check_bounds(self, "motion")
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
        if len(self.sojourn_times) != len(models):
            raise ValueError("motion.sojourn_times: one per model")
        mu = self.initial_mode_probabilities
        if len(mu) != len(models) or any(not (0 <= p <= 1) for p in mu) or abs(sum(mu) - 1) > 1e-9:
            raise ValueError(
                "motion.initial_mode_probabilities: one per model, each in [0, 1], summing to 1"
            )


@dataclass(frozen=True)
class MeasurementConfig:
    """``position_std`` (m): the position noise used when neither detection nor batch has a cov.
    ``range_rate_std`` (m/s): the noise assumed for a detection's range-rate (``vr``, seen
    from the batch's ``sensor_position``), which updates a track after its position (an
    extended Kalman update). 10 m/s by default, more than a Doppler radar's own noise: in a
    manoeuvre's first scans each mode's velocity is off by more than its covariance says, and
    a tighter value then hands the track to the wrong mode (a 3 g turn at T = 4 s through a
    missed scan was lost at 1-5 m/s and held at 10). A false alarm's range-rate is taken as
    a tenth surface clutter near zero Doppler (``N(0, clutter_range_rate_std²)`` on the
    ground) and the rest uniform within ``±initiation.max_speed``, so a consistent one adds
    ``ln(N(ν; 0, S) / p_fa(ṙ))`` to the track's score: much for a target moving along the
    beam (about 4 a hit), little for one crossing it (about 0.6), whose range-rate wind-blown
    trees give as well. ``clutter_range_rate_std`` is 0 (all uniform) or at least 0.01."""

    position_std: float = _field(
        10.0, "position noise per axis, m, of detections that carry no covariance", ge=1e-3, le=1e5
    )
    range_rate_std: float = _field(
        10.0,
        "range-rate (vr) noise the filter assumes, m/s: the sensor's, and what a manoeuvre adds"
        " to a mode's velocity error between scans",
        gt=0,
        le=1e4,
    )
    clutter_range_rate_std: float = _field(
        2.0,
        "spread of the range-rates of surface clutter (vegetation, sea, ground), m/s: a tenth"
        " of the false alarms are taken to be still on the ground within it, so a track's"
        " range-rate near zero counts little for it (0: false alarms' range-rates uniform;"
        " else at least 0.01)",
        ge=0,
        le=1e3,
    )

    def __post_init__(self) -> None:
        _check_bounds(self, "measurement")
        if 0.0 < self.clutter_range_rate_std < 0.01:
            raise ValueError(
                "measurement.clutter_range_rate_std: 0 or at least 0.01, got "
                f"{self.clutter_range_rate_std!r}"
            )


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

    Targets fly and drive in groups: a candidate that opens within ``group_radius`` of a
    confirmed track at least ``group_min_speed`` fast adds a third component to its prior,
    with probability ``group_fraction`` it moves with that track, ``N(v_track,
    group_velocity_std²)`` per axis (the nearest such track). A member of a fast group then
    starts with its group's velocity instead of a guess across the whole disc, and a pair
    that joins it to a neighbour's detection is far less likely than its own.

    ``method`` ``"single_point"`` starts a tentative track at each free detection with zero
    velocity of std ``velocity_std`` per axis: it cannot start a target moving much faster than
    ``sqrt(γ) · velocity_std`` per second of revisit (γ the gate threshold).

    Either way a new track has turn rate 0 with std ``turn_rate_std`` (rad/s).
    """

    method: str = _field(
        "two_point",
        'how tracks start: "two_point" (velocity-gated pairs) or "single_point"',
        choices=INITIATION_METHODS,
    )
    max_speed: float = _field(700.0, "fastest target a two-point start covers, m/s", gt=0, le=1e5)
    velocity_std: float = _field(
        15.0,
        "velocity std per axis of slow targets (and of single-point starts), m/s",
        ge=1e-3,
        le=1e5,
    )
    slow_target_fraction: float = _field(
        0.8, "prior probability that a new target is slow", gt=0, lt=1
    )
    turn_rate_std: float = _field(0.05, "a new track's turn-rate std, rad/s", gt=0, le=10.0)
    candidate_max_age: float = _field(
        12.0, "how long a lone detection waits for a second one, s", gt=0, le=3600.0
    )
    max_pairs_per_candidate: int = _field(
        8, "most tracks one candidate starts in a scan (the likeliest)", ge=1, le=1000
    )
    group_fraction: float = _field(
        0.5,
        "prior probability that a new target near a fast confirmed track moves with it",
        ge=0,
        lt=1,
    )
    group_radius: float = _field(
        1000.0, "how near a confirmed track a new target may move with it, m", gt=0, le=1e6
    )
    group_min_speed: float = _field(
        30.0, "slowest confirmed track a new target may move with, m/s", ge=0, le=1e5
    )
    group_velocity_std: float = _field(
        10.0, "velocity std per axis of a group's member about the group, m/s", gt=0, le=1e4
    )

    def __post_init__(self) -> None:
        _check_bounds(self, "initiation")
        if self.method not in INITIATION_METHODS:
            raise ValueError(
                f"initiation.method: one of {list(INITIATION_METHODS)}, got {self.method!r}"
            )


@dataclass(frozen=True)
class GatingConfig:
    """Chi-square gate on the innovation, two degrees of freedom: a true detection falls in it
    with probability ``gate_probability``."""

    gate_probability: float = _field(
        0.9999, "probability that a true detection falls in the chi-square gate", gt=0, le=1 - 1e-12
    )
    manoeuvre_acceleration: float = _field(
        50.0,
        "a confirmed track with nothing in its gate looks as far as a manoeuvre of this "
        "acceleration since its last update reaches, m/s² (0: not at all)",
        ge=0,
        le=1e4,
    )
    manoeuvre_turn_rate: float = _field(
        0.1,
        "and as far as a turn at this rate reaches (the acceleration is at most rate × speed), "
        "rad/s",
        gt=0,
        le=10.0,
    )
    manoeuvre_speed_change: float = _field(
        3.0,
        "and as far as a change of speed at this acceleration reaches along its velocity (a"
        " target setting off, speeding up or braking; at most manoeuvre_acceleration), where"
        " that search expects fewer than 0.1 false alarms, m/s² (0: only the turn's fifth)",
        ge=0,
        le=1e4,
    )

    def __post_init__(self) -> None:
        _check_bounds(self, "gating")

    @property
    def threshold(self) -> float:
        """γ with P(χ²₂ ≤ γ) = P_G: for two degrees of freedom γ = −2 ln(1 − P_G)."""
        return -2.0 * math.log1p(-self.gate_probability)

    @property
    def threshold_1d(self) -> float:
        """γ₁ with P(χ²₁ ≤ γ₁) = P_G, for a scalar innovation (a range-rate):
        γ₁ = Φ⁻¹((1 + P_G)/2)²."""
        return float(ndtri(0.5 * (1.0 + self.gate_probability))) ** 2


@dataclass(frozen=True)
class TrackManagementConfig:
    """Log-likelihood-ratio scoring and the sequential test (Blackman and Popoli, ch. 6).

    ``pd`` and ``clutter_density`` (λ_fa, per m²) are used when a scan does not carry its own;
    with ``clutter_map`` the density of a scan that carries none is learned per area
    (:mod:`trackers.clutter`), ``clutter_density`` its prior.
    ``new_target_density`` is λ_nt per m² per scan; a new track starts at
    ``ln(λ_nt / λ_fa)``, but never below ``ln 0.01``: λ_nt counts as at least a hundredth of
    the false-alarm density, which matters where that is dense (a camera's false alarms,
    :data:`trackers.scoring.MIN_NEW_TARGET_ODDS`).
    The confirmation threshold is
    ``ln((1 − β)/α)`` and the deletion threshold ``ln(β/(1 − α))`` with α =
    ``p_false_confirm`` and β = ``p_true_delete``. A confirmed track is also deleted when its
    score falls ``delete_drop_from_peak`` below its peak, or when it has had no detection for
    ``max_coast_time`` seconds, or ``m* − ½`` revisits of its sensor if that is longer (a
    GMTI every 10 s misses a vehicle twice in a row now and then), ``m*`` the misses in a
    row whose probability ``(1 − P_D)^m*`` is β: 2.5 revisits
    at ``P_D`` 0.9, 3.8 at 0.8, 5.2 at 0.7 (at most 9.5), ``P_D`` the batch's or, when it
    states none, the one the sensor's tracks show (:mod:`trackers.detection_rate`); past 2.5
    revisits only while the track's gate expects fewer than 0.1 false alarms. Time spent
    inside an extended track's resolution cell counts at the rate ``extended.in_cell_pd /
    pd`` there (the object hides it: a vehicle beside a convoy coasts that much longer).
    A sensor whose batches come more often than ``miss_correlation_time`` τ (a camera) does not
    miss a target independently at each frame: a miss of a confirmed track whose peak score is
    ``delete_drop_from_peak`` above the confirmation threshold costs
    ``max(ln(1 − P_D), min(1, Δ/τ) min(ln(1 − P_D), ln 0.1))``, Δ the longer of the time since
    the track's last look and the sensor's interval, so that it coasts through an occlusion of
    about ``τ ΔL_drop / max(|ln(1 − P_D)|, |ln 0.1|)`` (1.5 s at P_D 0.95, 2 s at 0.9 or less).
    """

    pd: float = _field(0.9, "detection probability, when a batch carries none", gt=0, le=1)
    clutter_density: float = _field(
        1e-6, "false-alarm density per m², when a batch carries none", gt=0, le=1.0
    )
    clutter_map: bool = _field(
        True,
        "for batches that carry no clutter_density, learn the false-alarm density of each area"
        " from each sensor's detections that no confirmed track took (clutter_density is then"
        " the prior)",
    )
    new_target_density: float = _field(
        1e-7,
        "new-target density per m² per scan (at least a hundredth of the false-alarm density)",
        gt=0,
        le=1.0,
    )
    p_false_confirm: float = _field(1e-5, "α: probability of confirming a false track", gt=0, lt=1)
    p_true_delete: float = _field(1e-3, "β: probability of deleting a true track", gt=0, lt=1)
    delete_drop_from_peak: float = _field(
        15.0,
        "a confirmed track is deleted when its score falls this far below its peak",
        gt=0,
        le=1e6,
    )
    miss_correlation_time: float = _field(
        0.3,
        "a sensor that looks at a confirmed track more often than this (s) does not miss it"
        " independently at each look (a pillar or a passing van hides a walker for a while):"
        " each miss lowers the score by its share Δ/τ of ln(1 − P_D) (of ln 0.1 at least,"
        " never more than the miss), Δ the time since the track's last look or the sensor's"
        " interval between batches, whichever is longer (0: every miss in full)",
        ge=0,
        le=60.0,
    )
    max_coast_time: float = _field(
        10.0,
        "a confirmed track is deleted after this long without a detection, s (or, if longer, "
        "as many revisits of its sensor as make that many misses in "
        "a row as unlikely as p_true_delete: 2.5 at P_D 0.9, 5.2 at 0.7, P_D learned from the "
        "sensor's tracks when its batches state none; inside an extended track's resolution "
        "cell the time counts at the rate extended.in_cell_pd / pd)",
        gt=0,
        le=1e6,
    )

    def __post_init__(self) -> None:
        _check_bounds(self, "track_management")
        if not (math.isfinite(self.confirm_threshold) and math.isfinite(self.delete_threshold)):
            raise ValueError(
                "track_management.p_false_confirm: too small, the confirmation threshold "
                "ln((1 − β)/α) must be a finite number (use 1e-300 or more)"
            )
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

    method: str = _field(
        "gnn", 'the point tracker: "gnn" (global nearest neighbour)', choices=ASSOCIATION_METHODS
    )

    def __post_init__(self) -> None:
        if self.method not in ASSOCIATION_METHODS:
            raise ValueError(
                f"association.method: one of {list(ASSOCIATION_METHODS)}, got {self.method!r}"
            )


@dataclass(frozen=True)
class ExtendedConfig:
    """Extended objects and groups: random-matrix tracks (paper 002, :mod:`trackers.extended`).

    A track's centroid moves as nearly constant velocity with acceleration PSD ``q``; its extent
    ``X`` (the ellipse ``(p − c)ᵀ X⁻¹ (p − c) ≤ 1`` holding the object) keeps its shape with an
    agility time constant ``tau``; ``z_scale`` relates ``X`` to the spread of the detections
    (1/4 for scatterers spread uniformly over the ellipse). Detections in a track's gate are
    split into subsets whose members are less than ``resolution_distance`` apart; the likeliest
    union of subsets is the track's. A cluster of at least ``min_detections`` detections, found
    in ``birth_scans`` scans in a row spanning ``birth_time`` and moving as one (no faster than
    ``max_speed``), starts a track (a scan of another sensor than the one that saw the cluster
    last does not break the row when it misses it); until then an object's detections may
    confirm individual tracks, which the new track absorbs. The detections of older confirmed
    tracks count for a cluster only if the tracks move together, within
    ``group_speed_spread``, and their median velocity is faster than that (stopped cars in a
    queue are each their own target). Individual tracks inside a track's
    resolution cell (its extent grown by half the resolution distance) have detection
    probability ``in_cell_pd``;
    those inside its extent that move with it (velocities within ``group_speed_spread``) for
    3 scans, and those its own detections started (in its cell, created since its cluster was
    first seen, never seen coming from outside), are absorbed. A track is deleted like an
    individual one (the sequential test of ``track_management``) or after ``max_coast_time``
    without detections. The resolution distance in force is at most
    ``resolution_noise_factor`` standard deviations of the position noise of the coarsest
    sensor heard in the last 60 s, and ``group_speed_spread`` shrinks by the same ratio (a
    camera's pedestrians are no group). A cluster must stand out from the clutter about it
    (three times the detections that false alarms of the batch's density, stated or learned
    for its sensor's whole scene, would put in its box: evenly spread clutter is no group).
    """

    enabled: bool = _field(True, "track extended objects and groups alongside individual targets")
    q: float = _field(0.5, "centroid acceleration noise PSD, m²/s³", gt=0, le=1e4)
    tau: float = _field(10.0, "time constant of extent changes, s", gt=0, le=1e6)
    z_scale: float = _field(
        0.25, "spread of the detections relative to the extent (1/4: uniform)", gt=0, le=10.0
    )
    resolution_distance: float = _field(
        200.0, "detections closer than this belong to one subset, m", gt=0, le=1e5
    )
    resolution_noise_factor: float = _field(
        40.0,
        "the resolution distance in force is at most this many standard deviations of the"
        " position noise of the coarsest sensor heard in the last 60 s (a batch's median), so"
        " that a fine sensor (a camera's 0.3 m) resolves targets metres apart; 0:"
        " resolution_distance always",
        ge=0,
        le=1e6,
    )
    gate_probability: float = _field(
        0.9999, "probability that a detection of the object falls in its gate", gt=0, lt=1
    )
    min_detections: int = _field(
        3, "fewest detections of a cluster that may start a track", ge=2, le=1000
    )
    birth_scans: int = _field(
        3,
        "scans in a row a cluster must be seen to start a track (after which one scan may"
        " miss it, once)",
        ge=1,
        le=100,
    )
    birth_time: float = _field(
        10.0,
        "shortest time a cluster must be seen to start a track, and a new track's age before"
        " it absorbs the individual tracks moving with it, s (independent targets close"
        " together look like a group for a few fast scans)",
        ge=0,
        le=1e6,
    )
    max_speed: float = _field(
        60.0, "fastest group or object the birth search follows, m/s", gt=0, le=1e4
    )
    group_speed_spread: float = _field(
        3.0, "members of one group move within this speed of each other, m/s", gt=0, le=1e4
    )
    in_cell_pd: float = _field(
        0.5, "detection probability of an individual track inside a resolution cell", gt=0, le=1
    )
    max_coast_time: float = _field(
        30.0, "an extended track is deleted after this long without detections, s", gt=0, le=1e6
    )

    def __post_init__(self) -> None:
        _check_bounds(self, "extended")

    @property
    def gate_threshold(self) -> float:
        """γ with P(χ²₂ ≤ γ) = P_G: γ = −2 ln(1 − P_G)."""
        return -2.0 * math.log1p(-self.gate_probability)


@dataclass(frozen=True)
class FormationConfig:
    """Formations: tight groups of resolvable targets tracked by template matching (paper 003,
    :mod:`trackers.formation`).

    Confirmed individual tracks at least ``min_speed`` fast, at least ``min_members`` of them,
    each within ``max_spacing`` of another and moving within ``max_velocity_difference`` of
    it, no two closer than ``extended.resolution_distance`` if extended tracking is on and they
    fly no faster than ``extended.max_speed`` (closer ones are then one unresolved object, the
    extended tracker's), seen so for ``confirm_scans`` scans spanning at least
    ``confirm_time``, become a formation. Its members are then updated with the detections
    that the template of the formation (the members' predicted positions on a grid, eq. 7)
    matches; their motion is the IMM of ``motion`` with the formation's own constant-velocity
    mode: noise ``q_cv``, mean time in it ``cv_sojourn_time`` and turn-rate reset
    ``cv_turn_rate_std`` (formations fly steadily, so a member's estimate should not carry the
    turn mode's noise between turns; the coordinated-turn mode still follows their turns).
    The members of a formation share one mode probability, to which every member's detection
    contributes (a formation turns as one body), and a confirmed track that moves with a
    formation for ``confirm_scans`` scans spanning ``confirm_time`` joins it.

    Off by default: on the paper's environments it holds the targets as well as the
    individual tracker alone, not better yet (``python -m benchmarks.formation``). A member that
    falls ``leave_distance`` behind or away from every other member, or whose velocity parts
    from the formation's by more than ``max_velocity_difference`` beyond what its turn and its
    own velocity uncertainty (3σ) explain, for ``leave_time``, or that is not detected for
    ``max_coast_time``, is handed back to the individual tracker; a formation left with fewer
    than 2 members ends.
    """

    enabled: bool = _field(
        False, "track formations of resolvable targets by template matching (opt-in)"
    )
    min_members: int = _field(3, "fewest confirmed tracks that start a formation", ge=2, le=100)
    min_speed: float = _field(
        30.0, "slowest members of a formation started automatically, m/s", ge=0, le=1e4
    )
    max_spacing: float = _field(
        1000.0, "each member is within this distance of another member, m", gt=0, le=1e6
    )
    max_velocity_difference: float = _field(
        20.0, "members move within this speed of each other, m/s", gt=0, le=1e4
    )
    confirm_scans: int = _field(
        5, "scans a group of tracks must move together to become a formation", ge=1, le=1000
    )
    confirm_time: float = _field(3.0, "and the time those scans must span, s", ge=0, le=1e6)
    q_cv: float = _field(
        0.05, "acceleration noise PSD of the members' constant-velocity mode, m²/s³", gt=0, le=1e4
    )
    cv_sojourn_time: float = _field(
        3000.0,
        "mean time a member spends in the constant-velocity mode, s (formations fly steadily;"
        " the other modes keep motion.sojourn_times)",
        gt=0,
        le=1e6,
    )
    cv_turn_rate_std: float = _field(
        0.05,
        "the members' constant-velocity mode resets the turn rate with this std, rad/s",
        gt=0,
        le=10.0,
    )
    gate_probability: float = _field(
        0.9999, "probability that a member's detection falls in its gate", gt=0, lt=1
    )
    leave_distance: float = _field(
        2000.0, "a member this far from every other member is leaving, m", gt=0, le=1e6
    )
    leave_time: float = _field(5.0, "a member leaving this long is handed back, s", ge=0, le=1e6)
    max_coast_time: float = _field(
        10.0, "a member undetected this long is handed back, s", gt=0, le=1e6
    )

    def __post_init__(self) -> None:
        _check_bounds(self, "formation")

    @property
    def gate_threshold(self) -> float:
        """γ with P(χ²₂ ≤ γ) = P_G: γ = −2 ln(1 − P_G)."""
        return -2.0 * math.log1p(-self.gate_probability)


#: The multiple-model filters of point-pattern tracks (``point_patterns.filter``).
POINT_PATTERN_FILTERS = ("lmm", "imm")
#: Most reference patterns, most points in one, longest name, largest |coordinate| (m).
MAX_PATTERNS = 32
MAX_PATTERN_POINTS = 64
MAX_PATTERN_NAME = 64
MAX_PATTERN_COORDINATE = 1e4


def _check_patterns(patterns: Any) -> dict[str, tuple[tuple[float, float], ...]]:
    """The patterns as ``{name: ((x, y), ...)}`` with float coordinates; ``ValueError`` naming
    ``point_patterns.patterns.<name>`` for a name or a point set the tracker cannot use: at
    least 3 and at most :data:`MAX_PATTERN_POINTS` points, finite coordinates within
    ±:data:`MAX_PATTERN_COORDINATE` m, no two points closer than 1 mm, not all on one line."""
    where = "point_patterns.patterns"
    if not isinstance(patterns, dict):
        raise ValueError(f"{where}: expected an object of name -> points, got {patterns!r}")
    if len(patterns) > MAX_PATTERNS:
        raise ValueError(f"{where}: at most {MAX_PATTERNS} patterns, got {len(patterns)}")
    out: dict[str, tuple[tuple[float, float], ...]] = {}
    for name, points in patterns.items():
        if not isinstance(name, str) or not (0 < len(name) <= MAX_PATTERN_NAME):
            raise ValueError(f"{where}: a name must be 1 to {MAX_PATTERN_NAME} characters")
        at = f"{where}.{name}"
        if not isinstance(points, list | tuple) or not (3 <= len(points) <= MAX_PATTERN_POINTS):
            raise ValueError(f"{at}: expected 3 to {MAX_PATTERN_POINTS} points [[x, y], ...]")
        pts: list[tuple[float, float]] = []
        for i, p in enumerate(points):
            ok = isinstance(p, list | tuple) and len(p) == 2
            ok = ok and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                for v in p
            )
            if not ok or max(abs(float(v)) for v in p) > MAX_PATTERN_COORDINATE:
                raise ValueError(
                    f"{at}[{i}]: expected [x, y], finite numbers within "
                    f"±{MAX_PATTERN_COORDINATE:g} m, got {p!r}"
                )
            pts.append((float(p[0]), float(p[1])))
        for i in range(len(pts)):
            for j in range(i):
                if math.dist(pts[i], pts[j]) < 1e-3:
                    raise ValueError(f"{at}: points {j} and {i} coincide")
        (x0, y0), (x1, y1) = pts[0], max(pts, key=lambda q: math.dist(q, pts[0]))
        span = math.dist((x0, y0), (x1, y1))
        off = max(abs((x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)) / span for x, y in pts)
        if off < 1e-3:
            raise ValueError(f"{at}: the points are all on one line (no attitude to see)")
        out[name] = tuple(pts)
    return out


@dataclass(frozen=True)
class PointPatternConfig:
    """Bending extended targets with known point patterns (papers 000 and 001,
    :mod:`trackers.pattern`).

    ``patterns`` maps a reference pattern's name to its points ``[[x, y], ...]`` (m, in the
    target's own frame; at least 3). Each scan the detections near a track are matched to every
    pattern by the fast point-pattern matcher (rotation, translation and a scale within
    ``1 ± scale_tolerance``), and the track's state ``[x, vx, y, vy, α, α̇]`` (α the attitude:
    pattern point ``p`` is seen at ``(x, y) + R(α) p``) is estimated by a multiple-model filter
    over principal modes (constant velocity, acceleration noise ``accel_std_cv``; coordinated
    turns at ``±turn_rate``, ``accel_std_ct``), proper modes (constant attitude; constant
    attitude rate; ``attitude_accel_std``) and shape modes (one per pattern): the layered
    MM (``filter`` ``"lmm"``, one bank per layer, ``lmm_iterations`` of eq. 12) or the full
    IMM over every combination (``"imm"``). A pattern matched with at least ``min_matched``
    points in ``birth_scans`` scans in a row, moving no faster than ``max_speed`` (from the
    third scan on, where the first two lead: the same velocity and attitude rate within the
    noise and 2 g), starts a confirmed track; its detections start and update no individual
    track. A track is deleted after ``max_coast_time`` without a match, or when its score falls
    ``track_management.delete_drop_from_peak`` below its peak. No pattern, no cost.
    """

    enabled: bool = _field(True, "track targets that show a configured point pattern")
    patterns: dict[str, tuple[tuple[float, float], ...]] = field(
        default_factory=dict,
        metadata={
            "description": (
                "reference patterns: name -> [[x, y], ...] in metres in the target's frame "
                "(at least 3 points)"
            ),
            "length": (3, MAX_PATTERN_POINTS),
            "max_items": MAX_PATTERNS,
            "name_length": MAX_PATTERN_NAME,
        },
    )
    filter: str = _field(
        "lmm",
        'the multiple-model filter: "lmm" (layered MM, paper 001) or "imm" (full IMM, paper 000)',
        choices=POINT_PATTERN_FILTERS,
    )
    lmm_iterations: int = _field(
        0, "iterations of the layered MM's coupling (eq. 12; 0: eqs. 7 and 10 once)", ge=0, le=10
    )
    turn_rate: float = _field(
        3.0, "turn rate of the coordinated-turn modes (one each way), deg/s", gt=0, le=90.0
    )
    accel_std_cv: float = _field(
        0.5, "acceleration noise std of the constant-velocity mode, m/s² per axis", gt=0, le=1e3
    )
    accel_std_ct: float = _field(
        0.5, "acceleration noise std of the coordinated-turn modes, m/s² per axis", gt=0, le=1e3
    )
    attitude_accel_std: float = _field(
        0.05, "attitude acceleration noise std of the proper modes, rad/s²", gt=0, le=100.0
    )
    stay_probability: float = _field(
        0.95, "probability that a layer's mode stays the same from one scan to the next", gt=0, lt=1
    )
    scale_tolerance: float = _field(
        0.1, "matched patterns may be this much larger or smaller (relative)", gt=0, lt=1
    )
    min_matched: int = _field(
        3, "fewest matched points of a pattern that start a track", ge=3, le=MAX_PATTERN_POINTS
    )
    birth_scans: int = _field(
        3, "scans in a row a pattern must be matched to start a track", ge=2, le=100
    )
    max_speed: float = _field(
        700.0, "fastest target a start follows between matches, m/s", gt=0, le=1e5
    )
    max_coast_time: float = _field(
        10.0, "a track is deleted after this long without a match, s", gt=0, le=1e6
    )

    def __post_init__(self) -> None:
        _check_bounds(self, "point_patterns")
        if self.filter not in POINT_PATTERN_FILTERS:
            raise ValueError(
                f"point_patterns.filter: one of {list(POINT_PATTERN_FILTERS)}, got {self.filter!r}"
            )
        object.__setattr__(self, "patterns", _check_patterns(self.patterns))
        for name, pts in self.patterns.items():
            if len(pts) < self.min_matched:
                raise ValueError(
                    f"point_patterns.patterns.{name}: {len(pts)} points, fewer than "
                    f"point_patterns.min_matched ({self.min_matched})"
                )

    @property
    def turn_rate_rad(self) -> float:
        """The coordinated-turn modes' rate, rad/s."""
        return math.radians(self.turn_rate)


@dataclass(frozen=True)
class TrackerConfig:
    """Everything the trackers can be told."""

    association: AssociationConfig = field(default_factory=AssociationConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    measurement: MeasurementConfig = field(default_factory=MeasurementConfig)
    initiation: InitiationConfig = field(default_factory=InitiationConfig)
    gating: GatingConfig = field(default_factory=GatingConfig)
    track_management: TrackManagementConfig = field(default_factory=TrackManagementConfig)
    extended: ExtendedConfig = field(default_factory=ExtendedConfig)
    formation: FormationConfig = field(default_factory=FormationConfig)
    point_patterns: PointPatternConfig = field(default_factory=PointPatternConfig)

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
    if hint is bool:
        if isinstance(value, bool):
            return value
        raise ValueError(f"{path}: expected true or false, got {value!r}")
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
        args = get_args(hint)
        if len(args) != 2 or args[1] is not Ellipsis:  # fixed length: (float, float)
            if len(value) != len(args):
                raise ValueError(f"{path}: expected {len(args)} items, got {value!r}")
            return tuple(
                _typed(a, v, f"{path}[{i}]")
                for i, (a, v) in enumerate(zip(args, value, strict=True))
            )
        return tuple(_typed(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
    if get_origin(hint) is dict:
        if not isinstance(value, dict):
            raise ValueError(f"{path}: expected an object, got {value!r}")
        key, item = get_args(hint)
        return {_typed(key, k, path): _typed(item, v, f"{path}.{k}") for k, v in value.items()}
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
