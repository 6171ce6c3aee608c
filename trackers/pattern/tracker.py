"""The point-pattern tracker: bending extended targets as a peer of the individual tracker
(papers 000 and 001).

A target whose detections form a known pattern (``point_patterns.patterns``: a ship's
superstructure, an aircraft's scatterers) is tracked in position, velocity, attitude ``α``
and shape. Each scan (:meth:`PatternTracker.propose`, then :meth:`~PatternTracker.commit`):

1. **Gate.** For every track, the detections within reach of its predicted pattern (a k-d
   tree ball around the predicted origin, grown by the largest pattern's radius and the
   prediction's uncertainty) are its candidates.
2. **Associate and filter (paper 000's cycle).** The multiple-model filter
   (:mod:`.multiple_model`: the layered MM by default, the full IMM on request) predicts the
   track under every principal, proper and shape mode and asks, once per shape mode, for the
   matched detections: the size-aware validation gate (:func:`validation_gate`), then the
   FPPM (:func:`~trackers.pattern.fppm.match_fppm`) restricted by a match-flag prior to the
   detections within a chi-square gate of each predicted pattern point ``h_i(x̂)`` (eq. 40),
   so that the match it finds is the one the prediction allows. When the FPPM finds fewer
   than three consistent points, the predicted points are assigned to their gated detections
   by least Mahalanobis cost (at most one each), so one or two points still update the
   centre (and, with two, the attitude).
3. **Claim and score.** The detections matched under the likeliest shape are the track's:
   they update and start no individual track. The score grows by
   ``ln Σ_J μ_J⁻ Λ_J`` (``Λ_J`` the mode's likelihood ratio against clutter, which counts
   missed points by ``1 − P_D`` and matched ones by ``P_D N(ν; 0, S) / λ``). A track is
   deleted after ``max_coast_time`` without two matched points, or when its score falls
   ``track_management.delete_drop_from_peak`` below its peak.
4. **Birth.** The detections no track claimed are grouped by a link distance (the longest
   edge of the patterns' minimum spanning trees, grown by the scale tolerance and the
   noise); in each group of at least ``min_matched`` detections every pattern is sought by
   the FPPM (scale within ``1 ± scale_tolerance``, the registration's residual within a
   chi-square bound). A pattern seen so in ``birth_scans`` scans in a row, displaced no
   faster than ``max_speed``, starts a confirmed track from the latest registration: origin
   ``t``, attitude ``θ``, velocity from the displacement. The tentative individual tracks its
   detections had started are taken over (reported deleted).

Tracks can also be started by hand (:meth:`PatternTracker.start`). Their Track snapshot has
``kind`` ``extended``, the position and velocity of the target frame's origin, ``attitude``,
``shape_probabilities`` by pattern name, ``model_probabilities`` of the principal and proper
layers (each summing to 1), and an ``extent``: the ellipse about the origin that holds the
likeliest pattern's points at the track's attitude.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.spatial import cKDTree
from scipy.stats import chi2

from trackers.config import (
    ExtendedConfig,
    PointPatternConfig,
    TrackerConfig,
    TrackManagementConfig,
)
from trackers.coverage import Coverage
from trackers.extended.tracker import _grown, extent_ellipse
from trackers.pattern.bending import (
    PrincipalModel,
    ProperModel,
    predict_mixture,
)
from trackers.pattern.fppm import PatternMatch, match_fppm
from trackers.pattern.multiple_model import (
    BendingModes,
    MMEstimate,
    imm_step,
    initial_estimate,
    lmm_step,
    transition_by_changes,
    validation_gate,
)
from trackers.pattern.registration import rotation, wrap_angle
from trackers.pattern.state import PatternCheckpoint, read_state
from trackers.peers import PeerProposal, PointTrackView, ResolutionCell, SavesImmutableState
from trackers.types import Scan, TrackSnapshot

__all__ = [
    "MAX_GROUP_SIZE",
    "PatternTrack",
    "PatternTracker",
    "modes_of",
    "pattern_snapshot",
]

#: Principal mode names (snapshot ``model_probabilities``): constant velocity, coordinated
#: turns counter-clockwise and clockwise at ``turn_rate``.
PRINCIPAL_NAMES = ("cv", "ct_ccw", "ct_cw")
#: Proper mode names: attitude held, attitude turning at an estimated rate.
PROPER_NAMES = ("attitude_hold", "attitude_turn")
#: Largest group of unclaimed detections the birth search matches patterns in: a denser
#: patch is clutter or many targets, and the FPPM's cost grows with its size squared.
MAX_GROUP_SIZE = 80
#: Probability of the chi-square gates around each predicted pattern point.
POINT_GATE_PROBABILITY = 0.999
#: Probability of the size-aware validation gate of a track's predicted origin.
VALIDATION_PROBABILITY = 0.9999
#: The FPPM's similarity-test false-rejection rate.
FALSE_REJECTION = 0.01
#: A birth sighting's registration residual bound: ``p · mse / σ² ≤ χ²_{2p−4}(this)``.
SIGHTING_PROBABILITY = 0.999
#: Most candidate sightings kept between scans (the oldest go first).
MAX_CANDIDATES = 1000
#: Prior probability of a new track's matched pattern (the rest share what is left).
BIRTH_SHAPE_PROBABILITY = 0.8
#: Prior principal and proper mode probabilities of a new track.
BIRTH_PRINCIPAL = (0.8, 0.1, 0.1)
BIRTH_PROPER = (0.7, 0.3)
#: Largest acceleration (m/s²) a candidate may show between the scans that start it: the third
#: sighting must be where the first two lead, within this and the noise.
BIRTH_ACCELERATION = 20.0
#: Fastest attitude change between two sightings of a candidate, rad/s (and a margin, rad).
MAX_ATTITUDE_RATE = 0.5
ATTITUDE_MARGIN = 0.2
#: Attitude-rate standard deviation of a new track, rad/s (paper 000: 2°/s).
BIRTH_ATTITUDE_RATE_STD = math.radians(2.0)


@dataclass(frozen=True, eq=False)
class PatternTrack:
    """One point-pattern track as of ``time`` (immutable)."""

    id: str
    estimate: MMEstimate
    shapes: tuple[str, ...]
    time: float
    score: float
    peak: float
    hits: int
    created: float
    updated: float
    #: The likeliest shape's reference points (the configuration's array, not a copy).
    pattern_points: np.ndarray
    detection_ids: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class _Sighting:
    """A pattern found in one scan's unclaimed detections (birth search)."""

    shape: int
    origin: tuple[float, float]
    attitude: float
    time: float
    rows: tuple[int, ...]
    support: int
    sigma: float
    seen: int = 1
    velocity: tuple[float, float] | None = None
    attitude_rate: float = 0.0
    #: The interval over which ``velocity`` was measured (s).
    baseline: float = 0.0


@dataclass(frozen=True, eq=False)
class _State:
    config: PointPatternConfig
    management: TrackManagementConfig
    modes: BendingModes | None
    #: The extended section: its resolution distance and in-cell detection probability make
    #: the pattern tracks' resolution cells.
    hybrid: ExtendedConfig = field(default_factory=ExtendedConfig)
    tracks: tuple[PatternTrack, ...] = ()
    candidates: tuple[_Sighting, ...] = ()
    next_id: int = 1
    time: float | None = None
    #: Each sensor's latest scan time: a candidate seen again must have been seen since the
    #: same sensor's previous scan ("consecutive scans").
    sensor_times: tuple[tuple[str, float], ...] = ()


def modes_of(cfg: PointPatternConfig) -> BendingModes | None:
    """The mode set of the configuration: principal CV and CT at ``±turn_rate``, proper
    attitude-hold (rate 0) and attitude-turn (rate estimated), one shape per pattern, and the
    transition matrix of paper 000 with ``stay_probability`` on its diagonal; ``None`` without
    patterns."""
    if not cfg.patterns:
        return None
    w = cfg.turn_rate_rad
    principal = (
        PrincipalModel(PRINCIPAL_NAMES[0], 0.0, cfg.accel_std_cv),
        PrincipalModel(PRINCIPAL_NAMES[1], w, cfg.accel_std_ct),
        PrincipalModel(PRINCIPAL_NAMES[2], -w, cfg.accel_std_ct),
    )
    proper = (
        ProperModel(PROPER_NAMES[0], 0.0, cfg.attitude_accel_std),
        ProperModel(PROPER_NAMES[1], None, cfg.attitude_accel_std),
    )
    shapes = {name: np.array(points, dtype=float) for name, points in cfg.patterns.items()}
    sizes = (len(principal), len(proper), len(shapes))
    Pi = transition_by_changes(sizes, diagonal=cfg.stay_probability)
    return BendingModes(principal, proper, shapes, Pi)


def _link_distance(patterns: tuple[np.ndarray, ...], tolerance: float, sigma: float) -> float:
    """Longest edge of any pattern's minimum spanning tree, grown by the scale tolerance and
    ``4σ√2``: the detections of one pattern are linked at this distance."""
    return _longest_spanning_edge(patterns) * (1.0 + tolerance) + 4.0 * math.sqrt(2.0) * sigma


@lru_cache(maxsize=64)
def _longest_edge(points: tuple[tuple[float, float], ...]) -> float:
    q = np.array(points)
    d = np.sqrt(((q[:, None] - q[None]) ** 2).sum(axis=2))
    return float(minimum_spanning_tree(d).toarray().max())


def _longest_spanning_edge(patterns: tuple[np.ndarray, ...]) -> float:
    return max(_longest_edge(tuple(map(tuple, q.tolist()))) for q in patterns)


def _sigma(R: np.ndarray) -> float:
    """Per-axis noise standard deviation of detection covariances ``(n, 2, 2)``: the root of
    their mean half trace."""
    return math.sqrt(max(float(np.mean(R[:, 0, 0] + R[:, 1, 1])) / 2.0, 1e-12))


def _shape_extent(pattern: np.ndarray, attitude: float) -> np.ndarray:
    """The ellipse ``pᵀ X⁻¹ p ≤ 1`` about the origin that holds every point of ``pattern`` at
    ``attitude``: its second moment ``C = mean(q qᵀ)``, rotated, scaled by
    ``max qᵢᵀ C⁻¹ qᵢ``."""
    q = pattern
    C = q.T @ q / len(q) + 1e-6 * np.eye(2)
    k = float(np.max(np.einsum("ni,ij,nj->n", q, np.linalg.inv(C), q)))
    Rm = rotation(attitude)
    return Rm @ (max(k, 1.0) * C) @ Rm.T


def _cells(snaps: Sequence[TrackSnapshot], ext: ExtendedConfig) -> tuple[ResolutionCell, ...]:
    """The resolution cells of the pattern tracks (paper 002's hybridization, as for extended
    tracks): each one's pattern ellipse about its position, grown by half of
    ``extended.resolution_distance``; individual tracks inside have detection probability
    ``extended.in_cell_pd`` (the target's own returns mask theirs)."""
    half = 0.5 * ext.resolution_distance
    return tuple(
        ResolutionCell(np.asarray(s.position), _grown(s.extent.matrix, half)[0], ext.in_cell_pd)
        for s in snaps
        if s.extent is not None
    )


def pattern_snapshot(track: PatternTrack) -> TrackSnapshot:
    """The track as a Track snapshot at its own time (``kind`` ``extended``)."""
    est = track.estimate
    x = est.x
    idx = np.array([0, 2, 1, 3])
    cov = np.array(est.P[np.ix_(idx, idx)], dtype=float)
    cov.flags.writeable = False
    mu_g, mu_p, mu_s = est.layer_probabilities
    models = {n: float(v) for n, v in zip(PRINCIPAL_NAMES, mu_g, strict=False)}
    models.update({n: float(v) for n, v in zip(PROPER_NAMES, mu_p, strict=False)})
    shapes = {n: float(v) for n, v in zip(track.shapes, mu_s, strict=True)}
    return TrackSnapshot(
        id=track.id,
        kind="extended",
        status="confirmed",
        time=float(track.time),
        position=(float(x[0]), float(x[2])),
        velocity=(float(x[1]), float(x[3])),
        covariance=cov,
        score=float(track.score),
        hits=int(track.hits),
        created=float(track.created),
        updated=float(track.updated),
        model_probabilities=models,
        detection_ids=track.detection_ids,
        extent=extent_ellipse(_shape_extent(track.pattern_points, float(x[4]))),
        attitude=wrap_angle(float(x[4])),
        shape_probabilities=shapes,
    )


def _logsumexp(a: np.ndarray, w: np.ndarray) -> float:
    """``ln Σ wᵢ e^{aᵢ}`` without overflow (``w > 0``)."""
    a = np.asarray(a, dtype=float) + np.log(w)
    top = float(a.max())
    return top + math.log(float(np.exp(a - top).sum())) if math.isfinite(top) else top


@dataclass(frozen=True, eq=False)
class _ModePredictions:
    """A track's combined estimate predicted to the scan under every (principal, proper)
    model pair: ``x (K, 6)``, the observed block ``P_o (K, 3, 3)`` over ``(x, y, α)``, and
    the pairs' prior weights ``w (K,)``; ``spread`` is ``Σ_k (x_k − x̄)(x_k − x̄)ᵀ``, which,
    added to a prediction's covariance, makes a gate hold every pair's prediction (a turn's
    onset moves the target off the likeliest mode's prediction by many of its σ)."""

    x: np.ndarray
    P_o: np.ndarray
    w: np.ndarray
    spread: np.ndarray


#: Weight of the uniform part of the mode weights of an association (a manoeuvre's onset must
#: be able to win over the mode that held until then).
MODE_WEIGHT_FLOOR = 0.1


def _mode_predictions(est: MMEstimate, dt: float, modes: BendingModes) -> _ModePredictions:
    r_g, r_p = len(modes.principal), len(modes.proper)
    K = r_g * r_p
    X, Ps = predict_mixture(
        np.broadcast_to(est.x, (K, 6)),
        np.broadcast_to(est.P, (K, 6, 6)),
        dt,
        modes.principal,
        modes.proper,
        np.repeat(np.eye(r_g), r_p, axis=0),
        np.tile(np.eye(r_p), (r_g, 1)),
    )
    obs = np.array([0, 2, 4])
    P_o = Ps[:, obs][:, :, obs]
    mu_g, mu_p = est.layer_probabilities[0], est.layer_probabilities[1]
    f = MODE_WEIGHT_FLOOR
    w = np.outer(
        (1 - f) * mu_g + f / len(mu_g),
        (1 - f) * mu_p + f / len(mu_p),
    ).reshape(-1)
    d = X - X.mean(axis=0)
    return _ModePredictions(x=X, P_o=P_o, w=w / w.sum(), spread=d.T @ d)


def _point_terms(
    modes: _ModePredictions, pattern: np.ndarray, z: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per mode pair ``k``, pattern point ``i`` and detection ``j``: the Mahalanobis distance
    ``d²[k, i, j]`` of ``z_j`` from the predicted point ``h_i(x_k)`` (eq. 40) under
    ``S_ki = D_i P_o,k D_iᵀ + R`` (``D_i = [I₂ | ∂h_i/∂α]``, eq. 41), and ``ln det S_ki``."""
    x = modes.x
    c, s = np.cos(x[:, 4]), np.sin(x[:, 4])
    qx, qy = pattern[:, 0], pattern[:, 1]
    hx = x[:, 0, None] + c[:, None] * qx - s[:, None] * qy
    hy = x[:, 2, None] + s[:, None] * qx + c[:, None] * qy
    rx = -s[:, None] * qx - c[:, None] * qy  # ∂h/∂α
    ry = c[:, None] * qx - s[:, None] * qy
    P = modes.P_o
    # S = D P Dᵀ + R with D = [[1, 0, rx], [0, 1, ry]], written out.
    a = P[:, None, 0, 0] + 2 * rx * P[:, None, 0, 2] + rx * rx * P[:, None, 2, 2] + R[0, 0]
    b = (
        P[:, None, 0, 1]
        + rx * P[:, None, 2, 1]
        + ry * P[:, None, 0, 2]
        + rx * ry * P[:, None, 2, 2]
        + R[0, 1]
    )
    cc = P[:, None, 1, 1] + 2 * ry * P[:, None, 1, 2] + ry * ry * P[:, None, 2, 2] + R[1, 1]
    det = a * cc - b * b
    dx = z[None, None, :, 0] - hx[:, :, None]
    dy = z[None, None, :, 1] - hy[:, :, None]
    d2 = (cc[..., None] * dx * dx - 2 * b[..., None] * dx * dy + a[..., None] * dy * dy) / det[
        ..., None
    ]
    return d2, np.log(det)


#: The detection probability of a track out of the scan's view: its prediction, with no
#: detection and a score that moves by no more than ln(1 − 1e-12) a point.
_UNSEEN_PD = 1e-12


@dataclass(frozen=True)
class _ScanTerms:
    """What every track's update takes from one scan, computed once: its detection
    probability ``P_D`` and false-alarm density ``λ``, ``ln(P_D / λ) − ln 2π`` (a matched
    point's log-likelihood ratio without its Gaussian exponent and determinant),
    ``ln(1 − P_D)`` (a missed point's) and the detections' per-axis noise σ."""

    pd: float
    lam: float
    log_hit: float
    log_miss: float
    sigma: float

    @classmethod
    def of(cls, scan: Scan, tm: TrackManagementConfig) -> _ScanTerms:
        pd = tm.pd if scan.pd is None else float(scan.pd)
        lam = tm.clutter_density if scan.clutter_density is None else float(scan.clutter_density)
        return cls(
            pd=pd,
            lam=lam,
            log_hit=math.log(pd / lam) - math.log(2.0 * math.pi),
            log_miss=math.log1p(-min(pd, 1.0 - 1e-9)),
            sigma=_sigma(scan.R) if scan.size else 0.0,
        )


def _association_log_ratio(
    pairs: np.ndarray,
    d2: np.ndarray,
    logdet: np.ndarray,
    w: np.ndarray,
    m: int,
    terms: _ScanTerms,
) -> float:
    """``ln Σ_k w_k Λ_k`` of an association, ``Λ_k`` its likelihood ratio against all clutter
    under mode pair ``k``: ``Π_pairs P_D N(ν_ki; 0, S_ki) / λ · (1 − P_D)^{m − p}``."""
    i, j = pairs[:, 0], pairs[:, 1]
    per = terms.log_hit - 0.5 * (logdet[:, i] + d2[:, i, j])
    return _logsumexp(per.sum(axis=1) + (m - len(pairs)) * terms.log_miss, w)


def _likeliest_assignment(
    d2: np.ndarray, logdet: np.ndarray, gated: np.ndarray, terms: _ScanTerms
) -> np.ndarray:
    """Under one mode pair: pattern points to detections (or missed), one to one, of least
    cost ``−ln(P_D N/λ)`` per pair against ``−ln(1 − P_D)`` per miss (the assignment
    problem with a miss column per point); only gated pairs."""
    m, n = d2.shape
    if not gated.any():
        return np.zeros((0, 2), dtype=np.int64)
    pair_cost = -terms.log_hit + 0.5 * (logdet[:, None] + d2)
    big = 1e12
    cost = np.full((m, n + m), big)
    cost[:, :n] = np.where(gated, pair_cost, big)
    cost[np.arange(m), n + np.arange(m)] = -terms.log_miss
    rows, cols = linear_sum_assignment(cost)
    keep = cols < n
    keep &= cost[rows, cols] < big
    return np.column_stack([rows[keep], cols[keep]]).astype(np.int64)


class PatternTracker(SavesImmutableState):
    """Bending extended targets with known point patterns; a peer of the point tracker
    (:class:`trackers.peers.PeerTracker`). See the module docstring for the step."""

    kind = "point_patterns"
    _checkpoint_type = PatternCheckpoint
    _kept_on_reset = ("config", "management", "modes", "hybrid", "next_id")
    _read_state = staticmethod(read_state)

    def __init__(self, config: TrackerConfig | None = None, *, id_prefix: str = "") -> None:
        """``id_prefix`` goes before every new track's id (``{id_prefix}B3``)."""
        config = config or TrackerConfig()
        self.id_prefix = id_prefix
        cfg = config.point_patterns
        self._state = _State(
            config=cfg,
            management=config.track_management,
            modes=modes_of(cfg),
            hybrid=config.extended,
        )

    # -- the peer interface ------------------------------------------------------------------

    @property
    def tracks(self) -> tuple[PatternTrack, ...]:
        return self._state.tracks

    @property
    def modes(self) -> BendingModes | None:
        """The mode set in force (``None`` without patterns)."""
        return self._state.modes

    def reconfigure(self, config: TrackerConfig) -> None:
        """From the next scan on: the new section; tracks are kept, their shape probabilities
        carried over by pattern name (a pattern removed loses its share; one added starts
        with a small one), and re-made when the filter changes."""
        state = self._state
        cfg = config.point_patterns
        modes = state.modes if cfg == state.config else modes_of(cfg)
        tracks = state.tracks
        if modes is not None and modes is not state.modes:
            tracks = tuple(self._adapted(tr, modes, cfg) for tr in tracks)
        self._state = replace(
            state,
            config=cfg,
            management=config.track_management,
            hybrid=config.extended,
            modes=modes,
            tracks=tracks if modes is not None else state.tracks,
            candidates=() if modes is not state.modes else state.candidates,
        )

    @staticmethod
    def _adapted(track: PatternTrack, modes: BendingModes, cfg: PointPatternConfig) -> PatternTrack:
        names = modes.layers[2]
        old = dict(zip(track.shapes, track.estimate.layer_probabilities[2], strict=True))
        mu_s = np.array([old.get(n, 0.0) for n in names]) + 0.05 / len(names)
        mu_g, mu_p = track.estimate.layer_probabilities[:2]
        est = initial_estimate(
            modes,
            track.estimate.x,
            track.estimate.P,
            algorithm=cfg.filter,
            layer_probabilities=(mu_g, mu_p, mu_s / mu_s.sum()),
        )
        best = int(np.argmax(est.layer_probabilities[2]))
        return replace(track, estimate=est, shapes=names, pattern_points=modes.patterns[best])

    def commit(self, proposal: PeerProposal) -> None:
        if isinstance(proposal.state, _State):
            self._state = proposal.state

    def snapshot(self) -> tuple[TrackSnapshot, ...]:
        return tuple(pattern_snapshot(t) for t in self._state.tracks)

    def start(
        self,
        time: float,
        pattern: str,
        position: Sequence[float] | np.ndarray,
        velocity: Sequence[float] | np.ndarray,
        attitude: float,
        *,
        attitude_rate: float = 0.0,
        position_std: float = 10.0,
        velocity_std: float = 5.0,
        attitude_std: float = 0.1,
    ) -> PatternTrack:
        """Start a confirmed track by hand at ``time`` (not before the last scan) showing the
        configured ``pattern``, its frame's origin at ``position`` with ``velocity`` and
        ``attitude`` (rad). Returns it; raises ``ValueError`` for an unknown pattern or
        unusable values, and changes nothing then."""
        state = self._state
        cfg, modes = state.config, state.modes
        if not math.isfinite(time) or (state.time is not None and time < state.time):
            raise ValueError(f"time: must be finite and not before {state.time}, got {time!r}")
        if modes is None or pattern not in cfg.patterns:
            known = sorted(cfg.patterns)
            raise ValueError(f"pattern: {pattern!r} is not configured (point_patterns: {known})")
        for name, v in (
            ("position_std", position_std),
            ("velocity_std", velocity_std),
            ("attitude_std", attitude_std),
        ):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
        pos = np.asarray(position, dtype=float).reshape(2)
        vel = np.asarray(velocity, dtype=float).reshape(2)
        x = np.array([pos[0], vel[0], pos[1], vel[1], float(attitude), float(attitude_rate)])
        if not np.isfinite(x).all():
            raise ValueError("position, velocity, attitude: must be finite numbers")
        P = np.diag(
            [
                position_std**2,
                velocity_std**2,
                position_std**2,
                velocity_std**2,
                attitude_std**2,
                BIRTH_ATTITUDE_RATE_STD**2,
            ]
        )
        track = self._new_track(state, modes, cfg, x, P, modes.layers[2].index(pattern), time)
        self._state = replace(state, tracks=(*state.tracks, track), next_id=state.next_id + 1)
        return track

    def _new_track(
        self,
        state: _State,
        modes: BendingModes,
        cfg: PointPatternConfig,
        x: np.ndarray,
        P: np.ndarray,
        shape: int,
        t: float,
        detection_ids: tuple[str, ...] = (),
    ) -> PatternTrack:
        r_s = modes.sizes[2]
        mu_s = np.full(r_s, (1.0 - BIRTH_SHAPE_PROBABILITY) / max(r_s - 1, 1))
        mu_s[shape] = BIRTH_SHAPE_PROBABILITY if r_s > 1 else 1.0
        est = initial_estimate(
            modes,
            x,
            P,
            algorithm=cfg.filter,
            layer_probabilities=(np.array(BIRTH_PRINCIPAL), np.array(BIRTH_PROPER), mu_s),
        )
        score = state.management.confirm_threshold
        return PatternTrack(
            id=f"{self.id_prefix}B{state.next_id}",
            estimate=est,
            shapes=modes.layers[2],
            time=float(t),
            score=score,
            peak=score,
            hits=1,
            created=float(t),
            updated=float(t),
            pattern_points=modes.patterns[shape],
            detection_ids=detection_ids,
        )

    # -- one scan ----------------------------------------------------------------------------

    def propose(self, scan: Scan, view: PointTrackView) -> PeerProposal:
        state = self._state
        cfg, tm, modes = state.config, state.management, state.modes
        t = float(scan.time)
        claimed = np.zeros(scan.size, dtype=bool)
        if not cfg.enabled or modes is None:
            gone = tuple(tr.id for tr in state.tracks)
            new_state = replace(state, tracks=(), candidates=(), time=t)
            return PeerProposal(claimed=claimed, deleted=gone, state=new_state)
        if not state.tracks and not state.candidates and scan.size < cfg.min_matched:
            return PeerProposal(claimed=claimed, state=replace(state, time=t))
        terms = _ScanTerms.of(scan, tm)
        tree = cKDTree(scan.z) if scan.size else None
        kept: list[PatternTrack] = []
        deleted: list[str] = []
        unseen = replace(terms, pd=_UNSEEN_PD, log_miss=math.log1p(-_UNSEEN_PD))
        for track in state.tracks:
            if scan.coverage is not None and not _in_view(track, t, scan.coverage, modes, cfg):
                # out of this sensor's view: predicted to the scan, its score left alone
                new = self._update(track, scan, None, claimed, cfg, modes, unseen)
                new = replace(new, score=track.score, peak=track.peak)
            else:
                new = self._update(track, scan, tree, claimed, cfg, modes, terms)
            dead = (t - new.updated > cfg.max_coast_time) or (
                new.peak - new.score > tm.delete_drop_from_peak
            )
            if dead:
                deleted.append(new.id)
            else:
                kept.append(new)
        # Births from the detections no track claimed, away from every track.
        sightings = self._sightings(scan, claimed, modes, cfg, kept) if scan.size else []
        times = dict(state.sensor_times)
        since = times.get(scan.sensor_id, -math.inf)
        times[scan.sensor_id] = t
        candidates, born, next_id = self._births(state, sightings, scan, since, cfg, modes)
        take: tuple[str, ...] = ()
        for track, rows in born:
            claimed[list(rows)] = True
            kept.append(track)
        if born and len(view):
            take = _taken([tr for tr, _ in born], view)
        new_state = replace(
            state,
            tracks=tuple(kept),
            candidates=candidates,
            next_id=next_id,
            time=t,
            sensor_times=tuple(times.items()),
        )
        snaps = tuple(pattern_snapshot(tr) for tr in kept)
        return PeerProposal(
            claimed=claimed,
            take=take,
            tracks=snaps,
            deleted=tuple(deleted) + take,
            cells=_cells(snaps, state.hybrid),
            state=new_state,
        )

    def _update(
        self,
        track: PatternTrack,
        scan: Scan,
        tree: cKDTree | None,
        claimed: np.ndarray,
        cfg: PointPatternConfig,
        modes: BendingModes,
        terms: _ScanTerms,
    ) -> PatternTrack:
        """The track after this scan (paper 000's cycle); marks its detections in
        ``claimed``."""
        t = float(scan.time)
        est = track.estimate
        dt = max(t - track.time, 0.0)
        x, P = est.x, est.P
        reach = float(modes.radii.max()) * (1.0 + cfg.scale_tolerance)
        centre = np.array([x[0] + x[1] * dt, x[2] + x[3] * dt])
        spread = P[0, 0] + P[2, 2] + dt * dt * (P[1, 1] + P[3, 3])
        speed = math.hypot(x[1], x[3])
        turn = 0.5 * speed * cfg.turn_rate_rad * dt * dt + 0.5 * cfg.accel_std_cv * dt * dt
        rows = np.zeros(0, dtype=np.int64)
        if tree is not None:
            radius = reach + turn + 5.0 * math.sqrt(spread + terms.sigma**2 * 2.0)
            near = np.asarray(tree.query_ball_point(centre, radius), dtype=np.int64)
            rows = np.sort(near[~claimed[near]]) if near.size else rows
        z = np.take(scan.z, rows, axis=0)
        R = (
            np.mean(np.take(scan.R, rows, axis=0), axis=0)
            if rows.size
            else np.mean(scan.R, axis=0)
            if scan.size
            else np.eye(2)
        )
        R = 0.5 * (R + R.T)
        sigma = math.sqrt(max(0.5 * float(R[0, 0] + R[1, 1]), 1e-12))
        scale = (1.0 - cfg.scale_tolerance, 1.0 + cfg.scale_tolerance)

        preds = _mode_predictions(est, dt, modes) if len(z) else None
        gate = -2.0 * math.log1p(-POINT_GATE_PROBABILITY)

        def associate(s: int, x_pred: np.ndarray, P_pred: np.ndarray) -> np.ndarray:
            if preds is None:
                return np.zeros((0, 2), dtype=np.int64)
            pattern = modes.patterns[s]
            near_s = validation_gate(
                z,
                x_pred,
                P_pred + preds.spread,
                R,
                float(modes.radii[s]) * scale[1],
                probability=VALIDATION_PROBABILITY,
            )
            if not len(near_s):
                return np.zeros((0, 2), dtype=np.int64)
            zs = np.take(z, near_s, axis=0)
            d2, logdet = _point_terms(preds, pattern, zs, R)
            gated = d2 <= gate
            m = len(pattern)
            # Candidates: each mode pair's likeliest assignment, and the FPPM's match (the
            # largest geometrically consistent set) among the pairs some mode gates; the
            # likeliest under the mixture of mode pairs is the association.
            options = [
                _likeliest_assignment(d2[k], logdet[k], gated[k], terms)
                for k in range(len(preds.w))
            ]
            union = gated.any(axis=0)
            if union.any(axis=1).sum() >= 3:
                match = match_fppm(
                    pattern,
                    zs,
                    sigma,
                    scale_range=scale,
                    w_max=m - 1,
                    false_rejection=FALSE_REJECTION,
                    mflag=union,
                )
                if match is not None:
                    options.append(np.array(match.pairs, dtype=np.int64))
            scores = [_association_log_ratio(o, d2, logdet, preds.w, m, terms) for o in options]
            pairs = options[int(np.argmax(scores))]
            if not len(pairs):
                return pairs
            return np.column_stack([pairs[:, 0], np.take(near_s, pairs[:, 1])])

        step = lmm_step if cfg.filter == "lmm" else imm_step
        kwargs = {"iterations": cfg.lmm_iterations} if cfg.filter == "lmm" else {}
        new_est, info = step(
            est, dt, z, R, associate, modes, pd=terms.pd, clutter_density=terms.lam, **kwargs
        )
        # ln Σ μ⁻ Λ over the shape layer's hypotheses (the IMM: over every mode).
        r_s = modes.sizes[2]
        if cfg.filter == "lmm":
            lnL = info.log_likelihoods[-r_s:]
            prior = info.predicted_layer_probabilities[2]
        else:
            lnL = info.log_likelihoods
            prior = est.filter_probabilities @ modes.transition
        gain = _logsumexp(lnL, np.maximum(prior, 1e-300))
        # The hypothesis that none of the detections is the target's is always there: the
        # likelihood ratio is at least that of every point missed, Σ_s μ_s (1 − P_D)^{m_s}.
        missed = _logsumexp(
            np.array([len(q) * terms.log_miss for q in modes.patterns]),
            np.maximum(est.layer_probabilities[2], 1e-300),
        )
        # (With no detection near the track the likelihood is that one already.)
        gain = float(np.logaddexp(gain, missed)) if len(z) else missed
        best = int(np.argmax(new_est.layer_probabilities[2]))
        pairs = info.pairs[best]
        matched = np.zeros(0, dtype=np.int64) if pairs is None else np.take(rows, pairs[:, 1])
        claimed[matched] = True
        ids = tuple(str(scan.detection_ids[j]) for j in matched.tolist() if scan.detection_ids[j])
        score = track.score + gain
        return replace(
            track,
            estimate=new_est,
            time=t,
            score=score,
            peak=max(track.peak, score),
            hits=track.hits + (1 if len(matched) >= 2 else 0),
            updated=t if len(matched) >= 2 else track.updated,
            pattern_points=modes.patterns[best],
            detection_ids=ids,
        )

    def _sightings(
        self,
        scan: Scan,
        claimed: np.ndarray,
        modes: BendingModes,
        cfg: PointPatternConfig,
        tracks: list[PatternTrack],
    ) -> list[_Sighting]:
        """Patterns found in the unclaimed detections, at most one per group of linked
        detections (the largest support, then the smallest residual); groups within reach
        of a track are not searched (:func:`_near_tracks`)."""
        free = np.flatnonzero(~claimed)
        if free.size < cfg.min_matched:
            return []
        z = np.take(scan.z, free, axis=0)
        sigma = _sigma(np.take(scan.R, free, axis=0))
        link = _link_distance(modes.patterns, cfg.scale_tolerance, sigma)
        pairs = cKDTree(z).query_pairs(link, output_type="ndarray")
        n = len(z)
        if not len(pairs):
            return []
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        count, label = connected_components(graph, directed=False)
        sizes = np.bincount(label, minlength=count)
        scale = (1.0 - cfg.scale_tolerance, 1.0 + cfg.scale_tolerance)
        out: list[_Sighting] = []
        for g in np.flatnonzero((sizes >= cfg.min_matched) & (sizes <= MAX_GROUP_SIZE)).tolist():
            members = np.flatnonzero(label == g)
            zg = np.take(z, members, axis=0)
            if tracks and _near_tracks(zg.mean(axis=0), tracks, modes, cfg, sigma):
                continue
            best: tuple[int, PatternMatch] | None = None
            for s, pattern in enumerate(modes.patterns):
                match = match_fppm(
                    pattern,
                    zg,
                    sigma,
                    scale_range=scale,
                    w_min=cfg.min_matched - 1,
                    false_rejection=FALSE_REJECTION,
                )
                if match is None or not _plausible(match, sigma):
                    continue
                if best is None or (match.support, -match.mse) > (
                    best[1].support,
                    -best[1].mse,
                ):
                    best = (s, match)
            if best is None:
                continue
            s, match = best
            G = match.registration
            rows = tuple(int(free[members[j]]) for j in match.pairs[:, 1].tolist())
            out.append(
                _Sighting(
                    shape=s,
                    origin=(float(G.t[0]), float(G.t[1])),
                    attitude=float(G.theta),
                    time=float(scan.time),
                    rows=rows,
                    support=match.support,
                    sigma=sigma,
                )
            )
        return out

    def _births(
        self,
        state: _State,
        sightings: list[_Sighting],
        scan: Scan,
        since: float,
        cfg: PointPatternConfig,
        modes: BendingModes,
    ) -> tuple[tuple[_Sighting, ...], list[tuple[PatternTrack, tuple[int, ...]]], int]:
        """Candidates seen again, new candidates, and the tracks born this scan (with the rows
        of their detections). A candidate is seen again by a sighting of the same pattern
        in this scan if it was seen since this sensor's previous scan (``since``), is
        displaced no faster than ``max_speed`` and turned no faster than
        :data:`MAX_ATTITUDE_RATE`; candidates not seen since then are dropped."""
        t = float(scan.time)
        old = [c for c in state.candidates if since <= c.time < t]
        used: set[int] = set()
        candidates: list[_Sighting] = []
        born: list[tuple[PatternTrack, tuple[int, ...]]] = []
        next_id = state.next_id
        for sg in sightings:
            best_k, best_d = -1, math.inf
            for k, c in enumerate(old):
                if k in used or c.shape != sg.shape:
                    continue
                dt = t - c.time
                if c.velocity is None:  # from one sighting: any speed up to max_speed
                    d = math.dist(c.origin, sg.origin)
                    turned = abs(wrap_angle(sg.attitude - c.attitude))
                    ok = turned <= MAX_ATTITUDE_RATE * dt + ATTITUDE_MARGIN
                    ok = ok and d <= cfg.max_speed * dt + 6.0 * sg.sigma
                else:  # from two or more: where its velocity and attitude rate lead
                    guess = (c.origin[0] + c.velocity[0] * dt, c.origin[1] + c.velocity[1] * dt)
                    d = math.dist(guess, sg.origin)
                    spread = 2.0 * sg.sigma * (1.0 + dt / c.baseline)
                    turned = abs(wrap_angle(sg.attitude - c.attitude - c.attitude_rate * dt))
                    ok = turned <= ATTITUDE_MARGIN * (1.0 + dt / c.baseline)
                    ok = ok and d <= 3.0 * spread + 0.5 * BIRTH_ACCELERATION * dt * dt
                if ok and d < best_d:
                    best_k, best_d = k, d
            if best_k < 0:
                candidates.append(sg)
                continue
            used.add(best_k)
            c = old[best_k]
            dt = t - c.time
            v = ((sg.origin[0] - c.origin[0]) / dt, (sg.origin[1] - c.origin[1]) / dt)
            rate = wrap_angle(sg.attitude - c.attitude) / dt
            seen = replace(sg, seen=c.seen + 1, velocity=v, attitude_rate=rate, baseline=dt)
            if seen.seen < cfg.birth_scans:
                candidates.append(seen)
                continue
            pos_var = 4.0 * sg.sigma**2
            vel_var = 2.0 * pos_var / (dt * dt) + (cfg.accel_std_cv * dt) ** 2
            radius = float(modes.radii[sg.shape])
            att_var = (2.0 * sg.sigma / max(radius, 1e-3)) ** 2 + 1e-4
            x = np.array([sg.origin[0], v[0], sg.origin[1], v[1], sg.attitude, rate])
            P = np.diag(
                [
                    pos_var,
                    vel_var,
                    pos_var,
                    vel_var,
                    att_var,
                    2.0 * att_var / (dt * dt) + BIRTH_ATTITUDE_RATE_STD**2,
                ]
            )
            ids = tuple(str(scan.detection_ids[j]) for j in sg.rows if scan.detection_ids[j])
            track = self._new_track(
                replace(state, next_id=next_id), modes, cfg, x, P, sg.shape, t, ids
            )
            next_id += 1
            born.append((track, sg.rows))
        return tuple(candidates[-MAX_CANDIDATES:]), born, next_id


def _near_tracks(
    point: np.ndarray,
    tracks: list[PatternTrack],
    modes: BendingModes,
    cfg: PointPatternConfig,
    sigma: float,
) -> bool:
    """Whether ``point`` is within a track's reach (twice the largest pattern radius, grown by
    the scale tolerance, the track's 3σ and 6σ of noise): near a track, its unmatched points
    and clutter would start a second track of the same target."""
    reach = 2.0 * float(modes.radii.max()) * (1.0 + cfg.scale_tolerance) + 6.0 * sigma
    for tr in tracks:
        x, P = tr.estimate.x, tr.estimate.P
        r = reach + 3.0 * math.sqrt(P[0, 0] + P[2, 2])
        if math.hypot(point[0] - x[0], point[1] - x[2]) <= r:
            return True
    return False


def _plausible(match: PatternMatch, sigma: float) -> bool:
    """The registration's residual is what the noise explains: ``p · mse / σ²`` within the
    :data:`SIGHTING_PROBABILITY` quantile of a chi-square with ``2p − 4`` degrees of freedom
    (a similarity has 4 parameters)."""
    p = match.support
    dof = max(2 * p - 4, 1)
    return p * match.mse / sigma**2 <= float(chi2.ppf(SIGHTING_PROBABILITY, dof))


def _taken(born: list[PatternTrack], view: PointTrackView) -> tuple[str, ...]:
    """The tentative individual tracks within reach of a newborn track's pattern (its
    detections started them): taken over, so that they end."""
    if not len(view):
        return ()
    xy = view.x[:, :2]
    out: set[str] = set()
    for track in born:
        x = track.estimate.x
        reach = float(np.sqrt((track.pattern_points**2).sum(axis=1)).max()) + 3.0 * math.sqrt(
            track.estimate.P[0, 0] + track.estimate.P[2, 2]
        )
        d = np.hypot(xy[:, 0] - x[0], xy[:, 1] - x[2])
        for i in np.flatnonzero((d <= reach) & ~view.confirmed).tolist():
            out.add(view.ids[i])
    return tuple(sorted(out))


def _in_view(
    track: PatternTrack, t: float, coverage: Coverage, modes: BendingModes, cfg: PointPatternConfig
) -> bool:
    """Whether a pattern track's predicted origin, give or take its largest pattern and five
    standard deviations of its position, is in the scan's coverage."""
    x, P = track.estimate.x, track.estimate.P
    dt = max(t - track.time, 0.0)
    centre = np.array([[x[0] + x[1] * dt, x[2] + x[3] * dt]])
    spread = P[0, 0] + P[2, 2] + dt * dt * (P[1, 1] + P[3, 3])
    reach = float(modes.radii.max()) * (1.0 + cfg.scale_tolerance) + 5.0 * math.sqrt(spread)
    return bool(coverage.contains(centre, reach)[0])
