"""The extended-object tracker: a peer of the individual tracker (paper 002).

Each scan (:meth:`ExtendedTracker.propose`, then :meth:`~ExtendedTracker.commit`):

1. **Predict** every extended track to the scan's time (random matrix, :mod:`.random_matrix`).
2. **Leave the individual targets theirs.** A detection inside the 99 % gate of a confirmed
   individual track that does not move with the extended track (velocities more than
   ``group_speed_spread`` apart, beyond their uncertainty) is left to that track: a vehicle
   overtaking a convoy keeps its detections.
3. **Gate and partition.** The other detections in the track's gate (``H P Hᵀ + z X + R``,
   chi-square, ``gate_probability``), but for those likelier under another extended track's
   gate (two groups passing each other), are split into subsets by the resolution distance
   (:mod:`.partition`); the nested unions of the subsets, best-fitting first, are scored by

       ΔL(W) = ln Poisson(|W|; γ) + ln f(W) − |W| ln λ_fa

   (``f`` the joint density of the detections under the predicted centroid and extent,
   ``γ`` the track's expected number of detections a scan, ``λ_fa`` the false-alarm density:
   the batch's, else the one the clutter map learned for its sensor's whole scene),
   against ``ΔL(∅) = −γ`` for no detection at all. The likeliest is the track's: its
   detections are *claimed* (they update no individual track and start none) and update the
   centroid and extent. ``L ← L + ΔL`` is the track's score, tested like an individual
   track's (paper 002 eq. 28-30; Wald's test with the thresholds of ``track_management``).
4. **Split.** A subset of at least two detections in the gate that the likeliest union leaves
   out for :data:`SPLIT_SCANS` scans in a row starts a new extended track (a convoy
   separating); it inherits the parent's velocity and status.
5. **Hybridization.** Every individual track predicted inside a confirmed extended track's
   *resolution cell* (its extent ellipse with each semi-axis grown by half the resolution
   distance) gets detection probability ``in_cell_pd``, so its score follows eq. 28-30 with
   it; individual tracks inside the extent that move with the extended track are absorbed:
   taken from the individual tracker and reported deleted, unless they explain their
   detections one to one (below; those its own detections started are absorbed still): a
   car overtaken by a convoy or in a platoon stays a car.
6. **Birth.** Detections claimed by no extended track form clusters (resolution distance).
   Of each cluster, only the detections that confirmed individual tracks do not explain one
   to one count: a connected set of confirmed tracks and the detections in their gates with
   one or two detections and at least as many tracks is as many targets (cars 50 m apart in
   a lane, or side by side in two lanes); more detections than tracks, or more than two
   strung together gate to gate, are an object's returns (a ship's). A cluster of at least
   ``min_detections`` such detections, seen in ``birth_scans`` scans in a row (then one
   scan of its sensor may miss it, once: :data:`RUN_MISSES`) spanning at least
   ``birth_time`` seconds and moving at no more than ``max_speed``, starts a tentative
   extended track with those of them that are explained by no confirmed individual track or
   by confirmed tracks moving together (with each other and with the cluster's run, their
   median faster than ``group_speed_spread``: cars queued at a red light are no group), less
   those of targets being acquired (tracks of ``ESTABLISHED_HITS`` detections, confirmed or
   not, that explain them one to one: alone with a detection, two side by side, or rivals
   of one start); a cluster that lies among more detections of individual targets (explained
   one to one by confirmed tracks not moving with it) than it holds starts none
   (:func:`_among_individuals`: a crowd's leftovers chained across a plaza). Its velocity is
   the slope of the run's centroids, weighed with the mean velocity of the confirmed
   individual tracks in the cluster that move together, if any (:func:`_birth_velocity`).

Tracks can also be started by hand (:meth:`ExtendedTracker.start`), from a centroid,
velocity and extent prior; such a track is confirmed at once.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cached_property
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from trackers.association.gating import (
    gate,
    log_gaussian_2d,
    position_noise,
)
from trackers.config import ExtendedConfig, TrackerConfig, TrackManagementConfig
from trackers.coverage import Coverage
from trackers.extended.partition import (
    UNION_FIND_EDGES,
    close_pairs,
    component_labels,
    edge_groups,
    pair_subsets,
    point_subsets,
)
from trackers.extended.random_matrix import (
    ExtendedEstimate,
    Moments,
    innovation_entries,
    merged,
    moments,
    moments_log_likelihood,
    predict,
    update,
    update_moments,
)
from trackers.extended.state import ExtendedCheckpoint, read_state
from trackers.peers import PeerProposal, PointTrackView, ResolutionCell, SavesImmutableState
from trackers.scoring import initial_score
from trackers.types import Extent, Scan, TrackSnapshot

__all__ = [
    "SPLIT_SCANS",
    "ExtendedTrack",
    "ExtendedTracker",
    "extent_ellipse",
    "position_noise",
    "remembered_noise",
    "resolution_in_force",
    "snapshot_of",
]

#: Scans in a row a separated subset must move away before it becomes a track of its own.
SPLIT_SCANS = 3
#: Scans in a row a confirmed individual track must be inside a confirmed extended track's
#: extent and moving with it before it is absorbed (a vehicle passing alongside is not).
ABSORB_SCANS = 3
#: Gate (χ²₂, 99 %) of a confirmed individual track that keeps its detections for it.
POINT_GATE = 9.21
#: Weight of the latest scan's detection count in the expected count γ.
GAMMA_GAIN = 0.2
#: Smallest expected detection count: keeps ln Poisson finite and a miss's cost positive.
MIN_GAMMA = 0.3
#: Smallest expected detection count learned from a track's scans: a track's misses cost it
#: delete_drop_from_peak in no more than that many (15 with the defaults).
MIN_LEARNED_GAMMA = 1.0
#: Velocity std (m/s) per axis of a new track's centroid beyond what its birth measured.
BIRTH_VELOCITY_STD = 5.0
#: Velocity std (m/s) per axis of a track split off another: measured from the centroid of a
#: few detections over one scan.
SPLIT_VELOCITY_STD = 10.0


#: Scans of its sensor that may miss a birth run, once seen in ``birth_scans`` scans, without
#: ending it. An object whose returns come and go (a ship whose scatterers a radar resolves,
#: some held by confirmed individual tracks that explain them one to one) leaves fewer than
#: ``min_detections`` free detections in one scan of three or four: at T = 2.5 s a run
#: needs 5 scans to span ``birth_time``, and a run that any such scan ended rarely did (a
#: newcomer's 300 m ship seen end-on showed 4-5 individual tracks and no extended one for
#: 400 s). Only established runs: uniform clutter's runs of one or two scans end as before.
RUN_MISSES = 1

#: A sensor's position noise counts for the resolution distance this long (s) after its last
#: batch ...
NOISE_MEMORY = 60.0
#: ... and for at most this many sensors (the latest).
NOISE_SENSORS = 64


def remembered_noise(
    noise: tuple[tuple[str, float, float], ...], sensor: str, sigma: float | None, t: float
) -> tuple[tuple[str, float, float], ...]:
    """``noise`` (sensor, σ̃, time) with ``sensor``'s ``sigma`` at ``t`` (when given), less
    the entries older than :data:`NOISE_MEMORY` and beyond the :data:`NOISE_SENSORS` latest."""
    kept = [e for e in noise if e[0] != sensor and t - e[2] <= NOISE_MEMORY]
    if sigma is not None:
        kept.append((sensor, sigma, t))
    else:
        kept += [e for e in noise if e[0] == sensor and t - e[2] <= NOISE_MEMORY]
    return tuple(sorted(kept, key=lambda e: e[2])[-NOISE_SENSORS:])


def resolution_in_force(cfg: ExtendedConfig, sigma: float | None) -> ExtendedConfig:
    """``cfg`` with the resolution distance in force for detections of position noise
    ``sigma`` (m; the coarsest of the recent sensors, :func:`remembered_noise`), and the group
    speed spread scaled with it:

        d_res = min(resolution_distance, k σ̃),
        spread = group_speed_spread · d_res / resolution_distance,

    ``k`` = ``resolution_noise_factor`` (0, or no ``sigma``: the configured values). The
    configured distance suits a radar (tens of metres of noise; a convoy's vehicles 30-150 m
    apart are one group); a camera with 0.3 m of noise sees pedestrians metres apart as
    separate targets, not as one object 200 m across. The spread scales with the distance
    (members of a group stay within it of each other for as long): pedestrians walking
    1-2 m/s in different directions are within 3 m/s of each other, yet no group. The
    coarsest recent sensor decides, so that a radar and a camera watching one scene see the
    same groups."""
    k = cfg.resolution_noise_factor
    if k <= 0 or sigma is None:
        return cfg
    d = k * sigma
    if d >= cfg.resolution_distance:
        return cfg
    return _scaled(cfg, d)


@functools.lru_cache(maxsize=32)
def _scaled(cfg: ExtendedConfig, d: float) -> ExtendedConfig:
    return replace(
        cfg,
        resolution_distance=d,
        group_speed_spread=cfg.group_speed_spread * d / cfg.resolution_distance,
    )


@dataclass(frozen=True, eq=False)
class ExtendedTrack:
    """One extended track as of ``time`` (immutable)."""

    id: str
    estimate: ExtendedEstimate
    time: float
    score: float
    peak: float
    hits: int
    confirmed: bool
    created: float
    updated: float
    gamma: float
    detection_ids: tuple[str, ...] = ()
    #: Scans in a row that a subset of its detections (chosen or left out) has been moving away
    #: from the largest one (:func:`_split_evidence`), with that subset's last centroid, its
    #: gap (m) to the largest one and the time.
    split_evidence: int = 0
    split_centroid: tuple[float, float] = (0.0, 0.0)
    split_gap: float = 0.0
    split_time: float = 0.0
    #: The same for a lone detection moving away from the largest subset (a vehicle leaving
    #: the group by itself): after :data:`SPLIT_SCANS` scans it is shed, left to the
    #: individual tracker, for as long as it goes on moving away.
    shed_evidence: int = 0
    shed_centroid: tuple[float, float] = (0.0, 0.0)
    shed_gap: float = 0.0
    shed_time: float = 0.0
    #: When its detections were first seen together (its cluster's first scan, before it was
    #: born); individual tracks created since, inside its extent, came from its detections.
    origin: float = math.inf
    #: Individual tracks seen coming up to it from outside its resolution cell.
    visitors: frozenset[str] = frozenset()


class _Candidate(NamedTuple):
    """A cluster seen in consecutive scans (but for one, once seen ``birth_scans`` times:
    :meth:`missed_by`), not yet a track: its latest centroid, and the
    sums for the least-squares line ``c(t) = a + v (t − t₀)`` through its centroids (a
    cluster of clutter jitters by tens of metres a scan: a velocity from two centroids would
    be off by tens of m/s). A tuple of plain floats: a scan makes and drops many of these.
    ``sensor`` saw it last: a scan of another sensor that does not see it leaves the run
    unbroken (each sensor resolves an object's returns its own way: a ship's scatterers,
    strung together for one radar, are as many lone points for a second one that looks
    along the ship)."""

    centroid: tuple[float, float]
    first_time: float
    time: float
    seen: int
    #: Σ1, Στ, Στ², Σcx, Σcy, Στcx, Στcy over the centroids seen, τ = t − first_time.
    sums: tuple[float, float, float, float, float, float, float]
    #: The sensor whose scan saw it last ("": not known, a file of an earlier version).
    sensor: str = ""
    #: Scans of its sensor that did not see it since it began (at most RUN_MISSES).
    missed: int = 0

    @classmethod
    def first(cls, centroid: tuple[float, float], t: float, sensor: str = "") -> _Candidate:
        cx, cy = centroid
        return cls((cx, cy), t, t, 1, (1.0, 0.0, 0.0, cx, cy, 0.0, 0.0), sensor)

    def seen_again(self, centroid: tuple[float, float], t: float, sensor: str) -> _Candidate:
        n, s1, s2, sx, sy, tx, ty = self.sums
        cx, cy = centroid
        tau = t - self.first_time
        sums = (n + 1.0, s1 + tau, s2 + tau * tau, sx + cx, sy + cy, tx + tau * cx, ty + tau * cy)
        return _Candidate((cx, cy), self.first_time, t, self.seen + 1, sums, sensor, self.missed)

    def broken_by(self, sensor: str) -> bool:
        """Whether a scan of ``sensor`` that does not see the run counts as a miss of it: a
        scan of the sensor that saw it last (or of any, when that is not known)."""
        return not self.sensor or self.sensor == sensor

    def missed_by(self, sensor: str, established: int) -> _Candidate | None:
        """The run after a scan of ``sensor`` that did not see it: unchanged for another
        sensor's scan; for its own, ``None`` (ended), but a run seen ``established`` times
        (``birth_scans``: it waits for ``birth_time`` only) may miss :data:`RUN_MISSES`
        of them."""
        if not self.broken_by(sensor):
            return self
        if self.seen < established or self.missed >= RUN_MISSES:
            return None
        return self._replace(missed=self.missed + 1)

    @property
    def velocity(self) -> np.ndarray:
        """The line's slope ``v = (n Στc − Στ Σc) / (n Στ² − (Στ)²)`` (0 for one centroid)."""
        return np.array(self.slope())

    def slope(self) -> tuple[float, float]:
        """:attr:`velocity` as two floats."""
        n, s1, s2, sx, sy, tx, ty = self.sums
        den = n * s2 - s1 * s1
        if n < 2 or den <= 0:
            return 0.0, 0.0
        return (n * tx - s1 * sx) / den, (n * ty - s1 * sy) / den

    def velocity_std(self, centroid_std: float) -> float:
        """Standard deviation of the slope for centroids uncertain by ``centroid_std`` (m):
        ``σ_c / √(Στ² − (Στ)²/n)`` (infinite for one centroid)."""
        n, s1, s2 = self.sums[:3]
        spread = s2 - s1 * s1 / n
        return centroid_std / math.sqrt(spread) if spread > 0 else math.inf

    def predicted(self, t: float) -> tuple[float, float]:
        """The line's centroid at ``t``: ``Σc/n + v (t − t₀ − Στ/n)``."""
        n, s1, _, sx, sy, _, _ = self.sums
        vx, vy = self.slope()
        lag = t - self.first_time - s1 / n
        return sx / n + vx * lag, sy / n + vy * lag


@dataclass(frozen=True, eq=False)
class _State:
    config: ExtendedConfig
    management: TrackManagementConfig
    tracks: tuple[ExtendedTrack, ...] = ()
    candidates: tuple[_Candidate, ...] = ()
    next_id: int = 1
    time: float | None = None
    #: Confirmed individual tracks seen inside an extent and moving with it: scans in a row.
    absorbing: tuple[tuple[str, int], ...] = ()
    #: Each recent sensor's position noise (:func:`position_noise`) and latest batch time.
    noise: tuple[tuple[str, float, float], ...] = ()


def extent_ellipse(X: np.ndarray) -> Extent:
    """Semi-axes (major first, m) and orientation (rad, of the major axis, in (−π/2, π/2]) of
    the ellipse ``pᵀ X⁻¹ p ≤ 1``: the square roots of X's eigenvalues and its major
    eigenvector's angle."""
    X = np.asarray(X, dtype=float)
    a, b, c = X[0, 0], X[0, 1], X[1, 1]
    mean, half = 0.5 * (a + c), math.hypot(0.5 * (a - c), b)
    l1, l2 = mean + half, max(mean - half, 0.0)
    theta = 0.5 * math.atan2(2.0 * b, a - c)
    return Extent(matrix=X.copy(), semi_axes=(math.sqrt(l1), math.sqrt(l2)), orientation=theta)


def _grown(X: np.ndarray, *margins: float) -> tuple[np.ndarray, ...]:
    """The shape matrices of the ellipse ``pᵀ X⁻¹ p ≤ 1`` with each semi-axis longer by
    ``m``, one for each of the ``margins``: ``V diag((√λᵢ + m)²) Vᵀ``. Written out for the
    2x2 ``X = [[a, b], [b, c]]`` with eigenvalues ``λ₁ ≥ λ₂ > 0``, it is

        (√λ₂ + m)² I + k (X − λ₂ I),    k = 1 + 2 m / (√λ₁ + √λ₂)

    (``X − λ₂ I`` is ``(λ₁ − λ₂) v₁v₁ᵀ``, and ``k (λ₁ − λ₂) = (√λ₁ + m)² − (√λ₂ + m)²``).
    A matrix that is not positive definite takes ``V`` from ``eigh``, its ``λᵢ`` clamped at 0."""
    (a, b), (_, c) = X.tolist()
    mean, half = 0.5 * (a + c), math.hypot(0.5 * (a - c), b)
    l2 = mean - half
    if not l2 > 0.0:
        w, V = np.linalg.eigh(X)
        root = np.sqrt(np.maximum(w, 0.0))
        return tuple((V * (root + m) ** 2) @ V.T for m in margins)
    r1, r2 = math.sqrt(mean + half), math.sqrt(l2)
    out = []
    for m in margins:
        s2, k = (r2 + m) ** 2, 1.0 + 2.0 * m / (r1 + r2)
        out.append(np.array([[s2 + k * (a - l2), k * b], [k * b, s2 + k * (c - l2)]]))
    return tuple(out)


def truncated_mean(gamma: float) -> float:
    """The mean number of detections of a scan that gives some, for a Poisson count of
    mean ``γ``: ``E[n | n ≥ 1] = γ / (1 − e^{−γ})`` (1 in the limit ``γ → 0``)."""
    return gamma / -math.expm1(-gamma) if gamma > 0.0 else 1.0


def expected_count(m: float) -> float:
    """The Poisson mean ``γ`` whose :func:`truncated_mean` is ``m`` (``m ≥ 1``; 0 for
    ``m ≤ 1``): Newton's method on ``f(γ) = γ / (1 − e^{−γ}) − m`` from ``γ₀ = m`` (f is
    convex and increasing, so the iterates fall monotonically to the root), to 1e-12."""
    if not m > 1.0:
        return 0.0
    if math.isinf(m):
        return m
    gamma = m
    for _ in range(60):
        q = -math.expm1(-gamma)  # 1 − e^{−γ}
        f = gamma / q - m
        slope = (q - gamma * math.exp(-gamma)) / (q * q)
        step = f / slope
        gamma -= step
        if abs(step) <= 1e-12 * max(1.0, gamma):
            break
    return gamma


def _log_poisson(n: int, gamma: float) -> float:
    """ln Poisson(n; γ) = n ln γ − γ − ln n!."""
    return n * math.log(gamma) - gamma - math.lgamma(n + 1)


def _mahalanobis(d: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``dᵢᵀ Sᵢ⁻¹ dᵢ`` for ``d (n, 2)`` and ``S (n, 2, 2)`` or ``(2, 2)``, 2x2 written out."""
    if S.ndim == 2:  # one matrix for all: its entries as floats
        (a, b), (_, c) = S.tolist()
    else:
        a, b, c = S[:, 0, 0], S[:, 0, 1], S[:, 1, 1]
    det = a * c - b * b
    x, y = d[:, 0], d[:, 1]
    return (c * x * x - 2.0 * b * x * y + a * y * y) / det


def _centroid(points: dict[int, tuple[float, ...]], rows: list[int]) -> tuple[float, float]:
    """The mean of the detections ``rows`` (n ≥ 1; ``points[r]`` starts with row r's x, y),
    summed in their order on floats: ``z[rows].mean(axis=0)`` to the bit, without numpy's
    cost for a few rows."""
    sx = sy = 0.0
    for r in rows:
        p = points[r]
        sx += p[0]
        sy += p[1]
    n = len(rows)
    return sx / n, sy / n


def _mean_R(points: dict[int, tuple[float, ...]], rows: list[int]) -> np.ndarray:
    """The mean of the covariances of the detections ``rows`` (n ≥ 1; ``points[r]`` is row
    r's ``(x, y, R₀₀, R₀₁, R₁₀, R₁₁)``), summed in their order on floats:
    ``np.mean(R[rows], axis=0)`` to the bit."""
    s0 = s1 = s2 = s3 = 0.0
    for r in rows:
        _, _, r0, r1, r2, r3 = points[r]
        s0 += r0
        s1 += r1
        s2 += r2
        s3 += r3
    n = len(rows)
    return np.array([[s0 / n, s1 / n], [s2 / n, s3 / n]])


def _points(scan: Scan, rows: np.ndarray) -> dict[int, tuple[float, ...]]:
    """Row ``r`` of the scan → ``(x, y, R₀₀, R₀₁, R₁₀, R₁₁)``, as floats, for the ``rows``."""
    z = np.take(scan.z, rows, axis=0).tolist()
    R = np.take(scan.R, rows, axis=0).reshape(-1, 4).tolist()
    return {r: (*zr, *Rr) for r, zr, Rr in zip(rows.tolist(), z, R, strict=True)}


def _hypot(x: float, y: float) -> float:
    """``np.hypot`` of two floats (not ``math.hypot``, which may round differently)."""
    return float(np.hypot(x, y))


def _one_to_one(n_trk: np.ndarray | int, n_det: np.ndarray | int) -> np.ndarray | bool:
    """Whether connected sets of ``n_trk`` tracks and ``n_det`` detections are explained one
    to one: one or two detections, and at least as many tracks (arrays or plain ints)."""
    return (n_trk >= n_det) & (n_det <= 2)


def _sets_of_few(
    det: np.ndarray,
    trk: np.ndarray,
    at: np.ndarray,
    n_d: int,
    n_trk: np.ndarray,
    n_det: np.ndarray,
    track_ok: np.ndarray,
) -> None:
    """:attr:`_PointGates._sets` for the gate pairs ``at`` that share a detection or a track
    with another pair, grouped by :func:`~trackers.extended.partition.edge_groups` (nodes:
    the detections, then ``n_d`` + the tracks): each pair's set sizes into ``n_trk`` and
    ``n_det``, each of their tracks' one-to-one verdict into ``track_ok`` (in place)."""
    d_list = np.take(det, at).tolist()
    k_list = [n_d + k for k in np.take(trk, at).tolist()]
    size_of: dict[int, tuple[int, int]] = {}
    for group in edge_groups(d_list, k_list):
        nd = sum(1 for node in group if node < n_d)
        sizes = (len(group) - nd, nd)
        for node in group:
            size_of[node] = sizes
    n_trk[at] = [size_of[d][0] for d in d_list]
    n_det[at] = [size_of[d][1] for d in d_list]
    tracks = [node for node in size_of if node >= n_d]
    track_ok[[node - n_d for node in tracks]] = [_one_to_one(*size_of[node]) for node in tracks]


class _PointGates:
    """The confirmed individual tracks of a scan (``rows`` of the view; ``xy``, ``v``, the
    position covariances ``Pp``, ``created``) with the 99 % gates in which they keep a
    detection. ``det``, ``trk``, ``m``: the (detection, track) pairs of the whole scan where
    the detection lies in the track's gate, as index arrays (rows of the scan, indices into
    the confirmed tracks) and squared Mahalanobis distances, found on first use: from the
    point tracker's own gate pairs of the scan (:attr:`PointTrackView.gated
    <trackers.peers.PointTrackView>`) when its gate is as wide, else by the same gating
    (:func:`trackers.association.gating.gate`) at the 99 % gate; :meth:`theirs` computes only
    the pairs it needs."""

    def __init__(self, view: PointTrackView, scan: Scan, min_hits: int | None = None) -> None:
        # min_hits: tentative tracks of that many detections or more are taken too
        kept = view.confirmed if min_hits is None else view.confirmed | (view.hits >= min_hits)
        self.rows = np.flatnonzero(kept)
        self._ids = view.ids
        self.size = scan.size
        self._z, self._R = scan.z, scan.R
        self._kept = kept
        self._view, self._scan = view, scan

    # The kept tracks' states, taken on first use (the births' test needs only the pairs).
    @cached_property
    def _x(self) -> np.ndarray:
        return np.take(self._view.x, self.rows, axis=0)

    @cached_property
    def _P(self) -> np.ndarray:
        return np.take(self._view.P, self.rows, axis=0)

    @property
    def xy(self) -> np.ndarray:
        return self._x[:, :2]

    @property
    def v(self) -> np.ndarray:
        return self._x[:, 2:4]

    @property
    def Pp(self) -> np.ndarray:
        return self._P[:, :2, :2]

    @property
    def Pv(self) -> np.ndarray:
        return self._P[:, 2:4, 2:4]

    @cached_property
    def created(self) -> np.ndarray:
        return np.take(self._view.created, self.rows)

    @cached_property
    def _pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        empty = np.zeros(0, dtype=np.intp)
        if not (self.rows.size and self.size):
            return empty, empty, np.zeros(0)
        if self._view.gated is not None:
            # The point tracker's own gate pairs of this scan, when its gate is as wide:
            # those of the kept tracks within this one (the same d², in the same order).
            shared, gamma = self._view.gated(self._scan)
            if gamma >= POINT_GATE:
                inside = np.take(self._kept, shared.track) & (shared.d2 <= POINT_GATE)
                position = np.cumsum(self._kept) - 1  # view row -> index into rows
                return (
                    shared.detection[inside],
                    np.take(position, shared.track[inside]),
                    shared.d2[inside],
                )
        own = gate(self.xy, self.Pp, self._z, self._R, POINT_GATE)
        return own.detection, own.track, own.d2

    @property
    def det(self) -> np.ndarray:
        return self._pairs[0]

    @property
    def trk(self) -> np.ndarray:
        return self._pairs[1]

    @property
    def m(self) -> np.ndarray:
        return self._pairs[2]

    @cached_property
    def _sets(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The connected sets of tracks and the detections in their gates: for each gate
        pair, its set's numbers of tracks and of detections; for each track, whether it has a
        detection in its gate and its set is explained one to one. A pair whose detection and
        track are in no other pair is a set of its own; only the others are labelled (every
        pair that touches one of them shares a node of two pairs, so their sets hold nothing
        else)."""
        det, trk = self.det, self.trk
        n_trk = np.ones(det.size, dtype=np.intp)
        n_det = np.ones(det.size, dtype=np.intp)
        track_ok = np.zeros(self.rows.size, dtype=bool)  # a track with no detection: no
        track_ok[trk] = True
        if det.size:
            shared = self._shared
            at = np.flatnonzero(shared)
            if 0 < at.size <= UNION_FIND_EDGES:
                # A few pairs (the usual case): their sets by one plain loop, no node arrays.
                _sets_of_few(det, trk, at, self.size, n_trk, n_det, track_ok)
            elif at.size:
                n_d = self.size  # nodes: the detections, then the tracks
                d, k = det[shared], n_d + trk[shared]
                labels = component_labels(n_d + self.rows.size, d, k)
                used = np.zeros(labels.size, dtype=bool)
                used[d] = used[k] = True
                dets = np.bincount(labels[:n_d][used[:n_d]], minlength=labels.size)
                trks = np.bincount(labels[n_d:][used[n_d:]], minlength=labels.size)
                at = labels[d]
                n_trk[shared], n_det[shared] = trks[at], dets[at]
                own = labels[n_d:][used[n_d:]]
                track_ok[used[n_d:]] = _one_to_one(trks[own], dets[own])
        return n_trk, n_det, track_ok

    @property
    def explained(self) -> np.ndarray:
        """Mask of the gate pairs whose detections the tracks explain one to one: their
        connected set (tracks joined by the detections in their gates) holds one or two
        detections and at least as many tracks. Cars 50 m apart in a lane, or side by side
        in two lanes, are as many targets as detections; a ship's returns are not, whether
        more of them than its point tracks or as many but strung together gate to gate (4
        returns along 200 m seen with 15 m of noise)."""
        n_trk, n_det, _ = self._sets
        return _one_to_one(n_trk, n_det)

    @property
    def explained_tracks(self) -> np.ndarray:
        """Mask of the tracks (``rows``) with a detection in their gate whose connected set
        is explained one to one (:attr:`explained`)."""
        return self._sets[2]

    @cached_property
    def resolved(self) -> np.ndarray:
        """Mask of the gate pairs whose track is resolved there: the one detection in its
        gate, in no other track's gate."""
        n_det = np.bincount(self.det, minlength=self.size)
        n_trk = np.bincount(self.trk, minlength=self.rows.size)
        return (np.take(n_det, self.det) == 1) & (np.take(n_trk, self.trk) == 1)

    @cached_property
    def _shared(self) -> np.ndarray:
        """Mask of the gate pairs whose detection or track is in another pair too."""
        det, trk = self.det, self.trk
        return (np.bincount(det, minlength=self.size)[det] > 1) | (
            np.bincount(trk, minlength=self.rows.size)[trk] > 1
        )

    @cached_property
    def explained_detections(self) -> np.ndarray:
        """Mask of the scan's detections in a gate pair the tracks explain one to one,
        ``detections(explained)``, without :attr:`_sets`' per-pair arrays when nothing else
        needed them: a pair whose detection and track are in no other pair is explained, and
        the sets of the few others are grouped by one loop."""
        det, trk = self.det, self.trk
        if "_sets" in self.__dict__ or det.size > UNION_FIND_EDGES:
            return self.detections(self.explained)
        out = np.zeros(self.size, dtype=bool)
        if det.size == 0:
            return out
        shared = self._shared
        out[det[~shared]] = True  # a pair in no set with another: one to one
        at = np.flatnonzero(shared)
        if at.size:
            n_d = self.size  # nodes: the detections, then n_d + the tracks
            k_list = [n_d + k for k in np.take(trk, at).tolist()]
            for group in edge_groups(np.take(det, at).tolist(), k_list):
                dets = [node for node in group if node < n_d]
                if _one_to_one(len(group) - len(dets), len(dets)):
                    out[dets] = True
        return out

    def detections(self, pairs: np.ndarray) -> np.ndarray:
        """Mask of the scan's detections in the gate ``pairs`` (a mask over the pairs)."""
        out = np.zeros(self.size, dtype=bool)
        out[self.det[pairs]] = True
        return out

    @cached_property
    def _trace_Pp(self) -> np.ndarray:
        return self._P[:, 0, 0] + self._P[:, 1, 1]

    def theirs(
        self,
        rows: list[int],
        points: dict[int, tuple[float, ...]],
        centre: tuple[float, float],
        reach: float,
        ve: tuple[float, float],
        spread: float,
        own: tuple[float, frozenset[str], float] = (math.inf, frozenset(), 0.0),
    ) -> set[int]:
        """What the confirmed tracks not moving with an extended track would take of its
        detections ``rows`` (ascending, all within ``reach`` of ``centre``; ``points`` as
        :func:`_points` gives them): for each track whose velocity is more than ``spread``
        (m/s) from ``ve`` (:func:`_moves_with` with no allowance for uncertainty), the
        detection nearest to it in its gate (Mahalanobis; of equally near ones the first), if
        any; but for the extended track's own (``own``: its origin, its visitors and the
        fastest group; tracks created since the origin, no visitor, no faster than that,
        as :func:`_hybridize` absorbs). Only the tracks whose gate can
        reach that far are looked at (``d² ≤ χ² λ_max(Pp + R) ≤ χ² (tr Pp + tr R)``), on
        floats, operation for operation as the array formulas."""
        if not (rows and self.rows.size):
            return set()
        widest = max(points[r][2] + points[r][5] for r in rows)
        gate = np.sqrt(POINT_GATE * (self._trace_Pp + widest)) * (1.0 + 1e-9) + 1e-9
        r = gate + reach
        dx, dy = self.xy[:, 0] - centre[0], self.xy[:, 1] - centre[1]
        ks = np.flatnonzero(dx * dx + dy * dy <= r * r)
        if ks.size == 0:
            return set()
        origin, visitors, max_speed = own
        mine = np.take(self.created, ks) >= origin
        if mine.any():
            v = np.take(self.v, ks, axis=0)
            mine &= np.hypot(v[:, 0], v[:, 1]) <= max_speed
        if mine.any():
            ids = self._ids
            mine[mine] = [ids[int(self.rows[k])] not in visitors for k in ks[mine].tolist()]
            ks = ks[~mine]
            if ks.size == 0:
                return set()
        x = np.take(self._x, ks, axis=0)[:, :4].tolist()
        P = np.take(self._P, ks, axis=0)[:, :4, :4].reshape(-1, 16).tolist()
        gate = np.take(gate, ks).tolist()
        out: set[int] = set()
        for (x0, x1, vx, vy), p, g in zip(x, P, gate, strict=True):
            if _hypot(vx - ve[0], vy - ve[1]) <= spread:
                continue  # moves with it
            pa, pb, pc = p[0], p[1], p[5]
            best, best_m = -1, POINT_GATE
            for row in rows:
                zx, zy, ra, rb, _, rc = points[row]
                ex, ey = zx - x0, zy - x1
                if ex * ex + ey * ey > g * g:
                    continue  # beyond its gate
                a, b, c = pa + ra, pb + rb, pc + rc
                m = (c * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / (a * c - b * b)
                if m < best_m or (best < 0 and m == best_m):
                    best, best_m = row, m
            if best >= 0:
                out.add(best)
        return out


def _moves_with(
    v: np.ndarray,
    Pv: np.ndarray,
    ve: np.ndarray,
    Pve: np.ndarray,
    spread: float,
    sigmas: float | np.ndarray = 1.0,
) -> np.ndarray:
    """Whether velocities ``v (n, 2)`` are within ``spread`` (m/s) of ``ve``, allowing
    ``sigmas`` standard deviations of both estimates."""
    sd = np.sqrt(0.5 * (np.trace(Pv, axis1=1, axis2=2) + np.trace(Pve)))
    return np.hypot(*(v - ve).T) <= spread + sigmas * sd


class ExtendedTracker(SavesImmutableState):
    """Random-matrix tracks of extended objects and groups; a peer of the point tracker
    (:class:`trackers.peers.PeerTracker`). See the module docstring for the step."""

    kind = "extended"
    _checkpoint_type = ExtendedCheckpoint
    _kept_on_reset = ("config", "management", "next_id")
    _read_state = staticmethod(read_state)

    def __init__(self, config: TrackerConfig | None = None, *, id_prefix: str = "") -> None:
        """``id_prefix`` goes before every new track's id (``{id_prefix}E3``)."""
        config = config or TrackerConfig()
        self.id_prefix = id_prefix
        self._state = _State(config=config.extended, management=config.track_management)

    # -- the peer interface ------------------------------------------------------------------

    @property
    def tracks(self) -> tuple[ExtendedTrack, ...]:
        return self._state.tracks

    def reconfigure(self, config: TrackerConfig) -> None:
        self._state = replace(
            self._state, config=config.extended, management=config.track_management
        )

    def commit(self, proposal: PeerProposal) -> None:
        if isinstance(proposal.state, _State):
            self._state = proposal.state

    def snapshot(self) -> tuple[TrackSnapshot, ...]:
        return tuple(_snapshot(t, t.time) for t in self._state.tracks)

    def start(
        self,
        time: float,
        position: np.ndarray,
        velocity: np.ndarray,
        extent: np.ndarray,
        position_std: float = 20.0,
        velocity_std: float = 5.0,
        expected_detections: float = 3.0,
    ) -> ExtendedTrack:
        """Start a confirmed extended track by hand at ``time`` (not before the last scan), from
        a centroid, velocity and extent prior (``extent`` the 2x2 shape matrix, m²). Returns
        it; raises ``ValueError`` and changes nothing for unusable values, a speed above
        ``max_speed``, or a centroid inside a confirmed track's extent (predicted to
        ``time``): that object is tracked already."""
        state = self._state
        if not math.isfinite(time) or (state.time is not None and time < state.time):
            raise ValueError(f"time: must be finite and not before {state.time}, got {time!r}")
        for name, v in (
            ("position_std", position_std),
            ("velocity_std", velocity_std),
            ("expected_detections", expected_detections),
        ):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
        x = np.concatenate([np.reshape(position, 2), np.reshape(velocity, 2)]).astype(float)
        if not np.isfinite(x).all():
            raise ValueError("position and velocity: must be finite numbers")
        speed = math.hypot(x[2], x[3])
        if speed > state.config.max_speed:
            raise ValueError(
                f"velocity: {speed:.6g} m/s is faster than extended.max_speed "
                f"({state.config.max_speed:.6g} m/s), the fastest group the tracker holds"
            )
        X = np.asarray(extent, dtype=float).reshape(2, 2)
        if not (
            np.isfinite(X).all()
            and abs(X[0, 1] - X[1, 0]) <= 1e-9 * (abs(X[0, 0]) + abs(X[1, 1]))
            and X[0, 0] > 0
            and X[0, 0] * X[1, 1] - X[0, 1] * X[1, 0] > 0
        ):
            raise ValueError("extent: must be a symmetric positive definite 2x2 matrix")
        for other in state.tracks:
            if not other.confirmed:
                continue
            est_o = other.estimate
            d = x[:2] - (est_o.x[:2] + est_o.x[2:4] * (time - other.time))
            if float(d @ np.linalg.solve(est_o.X, d)) <= 1.0:
                raise ValueError(
                    f"position: inside the extent of extended track {other.id!r}, which "
                    "already holds this object"
                )
        P = np.diag([position_std**2] * 2 + [velocity_std**2] * 2)
        est = ExtendedEstimate(x=x, P=P, X=X, alpha=10.0)
        track = ExtendedTrack(
            id=f"{self.id_prefix}E{state.next_id}",
            estimate=est,
            time=float(time),
            score=state.management.confirm_threshold,
            peak=state.management.confirm_threshold,
            hits=0,
            confirmed=True,
            created=float(time),
            updated=float(time),
            gamma=float(expected_detections),
        )
        self._state = replace(state, tracks=(*state.tracks, track), next_id=state.next_id + 1)
        return track

    def propose(self, scan: Scan, view: PointTrackView) -> PeerProposal:
        state = self._state
        cfg, tm = state.config, state.management
        t = float(scan.time)
        claimed = np.zeros(scan.size, dtype=bool)
        if not cfg.enabled:
            gone = tuple(tr.id for tr in state.tracks if tr.confirmed)
            new_state = replace(state, tracks=(), candidates=(), time=t, noise=())
            return PeerProposal(claimed=claimed, deleted=gone, state=new_state)
        sigma = position_noise(scan.R)
        noise = remembered_noise(state.noise, scan.sensor_id, sigma, t)
        cfg = resolution_in_force(cfg, max((e[1] for e in noise), default=None))
        # the false-alarm density a track's detections must beat: the batch's stated one,
        # else the one its sensor's clutter map learned for the whole scene or, where it is
        # denser, about the track's centroid (what a cluster must beat to start a track,
        # :func:`_standing_out`), else the configured one
        lam = scan.clutter_density if scan.clutter_density is not None else scan.clutter_scene
        log_lam = math.log(tm.clutter_density if lam is None else float(lam))
        next_id = state.next_id
        gates: _PointGates | None = None

        def point_gates() -> _PointGates:
            nonlocal gates
            if gates is None:
                gates = _PointGates(view, scan)
            return gates

        # One k-d tree of the scan, if there are tracks: the detections near each track, and
        # the births' pairs.
        tree = cKDTree(scan.z) if scan.size and state.tracks else None
        R_mean = np.mean(scan.R, axis=0) if tree is not None else None
        kept: list[ExtendedTrack] = []
        spawned: list[ExtendedTrack] = []
        deleted: list[str] = []
        ests = [predict(tr.estimate, max(0.0, t - tr.time), cfg.q, cfg.tau) for tr in state.tracks]
        log_lams = [log_lam] * len(ests)
        if ests and scan.clutter_density is None and scan.clutter_around is not None:
            about = scan.clutter_around(np.array([e.x[:2] for e in ests], dtype=float))
            log_lams = [max(log_lam, math.log(a)) for a in about.tolist()]
        owner = _owners(ests, scan, tree, R_mean, cfg) if tree is not None else None
        for idx, track in enumerate(state.tracks):
            est = ests[idx]
            if scan.coverage is not None and not _in_view(scan.coverage, est):
                # Out of this sensor's view: not looked at, so not missed either.
                if _dead(track, t, cfg, tm):
                    if track.confirmed:
                        deleted.append(track.id)
                    continue
                kept.append(replace(track, estimate=est, time=t, detection_ids=()))
                continue
            subsets: list[list[int]] = []
            points: dict[int, tuple[float, ...]] = {}
            inside: dict[int, float] | None = None
            if tree is not None:
                # (a detection likelier under another extended track's gate is that one's)
                taken = claimed if owner is None else claimed | ((owner >= 0) & (owner != idx))
                subsets, points, inside = _gated_subsets(
                    est, scan, tree, R_mean, taken, point_gates, cfg, track
                )
            gain, chosen, parts, left_out, fitted = _likeliest(
                track, est, scan, subsets, points, cfg, log_lams[idx], inside
            )
            score = track.score + gain
            evidence, split, split_c, split_d, split_v = _split_evidence(
                track, points, parts, left_out, t, cfg
            )
            split_rows = np.array(split, dtype=np.intp)
            splitting = evidence >= SPLIT_SCANS and not claimed[split_rows].any()
            shed_n, shed, shed_c, shed_d = _lone_evidence(track, points, parts, left_out, t, cfg)
            if shed_n >= SPLIT_SCANS and shed in chosen and not splitting:
                # a vehicle leaving by itself: its detection is left to the individual
                # tracker, the extent follows the rest
                chosen = [r for r in chosen if r != shed]
                fitted = None
            if splitting:  # the parent keeps the rest, its extent fitted to it afresh
                leaving = set(split)
                chosen = [r for r in chosen if r not in leaving]
                fitted = None
                if chosen:
                    est = replace(
                        est,
                        X=_spread(scan, np.array(chosen, dtype=np.intp), cfg)[2],
                        alpha=2.0 + len(chosen),
                    )
            n = len(chosen)
            # γ is learned from the scans that gave the track detections (their mean is the
            # zero-truncated Poisson mean, :func:`expected_count`), and a learned γ is at
            # least MIN_LEARNED_GAMMA: learned from its misses too, it fell with each
            # (γ ← 0.8 γ), so that a track's misses cost at most 5 γ in all, less than
            # delete_drop_from_peak for γ < 3 (a split-off pair of clutter detections
            # coasted, confirmed, for all of max_coast_time); and an object giving one
            # detection every scan (no Poisson count) would read γ → 0.
            gamma = track.gamma
            if n:
                seen = truncated_mean(gamma)
                gamma = max(MIN_LEARNED_GAMMA, expected_count(seen + GAMMA_GAIN * (n - seen)))
            chosen = np.array(chosen, dtype=np.intp)
            if n:
                claimed[chosen] = True
                if fitted is None:
                    R_chosen = np.mean(np.take(scan.R, chosen, axis=0), axis=0)
                    est = update(est, np.take(scan.z, chosen, axis=0), R_chosen, cfg.z_scale)
                else:  # the union's own: its mean R and moments, found when it was scored
                    est = update_moments(est, fitted[1], fitted[0], cfg.z_scale)
            new = ExtendedTrack(
                id=track.id,
                estimate=est,
                time=t,
                score=score,
                peak=max(track.peak, score),
                hits=track.hits + (1 if n else 0),
                confirmed=track.confirmed or score >= tm.confirm_threshold,
                created=track.created,
                updated=t if n else track.updated,
                gamma=gamma,
                detection_ids=_ids(scan, chosen),
                split_evidence=0 if splitting else evidence,
                split_centroid=split_c,
                split_gap=split_d,
                split_time=t,
                shed_evidence=shed_n,
                shed_centroid=shed_c,
                shed_gap=shed_d,
                shed_time=t if shed is not None or not shed_n else track.shed_time,
                origin=track.origin,
                visitors=track.visitors,
            )
            if splitting:
                claimed[split_rows] = True
                child = _born(
                    f"{self.id_prefix}E{next_id}",
                    scan,
                    split_rows,
                    split_v,
                    new.confirmed,
                    tm.confirm_threshold if new.confirmed else new.score,
                    float(split_rows.size),
                    cfg,
                    tm,
                    velocity_std=SPLIT_VELOCITY_STD,
                )
                spawned.append(child)
                next_id += 1
            if _dead(new, t, cfg, tm):
                if new.confirmed:
                    deleted.append(new.id)
                continue
            kept.append(new)
        kept, merged = _merge(kept + spawned, cfg)
        deleted.extend(merged)
        step = t - state.time if state.time is not None and t > state.time else 0.0
        kept, cells, take, seen = _hybridize(
            kept, view, dict(state.absorbing), step, t, cfg, point_gates
        )
        absorbed = tuple(sorted(take))
        if absorbed:
            index = view.index()
            gone = tuple(tid for tid in absorbed if view.confirmed[index[tid]])
        else:
            gone = ()
        # Births from clusters no extended track explains.
        pairs = (
            None
            if tree is None
            else tree.query_pairs(cfg.resolution_distance, output_type="ndarray")
        )
        born, candidates, next_id = self._births(
            scan, view, claimed, pairs, point_gates, state, cfg, next_id, t, sigma or 0.0
        )
        for _, rows in born:
            claimed[rows] = True
        tracks = tuple(kept) + tuple(track for track, _ in born)
        new_state = replace(
            state,
            tracks=tracks,
            candidates=candidates,
            next_id=next_id,
            time=t,
            absorbing=tuple((tid, k) for tid, k in seen.items() if tid not in take),
            noise=noise,
        )
        return PeerProposal(
            claimed=claimed,
            cells=cells,
            take=absorbed,
            tracks=tuple(_snapshot(tr, t) for tr in tracks),
            deleted=tuple(deleted) + gone,
            state=new_state,
        )

    # -- births --------------------------------------------------------------------------------

    def _births(self, scan, view, claimed, pairs, point_gates, state, cfg, next_id, t, sigma):
        """New tracks from the clusters of the unclaimed detections (module docstring, step
        6); ``view`` the point tracks, ``pairs`` the pairs of the scan's detections closer
        than the resolution distance (from the k-d tree the tracks used), if known; ``sigma``
        the scan's position noise (:func:`position_noise`); ``cfg``
        the configuration with the resolution distance in force."""
        tm = state.management
        free = ~claimed
        if pairs is None and not claimed.any():
            i, j = close_pairs(scan.z, cfg.resolution_distance)
        elif pairs is None:
            rows = np.flatnonzero(free)
            i, j = close_pairs(np.take(scan.z, rows, axis=0), cfg.resolution_distance)
            i, j = np.take(rows, i), np.take(rows, j)
        else:  # the pairs of free detections among them
            i, j = pairs[:, 0], pairs[:, 1]
            both = np.flatnonzero(free[i] & free[j])
            i, j = np.take(i, both), np.take(j, both)
        # The clusters: the subsets of at least min_detections (≥ 2) free detections (rows
        # ascending, in order of their first row), as lists for their centroids on floats.
        subsets = pair_subsets(scan.size, i, j, max(2, cfg.min_detections))
        if subsets:
            # Only what a group may hold makes a run: the detections confirmed tracks
            # explain are the individual targets' (a platoon of cars is no object, and a
            # track lost for a scan or two does not start one either).
            kept = _less_explained(subsets, point_gates())
            subsets = [rows for rows in kept if rows.size >= max(2, cfg.min_detections)]
        if subsets:
            stated = scan.clutter_density
            subsets = _standing_out(
                subsets,
                scan,
                scan.clutter_scene if stated is None else float(stated),
                sigma,
                around=scan.clutter_around if stated is None else None,
            )
        clusters = subsets
        centroids = _centroids(scan, clusters)
        # Each cluster's run: the candidate it continues (nearest to its prediction).
        match: list[_Candidate | None] = [None] * len(clusters)
        candidates: list[_Candidate] = []
        in_view = _runs_in_view(state.candidates, scan, cfg, t)
        for cand, looked in zip(state.candidates, in_view, strict=True):
            dt = t - cand.time
            if dt <= 0 or not looked:  # a run out of view goes on
                candidates.append(cand)
                continue
            px, py = cand.predicted(t)
            if not clusters:
                if (kept_run := cand.missed_by(scan.sensor_id, cfg.birth_scans)) is not None:
                    candidates.append(kept_run)
                continue
            reach = cfg.resolution_distance + (
                cfg.max_speed * dt if cand.seen == 1 else 2.0 * cfg.group_speed_spread * dt
            )
            best, best_d = -1, reach
            for k, (cx, cy) in enumerate(centroids):
                d = math.hypot(cx - px, cy - py)
                if d <= best_d and match[k] is None:
                    best, best_d = k, d
            if best >= 0:
                match[best] = cand
            elif (kept_run := cand.missed_by(scan.sensor_id, cfg.birth_scans)) is not None:
                candidates.append(kept_run)  # another sensor's miss, or its one allowed
        born: list[tuple[ExtendedTrack, np.ndarray]] = []
        ripe: list[tuple[np.ndarray, _Candidate]] = []
        for k, centroid in enumerate(centroids):
            cand = match[k]
            run = None if cand is None else cand.seen_again(centroid, t, scan.sensor_id)
            if run is None or math.hypot(*run.slope()) > cfg.max_speed:
                candidates.append(_Candidate.first(centroid, t, scan.sensor_id))
            elif run.seen >= cfg.birth_scans and t - run.first_time >= cfg.birth_time:
                ripe.append((subsets[k], run))
            else:
                candidates.append(run)
        if not ripe:
            return born, tuple(candidates), next_id
        # A run that would start a track now: only the detections a group may hold count. A
        # confirmed individual track explains detections of a cluster only if it is older than
        # the cluster's run: tracks that the cluster's own detections confirmed (clutter that
        # a point tracker takes for targets) hold nothing back. A run left with too few starts
        # again.
        since = np.array([run.first_time for _, run in ripe])
        moving = (
            np.array([run.slope() for _, run in ripe]),
            np.array([run.velocity_std(0.5 * cfg.resolution_distance) for _, run in ripe]),
        )
        kept = _group_clusters([rows for rows, _ in ripe], point_gates(), cfg, since, moving)
        kept = _not_acquiring(kept, view, scan)
        kept = _among_individuals(kept, scan, point_gates(), sigma, moving, cfg.group_speed_spread)
        members = [
            _members_velocity(rows, point_gates(), cfg, run.first_time, run.velocity, sd)
            for rows, (_, run), sd in zip(kept, ripe, moving[1].tolist(), strict=True)
        ]
        for rows, (_, run), held in zip(kept, ripe, members, strict=True):
            if rows.size < cfg.min_detections:
                candidates.append(_Candidate.first(run.centroid, t, scan.sensor_id))
                continue
            velocity, velocity_std = _birth_velocity(
                run.velocity, run.velocity_std(0.5 * cfg.resolution_distance), held
            )
            track = _born(
                f"{self.id_prefix}E{next_id}",
                scan,
                rows,
                velocity,
                False,
                initial_score(tm.new_target_density, tm.clutter_density),
                float(rows.size),
                cfg,
                tm,
                velocity_std=min(cfg.max_speed, max(BIRTH_VELOCITY_STD, velocity_std)),
                origin=run.first_time,
            )
            born.append((track, rows))
            next_id += 1
        return born, tuple(candidates), next_id


def _centroids(scan: Scan, clusters: list[np.ndarray]) -> list[tuple[float, float]]:
    """The mean of each cluster's detections (rows of ``scan``), all at once: sums over the
    clusters' runs of rows."""
    if not clusters:
        return []
    sizes = [rows.size for rows in clusters]
    starts = list(itertools.accumulate(sizes[:-1], initial=0))
    sums = np.add.reduceat(scan.z.take(np.concatenate(clusters), axis=0), starts, axis=0)
    return [(x / n, y / n) for (x, y), n in zip(sums.tolist(), sizes, strict=True)]


def _members_velocity(
    rows: np.ndarray,
    pg: _PointGates,
    cfg: ExtendedConfig,
    since: float = -math.inf,
    run_v: np.ndarray | None = None,
    run_sd: float = math.inf,
) -> tuple[np.ndarray, float] | None:
    """The velocity of a cluster (detections ``rows`` of the scan) that the confirmed
    individual tracks in it show, and its standard deviation per axis: the mean ``v̄`` of the
    velocities ``vᵢ`` of the tracks with one of the cluster's detections in their gate, that
    :func:`_group_clusters` lets explain it (created before ``since``, the run's first time,
    or resolved; moving within ``group_speed_spread`` plus twice ``run_sd`` of the run's
    velocity ``run_v``), that move together (within ``group_speed_spread`` of their
    median), two at least, with

        σ² = max(s², σ̄²) / n,    s² = Σ‖vᵢ − v̄‖² / (2 (n − 1)),    σ̄² = mean of tr(P_vᵢ) / 2,

    (the scatter of the tracks' velocities, or their own uncertainty if that is larger,
    over the ``n`` tracks); ``None`` without two such tracks. A ship's scatterers that a
    radar resolves are held by individual tracks before the ship's track starts: their
    velocities are noisy, but far less so than the slope of the cluster's centroid, which
    jumps along the hull with whichever scatterers a scan shows."""
    if pg.det.size == 0 or rows.size == 0:
        return None
    mine = np.zeros(pg.size, dtype=bool)
    mine[rows] = True
    pairs = mine[pg.det]
    if since > -math.inf:  # young tracks explain only what they resolve
        pairs &= (np.take(pg.created, pg.trk) < since) | pg.resolved
    trk = np.unique(pg.trk[pairs])
    if run_v is not None and trk.size:
        off = np.hypot(*(np.take(pg.v, trk, axis=0) - run_v).T)
        trk = trk[off <= cfg.group_speed_spread + 2.0 * run_sd]
    if trk.size < 2:
        return None
    v = np.take(pg.v, trk, axis=0)
    together = np.hypot(*(v - np.median(v, axis=0)).T) <= cfg.group_speed_spread
    n = int(together.sum())
    if n < 2:
        return None
    v = v[together]
    mean = v.mean(axis=0)
    scatter = float(np.sum((v - mean) ** 2)) / (2.0 * (n - 1))
    Pv = np.take(pg.Pv, trk[together], axis=0)
    own = float(np.mean(Pv[:, 0, 0] + Pv[:, 1, 1])) / 2.0
    return mean, math.sqrt(max(scatter, own) / n)


def _birth_velocity(
    slope: np.ndarray, slope_std: float, members: tuple[np.ndarray, float] | None
) -> tuple[np.ndarray, float]:
    """A new extended track's velocity and its standard deviation per axis: the slope of its
    cluster's centroids (std ``slope_std``), combined with the velocity its confirmed
    individual tracks show (:func:`_members_velocity`), if any, by inverse variances:

        v = (σ_m² v_c + σ_c² v_m) / (σ_c² + σ_m²),    σ² = σ_c² σ_m² / (σ_c² + σ_m²)."""
    if members is None:
        return slope, slope_std
    v_m, s_m = members
    if not math.isfinite(slope_std):
        return v_m, s_m
    a, b = slope_std**2, s_m**2
    return (b * slope + a * v_m) / (a + b), math.sqrt(a * b / (a + b))


#: A tentative track of this many detections is a target being acquired: a birth leaves its
#: detection to it when it explains it one to one (:attr:`_PointGates.explained`).
ESTABLISHED_HITS = 3


def _not_acquiring(
    clusters: list[np.ndarray], view: PointTrackView, scan: Scan
) -> list[np.ndarray]:
    """The detections of each cluster (rows of the scan) less those of targets being
    acquired: explained one to one (:attr:`_PointGates.explained`) by tracks of
    :data:`ESTABLISHED_HITS` detections or more, confirmed or not yet, alone or two side by
    side, or with a rival track of the same start (cars entering a radar's view in a dense
    flow, whose tracks take a few scans to confirm)."""
    return _less_explained(clusters, _PointGates(view, scan, ESTABLISHED_HITS))


#: A cluster is a group only if it holds this many times the detections that false alarms
#: of the scan's density would put in its box (:func:`_standing_out`).
GROUP_CONTRAST = 3.0


def _among_individuals(
    clusters: list[np.ndarray],
    scan: Scan,
    pg: _PointGates,
    sigma: float,
    moving: tuple[np.ndarray, np.ndarray],
    spread: float,
) -> list[np.ndarray]:
    """The clusters (rows of the scan that a group would hold) less those that lie among
    more individual targets than they hold detections. Cluster ``k`` of ``n`` detections
    with mean ``z̄``, principal axes ``a₁, a₂`` and scatter eigenvalues ``λ₁, λ₂`` is dropped
    (emptied: it restarts as a candidate) when

        #{j ∉ cluster : |a_iᵀ (z_j − z̄)| ≤ ½ √(12 λ_i) + 2σ, i = 1, 2} > n

    over the scan's detections ``z_j`` that a confirmed individual track explains one to one
    (:attr:`_PointGates.explained`) and that move apart from the cluster's run: the track's
    velocity more than ``spread`` plus twice the run's velocity std from the run's
    (``moving``: each cluster's run velocity ``(K, 2)`` and std ``(K,)``, as
    :func:`_group_clusters` has them; a convoy's own tracked vehicles do not count against
    it). The box is :func:`_standing_out`'s, grown by two standard deviations ``sigma`` of
    the noise each way. A crowd of pedestrians walking every way, each with their own track,
    leaves a few detections that no track explains one to one (people side by side, false
    alarms); chained at the resolution distance through the crowd they spanned a plaza, and
    one group track over it took every person's detections."""
    if not clusters or pg.det.size == 0:
        return clusters
    pairs = np.flatnonzero(pg.explained)
    det, trk = pg.det[pairs], pg.trk[pairs]
    v = np.take(pg.v, trk, axis=0)
    run_v, run_sd = moving
    out = []
    for k, rows in enumerate(clusters):
        if rows.size < 2 or det.size == 0:
            out.append(rows)
            continue
        apart = np.hypot(*(v - run_v[k]).T) > spread + 2.0 * run_sd[k]
        others = np.zeros(scan.size, dtype=bool)
        others[det[apart]] = True
        others[rows] = False
        idx = np.flatnonzero(others)
        if idx.size == 0:
            out.append(rows)
            continue
        z = scan.z.take(rows, axis=0)
        mean = z.mean(axis=0)
        d = z - mean
        lam, axes = np.linalg.eigh(d.T @ d / rows.size)
        half = 0.5 * np.sqrt(12.0 * np.maximum(lam, 0.0)) + 2.0 * sigma
        local = (scan.z.take(idx, axis=0) - mean) @ axes
        inside = np.count_nonzero(np.all(np.abs(local) <= half, axis=1))
        out.append(rows if inside <= rows.size else rows[:0])
    return out


def _standing_out(
    clusters: list[np.ndarray],
    scan: Scan,
    clutter: float | None,
    sigma: float,
    around: Callable[[np.ndarray], np.ndarray] | None = None,
) -> list[np.ndarray]:
    """The clusters (rows of the scan) that stand out from the clutter about them: those of
    ``n`` detections with

        n ≥ c λ (w + 4σ)(h + 4σ),    w, h = √(12 λ₁), √(12 λ₂),

    ``w × h`` the box of the cluster along its principal axes (``λ₁``, ``λ₂`` the
    eigenvalues of its detections' scatter matrix: the sides of a uniformly filled
    rectangle, whatever its heading), grown by two standard deviations ``sigma`` of the
    scan's position noise on each side (all clusters at once), ``λ`` the false-alarm
    density ``clutter`` (the scan's stated one, or its sensor's whole scene's as the clutter
    map learned it, or, where denser, the map's density ``around`` the cluster's centroid
    when given; ``None``: every cluster) and ``c`` = :data:`GROUP_CONTRAST`. Chained at
    the resolution distance, false alarms spread evenly over a sensor's small scene are one
    cluster as dense as the scene itself (a radar over a 400 m road junction, 2-80 false
    alarms a scan, no density stated: one extended track took the square and its targets); a
    ship's returns, a convoy, a patch of backwash are many times denser than the clutter about
    them (a lone ship's returns, which the map counts before its tracks hold them, about four
    times). Sea clutter near a coastal radar (a thousand false alarms a scan within 6 km, few
    beyond) is a hundred times denser than the radar's whole scene, and clusters of it started
    group tracks that fed on it; the block of cells about them is as dense as they are."""
    if clutter is None or not clutter > 0:
        return clusters
    sizes = [rows.size for rows in clusters]
    n = np.array(sizes, dtype=float)
    starts = list(itertools.accumulate(sizes[:-1], initial=0))
    z = scan.z.take(np.concatenate(clusters), axis=0)
    x, y = z[:, 0], z[:, 1]
    mx = np.add.reduceat(x, starts) / n
    my = np.add.reduceat(y, starts) / n
    dx, dy = x - np.repeat(mx, sizes), y - np.repeat(my, sizes)
    sxx = np.add.reduceat(dx * dx, starts) / n
    syy = np.add.reduceat(dy * dy, starts) / n
    sxy = np.add.reduceat(dx * dy, starts) / n
    half, root = 0.5 * (sxx + syy), np.hypot(0.5 * (sxx - syy), sxy)
    w = np.sqrt(12.0 * (half + root)) + 4.0 * sigma
    h = np.sqrt(12.0 * np.maximum(half - root, 0.0)) + 4.0 * sigma
    lam = clutter if around is None else np.maximum(clutter, around(np.column_stack([mx, my])))
    expected = GROUP_CONTRAST * lam * w * h
    return [rows for rows, e in zip(clusters, expected.tolist(), strict=True) if rows.size >= e]


def _less_explained(clusters: list[np.ndarray], pg: _PointGates) -> list[np.ndarray]:
    """The detections of each cluster (rows of the scan) less those that the tracks of
    ``pg`` explain one to one (:attr:`_PointGates.explained`)."""
    if pg.det.size == 0:
        return clusters
    theirs = pg.explained_detections
    return [rows[~theirs[rows]] for rows in clusters]


def _group_clusters(
    clusters: list[np.ndarray],
    pg: _PointGates,
    cfg: ExtendedConfig,
    since: np.ndarray | None = None,
    moving: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[np.ndarray]:
    """The detections of each cluster (rows of the scan) that a group may hold: those no
    confirmed individual track explains, and those of confirmed tracks that move together
    (within ``group_speed_spread`` of the median velocity of the cluster's tracks, two
    tracks at least, the median itself faster than that: tracks at rest together are
    targets each). With ``since`` (one time per cluster), a track created since explains
    that cluster's detections only if it is resolved (its gate holds one detection, which no
    other gate holds). With ``moving`` (each cluster's run velocity ``(K, 2)`` and its std
    ``(K,)``), tracks that move together move with their cluster too: within
    ``group_speed_spread`` plus twice that std of the run's velocity (cars of the other
    carriageway that pass a cluster of cars move together, but not with it). All clusters at
    once, in array operations."""
    if pg.det.size == 0:
        return clusters
    K, m = len(clusters), pg.rows.size
    which = np.full(pg.size, -1, dtype=np.intp)
    which[np.concatenate(clusters)] = np.repeat(np.arange(K), [r.size for r in clusters])
    c = which[pg.det]
    inside = c >= 0
    if since is not None:
        # A track the cluster's own detections started explains its detection only when it
        # is resolved: the one detection in its gate, in no other track's gate (independent
        # targets seen together from the start; not an object's scattered returns).
        trk = pg.trk[inside]
        inside[inside] = (np.take(pg.created, trk) < since[c[inside]]) | pg.resolved[inside]
    if not inside.any():
        return clusters
    c, det, trk = c[inside], pg.det[inside], pg.trk[inside]
    key = c * m + trk
    uniq = np.unique(key)  # each (cluster, track) once, by cluster
    uc, ut = np.divmod(uniq, m)
    v = np.take(pg.v, ut, axis=0)
    counts = np.bincount(uc, minlength=K)
    lo = np.cumsum(counts) - counts + np.maximum(counts - 1, 0) // 2
    hi = np.cumsum(counts) - counts + counts // 2
    median = np.zeros((K, 2))
    has = counts > 0
    for axis in (0, 1):  # per-cluster median: sort by (cluster, component)
        sv = v[np.lexsort((v[:, axis], uc)), axis]
        median[has, axis] = 0.5 * (sv[lo[has]] + sv[hi[has]])
    near = np.hypot(*(v - np.take(median, uc, axis=0)).T) <= cfg.group_speed_spread
    if moving is not None:
        run_v, run_sd = moving
        off = np.hypot(*(v - np.take(run_v, uc, axis=0)).T)
        near &= off <= cfg.group_speed_spread + 2.0 * np.take(run_sd, uc)
    # At rest, moving together says nothing: cars queued at a junction are each their own
    # target, and a group born over them took the queue (both approaches, at times). The
    # tracks' median tells (a run's velocity, from centroids of whichever of an object's
    # returns were seen, is the noisier).
    near &= np.take(np.hypot(*median.T) > cfg.group_speed_spread, uc)
    near &= np.bincount(uc, weights=near, minlength=K)[uc] >= 2
    ok = near[np.searchsorted(uniq, key)]
    if ok.all():
        return clusters
    drop = np.zeros(pg.size, dtype=bool)
    drop[det[~ok]] = True
    return [rows[~drop[rows]] for rows in clusters]


def _gate_radius(ga: float, gb: float, gc: float, cfg: ExtendedConfig) -> float:
    """The radius of a gate ``mᵀ S⁻¹ m ≤ gate_threshold`` with ``S = [[ga, gb], [gb, gc]]``:
    ``√(γ λ_max(S))``."""
    return math.sqrt(cfg.gate_threshold * (0.5 * (ga + gc) + _hypot(0.5 * (ga - gc), gb)))


def _owners(
    ests: list[ExtendedEstimate],
    scan: Scan,
    tree: cKDTree,
    R_mean: np.ndarray,
    cfg: ExtendedConfig,
) -> np.ndarray | None:
    """For each detection in the gates of two extended tracks or more (predicted ``ests``),
    the one under which it is likeliest, ``N(y; H x, H P Hᵀ + z X + R̄)``; −1 for the others.
    ``None`` when no detection is in two gates. Two groups crossing (the two carriageways of a
    motorway) then each keep their own detections, the nearer to their predicted centroid,
    instead of the first one taking all of both and the other starving."""
    if len(ests) < 2:
        return None
    best = np.full(scan.size, -np.inf)
    owner = np.full(scan.size, -1, dtype=np.intp)
    seen = np.zeros(scan.size, dtype=np.intp)
    for i, est in enumerate(ests):
        ga, gb, gc = innovation_entries(est, 1, R_mean, cfg.z_scale)
        near = np.asarray(
            tree.query_ball_point(est.x[:2], _gate_radius(ga, gb, gc, cfg)), dtype=np.intp
        )
        if near.size == 0:
            continue
        m, ll = log_gaussian_2d(
            np.take(scan.z, near, axis=0) - est.x[:2], np.array([[ga, gb], [gb, gc]])
        )
        inside = m <= cfg.gate_threshold
        near, ll = near[inside], ll[inside]
        seen[near] += 1
        better = ll > best[near]
        best[near[better]] = ll[better]
        owner[near[better]] = i
    shared = seen >= 2
    if not shared.any():
        return None
    owner[~shared] = -1
    return owner


def _gated_subsets(
    est: ExtendedEstimate,
    scan: Scan,
    tree: cKDTree,
    R_mean: np.ndarray,
    claimed: np.ndarray,
    point_gates: Callable[[], _PointGates],
    cfg: ExtendedConfig,
    track: ExtendedTrack | None = None,
) -> tuple[list[list[int]], dict[int, tuple[float, ...]], dict[int, float] | None]:
    """The detections a track predicted to ``est`` may take, as resolution subsets (rows of
    the scan, in the k-d tree's order): of the unclaimed detections near it, less the one
    nearest to each confirmed individual track not moving with it (velocities more than
    ``group_speed_spread`` apart) and not started by its own detections (created since
    ``track``'s cluster was first seen, never seen coming from outside: those of a ship's
    returns that jump about its hull would starve a new track of them), the subsets with a
    detection in its gate ``mⱼ = (yⱼ − H x)ᵀ (H P Hᵀ + z X + Rⱼ)⁻¹ (yⱼ − H x) ≤ gate_threshold``,
    whole (a bending column). Near: within 1.5 times the radius of the gate with the scan's
    mean ``R̄`` plus a resolution distance. Also returns the near detections as
    :func:`_points` gives them, and ``mⱼ`` of each detection of the subsets that lies in the
    gate when the gate's radius (with ``R̄``) is less than the resolution distance (else
    None)."""
    ga, gb, gc = innovation_entries(est, 1, R_mean, cfg.z_scale)  # H P Hᵀ + z X + R̄
    radius = _gate_radius(ga, gb, gc, cfg)
    c0, c1, v0, v1 = est.x.tolist()
    reach = 1.5 * radius + cfg.resolution_distance
    near = np.asarray(tree.query_ball_point((c0, c1), reach), dtype=np.intp)
    near = near[~claimed[near]]
    if near.size == 0:
        return [], {}, None
    points = _points(scan, near)
    rows = near.tolist()
    theirs = point_gates().theirs(
        sorted(rows),
        points,
        (c0, c1),
        reach,
        (v0, v1),
        cfg.group_speed_spread,
        (
            (math.inf, frozenset(), 0.0)
            if track is None
            else (track.origin, track.visitors, cfg.max_speed)
        ),
    )
    if theirs:
        rows = [r for r in rows if r not in theirs]
    (r00, r01), (_, r11) = R_mean.tolist()
    ha, hb, hc = ga - r00, gb - r01, gc - r11  # the gate less R̄, to which each Rⱼ is added
    m = []
    for r in rows:
        x, y, ra, rb, _, rc = points[r]
        x, y = x - c0, y - c1
        a, b, c = ha + ra, hb + rb, hc + rc
        m.append((c * x * x - 2.0 * b * x * y + a * y * y) / (a * c - b * b))
    gated = [mk <= cfg.gate_threshold for mk in m]
    subsets = [
        s
        for s in point_subsets([points[r][:2] for r in rows], cfg.resolution_distance)
        if any(gated[k] for k in s)
    ]
    # An object whose gate is narrower than the resolution distance cannot reach beyond it
    # through detections of its own: what a subset chains to out there is someone else's.
    inside = (
        {rows[k]: m[k] for s in subsets for k in s if gated[k]}
        if radius < cfg.resolution_distance
        else None
    )
    return [[rows[k] for k in s] for s in subsets], points, inside


def _likeliest(
    track: ExtendedTrack,
    est: ExtendedEstimate,
    scan: Scan,
    subsets: list[list[int]],
    points: dict[int, tuple[float, ...]],
    cfg: ExtendedConfig,
    log_lam: float,
    inside: dict[int, float] | None,
) -> tuple[float, list[int], list[list[int]], list[list[int]], tuple[np.ndarray, Moments] | None]:
    """The likeliest candidate set of detections, by

        ΔL(W) = ln Poisson(|W|; γ) + ln f(W) − |W| ln λ_fa,    ΔL(∅) = −γ

    (no detection at all is a candidate too; ``log_lam`` = ln λ_fa). The candidates are the
    nested unions of ``subsets`` (ranked by the Mahalanobis distance of each subset's
    centroid to the predicted one, under ``H P Hᵀ + z X + R̄`` over the square root of the
    subset's size, ``R̄`` the mean over all the subsets) and, when the subsets hold
    detections outside the
    gate of an object smaller than the resolution distance (``inside`` not None: a
    resolution subset chains it to clutter, a buoy or another target up to a resolution
    distance away), the nested unions of the detections ``inside`` the gate alone, ranked by
    their ``mⱼ``.

    Returns ``ΔL``, the union's rows (ascending), the parts of the subsets in it and the
    subsets of at least two detections left out of it, and its mean ``R`` and
    :func:`moments` (None for no detection)."""
    gain = -track.gamma  # ΔL(∅)
    if not subsets:
        return gain, [], [], [], None
    rows = sorted(r for s in subsets for r in s)
    G1 = innovation_entries(est, 1, _mean_R(points, rows), cfg.z_scale)
    c0, c1 = est.x[:2].tolist()
    fit = []
    for s in subsets:
        mx, my = _centroid(points, s)
        x, y = mx - c0, my - c1
        root = max(1, len(s)) ** 0.5
        a, b, c = (g / root for g in G1)
        fit.append((c * x * x - 2.0 * b * x * y + a * y * y) / (a * c - b * b))
    families = [[subsets[k] for k in sorted(range(len(subsets)), key=fit.__getitem__)]]
    if inside is not None and len(inside) < len(rows):  # some lie outside the gate
        families.append([[r] for r in sorted(inside, key=inside.__getitem__)])
    chosen: list[int] = []
    R_best = mom_best = None
    for family in families:
        union: list[int] = []
        for add in family:
            union.extend(add)
            W = sorted(union)
            Rm = _mean_R(points, W)
            mom = moments(np.take(scan.z, W, axis=0))
            g = (
                _log_poisson(len(W), track.gamma)
                + moments_log_likelihood(est, mom, Rm, cfg.z_scale, extent_uncertain=True)
                - len(W) * log_lam
            )
            if g > gain:
                gain, chosen, R_best, mom_best = g, W, Rm, mom
    if not chosen:
        return gain, [], [], [], None
    taken = set(chosen)
    parts = [p for p in ([r for r in s if r in taken] for s in subsets) if p]
    left_out = [s for s in subsets if len(s) >= 2 and not taken.intersection(s)]
    return gain, chosen, parts, left_out, (R_best, mom_best)


def _hybridize(
    tracks: list[ExtendedTrack],
    view: PointTrackView,
    before: dict[str, int],
    step: float,
    t: float,
    cfg: ExtendedConfig,
    point_gates: Callable[[], _PointGates] | None = None,
) -> tuple[list[ExtendedTrack], tuple[ResolutionCell, ...], set[str], dict[str, int]]:
    """Resolution cells and absorbed individual tracks (module docstring, step 5). Returns
    the tracks (their visitors brought up to date), the cells of the confirmed ones, the ids
    of the individual tracks to take, and the confirmed ones seen moving with an extent
    (scans in a row; ``before``: as of the last scan). A confirmed track moving with it that
    explains its detection one to one (:attr:`_PointGates.explained_tracks` of
    ``point_gates``) is not absorbed; those its own detections started are."""
    cells: list[ResolutionCell] = []
    take: set[str] = set()
    seen: dict[str, int] = {}
    if not len(view) or not tracks:
        return tracks, (), take, seen
    tracks = list(tracks)
    ids = view.ids
    live: set[str] | None = None
    half = 0.5 * cfg.resolution_distance
    spread, max_speed = cfg.group_speed_spread, cfg.max_speed
    for pos, track in enumerate(tracks):
        est = track.estimate
        cx, cy, ex, ey = est.x.tolist()
        cell, watch = _grown(est.X, half, half + max_speed * step)
        (ca, cb), (_, cc) = cell.tolist()
        (wa, wb), (_, wc) = watch.tolist()
        (xa, xb), (_, xc) = est.X.tolist()
        # Only the individual tracks within the largest ellipse's major semi-axis (a little
        # more, for rounding; √(tr X) bounds X's) can be inside any of them: the others are
        # never looked at. On floats, operation for operation as the array formulas.
        reach = (math.sqrt(xa + xc) + half + max_speed * step) * (1.0 + 1e-6) + 1e-6
        near = _near_rows(view, cx, cy, reach)
        in_cell, near_out, inside = [], [], []
        for i, (x, y) in zip(near, np.take(view.x[:, :2], near, axis=0).tolist(), strict=True):
            x, y = x - cx, y - cy
            if (cc * x * x - 2.0 * cb * x * y + ca * y * y) / (ca * cc - cb * cb) <= 1.0:
                in_cell.append(i)
            elif (wc * x * x - 2.0 * wb * x * y + wa * y * y) / (wa * wc - wb * wb) <= 1.0:
                # a visitor: an individual track seen near it but outside its cell (a vehicle
                # coming up to it), which never counts as started by its own detections
                near_out.append(i)
            if (xc * x * x - 2.0 * xb * x * y + xa * y * y) / (xa * xc - xb * xb) <= 1.0:
                inside.append(i)
        visitors = track.visitors
        if visitors:
            live = set(ids) if live is None else live
            visitors = frozenset(v for v in visitors if v in live)
        visitors = visitors | {ids[i] for i in near_out}
        if visitors != track.visitors:
            tracks[pos] = track = replace(track, visitors=visitors)
        if not track.confirmed:
            continue
        established = track.hits >= cfg.birth_scans and t - track.created >= cfg.birth_time
        cells.append(ResolutionCell(center=est.x[:2], matrix=cell, pd=cfg.in_cell_pd))
        # tracks that its own detections started since its cluster was first seen:
        # in its cell, never seen coming, no faster than a group
        for i in in_cell:
            if (
                view.created[i] >= track.origin
                and _hypot(view.x[i, 2], view.x[i, 3]) <= max_speed
                and ids[i] not in visitors
            ):
                take.add(ids[i])
        if not established:
            continue
        # a confirmed track must move with it within the spread itself, for ABSORB_SCANS
        # scans in a row; a tentative one within its uncertainty too (:func:`_moves_with`)
        (pa, _), (_, pc) = est.P[2:4, 2:4].tolist()
        for i in inside:
            tid = ids[i]
            if tid in take:
                continue
            confirmed = bool(view.confirmed[i])
            vx, vy = view.x[i, 2:4].tolist()
            sd = math.sqrt(0.5 * (float(view.P[i, 2, 2] + view.P[i, 3, 3]) + (pa + pc)))
            if not _hypot(vx - ex, vy - ey) <= spread + (0.0 if confirmed else 1.0) * sd:
                continue
            if not confirmed:
                take.add(tid)
            elif _resolved(point_gates, i):
                continue
            else:
                seen[tid] = before.get(tid, 0) + 1
                if seen[tid] >= ABSORB_SCANS:
                    take.add(tid)
    return tracks, tuple(cells), take, seen


def _resolved(point_gates: Callable[[], _PointGates] | None, row: int) -> bool:
    """Whether the confirmed track at ``row`` of the view is a target of its own."""
    if point_gates is None:
        return False
    pg = point_gates()
    k = int(np.searchsorted(pg.rows, row))
    return bool(pg.explained_tracks[k])


def _near_rows(view: PointTrackView, cx: float, cy: float, reach: float) -> list[int]:
    """The rows of the view whose predicted position is within ``reach`` of ``(cx, cy)``."""
    xy = view.x[:, :2]
    dx, dy = xy[:, 0] - cx, xy[:, 1] - cy
    return np.flatnonzero(dx * dx + dy * dy <= reach * reach).tolist()


def _split_evidence(
    track: ExtendedTrack,
    points: dict[int, tuple[float, ...]],
    parts: list[list[int]],
    left_out: list[list[int]],
    t: float,
    cfg: ExtendedConfig,
) -> tuple[int, list[int], tuple[float, float], float, np.ndarray]:
    """The split evidence after this scan (paper 002: an extent that grows because its
    detections fall apart into separated subsets is a group separating). The *main* part is
    the largest subset of the track's chosen detections ``parts``; of the other subsets of at
    least two detections, chosen or left out, the one farthest from it (centroid distance, the gap,
    more than the resolution distance by construction of the subsets) is the separating one.
    The evidence grows when the gap is larger than at the previous scan and the subset is
    where the previous one could have gone at the parent's speed (plus twice
    ``group_speed_spread``, and half a resolution distance of jitter): a group moving away; a
    gap that a missed vehicle
    leaves in a column closes again, and a column bending round a corner stays one subset).
    Subsets are lists of rows of the scan, ``points`` their detections (:func:`_points`).
    Returns the evidence, the subset's rows, its centroid, the gap and its velocity from the two
    scans."""
    none = (0, [], (0.0, 0.0), 0.0, np.zeros(2))
    if not parts:
        return none
    velocity = track.estimate.x[2:4].copy()
    dt = t - track.split_time
    # a group driving off keeps about the parent's speed
    reach = _hypot(*velocity.tolist()) + 2.0 * cfg.group_speed_spread
    everyone = parts + left_out
    centroid = {id(r): _centroid(points, r) for r in everyone}

    def apart(r: list[int], c: tuple[float, float]) -> float:
        """Distance from the centroid of ``r`` to ``c``."""
        cr = centroid[id(r)]
        return _hypot(cr[0] - c[0], cr[1] - c[1])

    if track.split_evidence and dt > 0:  # the subset that was separating, if it still is
        prev = track.split_centroid
        near = [
            r
            for r in everyone
            if len(r) >= 2 and apart(r, prev) <= 0.5 * cfg.resolution_distance + reach * dt
        ]
        if near:
            rows = min(near, key=lambda r: apart(r, prev))
            rest = [r for r in parts if r is not rows]
            if rest:
                main = max(rest, key=len)
                cs = centroid[id(rows)]
                gap = apart(main, cs)
                if gap > track.split_gap:
                    evidence = track.split_evidence + 1
                    v = np.array([(cs[0] - prev[0]) / dt, (cs[1] - prev[1]) / dt])
                    return evidence, rows, cs, gap, v
    main = max(parts, key=len)
    others = [r for r in everyone if r is not main and len(r) >= 2]
    if not others:
        return none
    c_main = centroid[id(main)]
    rows = max(others, key=lambda r: apart(r, c_main))
    cs = centroid[id(rows)]
    return 1, rows, cs, apart(rows, c_main), velocity


def _lone_evidence(
    track: ExtendedTrack,
    points: dict[int, tuple[float, ...]],
    parts: list[list[int]],
    left_out: list[list[int]],
    t: float,
    cfg: ExtendedConfig,
) -> tuple[int, int | None, tuple[float, float], float]:
    """The evidence that one vehicle is leaving the group by itself (the track's ``shed_*``
    fields; :func:`_split_evidence` does the same for groups of two or more): a detection
    alone in its subset (more than the resolution distance from every other), outside the
    largest subset, that moves away from the track's predicted centroid ``c``. It grows at
    each scan when such a detection is where the last one could have gone (``max_speed``
    times the interval, plus half a resolution distance, around the last one carried along
    with the track) and its gap to ``c`` has grown; the centroid is steadier than the
    largest subset's, whose parts come and go as members are missed. A scan without one, or
    with one no farther out, lowers it by one (a vehicle is missed one scan in ten) and
    keeps the last place, gap and time; members of a column that drives on keep their gaps
    about the centroid and seldom add up to three. Returns the evidence, the detection's row
    (``None`` if none this scan), its position and its gap."""
    prev_n, prev, prev_gap = track.shed_evidence, track.shed_centroid, track.shed_gap
    if not parts:
        return max(prev_n - 1, 0), None, prev, prev_gap
    cx, cy, vx, vy = track.estimate.x.tolist()
    lag = t - track.time
    hub = (cx + vx * lag, cy + vy * lag)
    main = max(parts, key=len)
    alone = [part[0] for part in parts + left_out if len(part) == 1 and part is not main]
    dt = t - track.shed_time
    if prev_n and dt <= 0:  # another sensor's scan of the same instant: nothing new
        return prev_n, None, prev, prev_gap
    if prev_n:
        px, py = prev[0] + vx * dt, prev[1] + vy * dt
        window = 0.5 * cfg.resolution_distance + cfg.max_speed * dt
        near = [r for r in alone if _hypot(points[r][0] - px, points[r][1] - py) <= window]
        if near:
            r = min(near, key=lambda r: _hypot(points[r][0] - px, points[r][1] - py))
            x, y = points[r][:2]
            gap = _hypot(x - hub[0], y - hub[1])
            if gap > prev_gap:
                return prev_n + 1, r, (x, y), gap
        return prev_n - 1, None, prev, prev_gap
    if not alone:
        return 0, None, (0.0, 0.0), 0.0
    r = max(alone, key=lambda r: _hypot(points[r][0] - hub[0], points[r][1] - hub[1]))
    x, y = points[r][:2]
    return 1, r, (x, y), _hypot(x - hub[0], y - hub[1])


def _spread(
    scan: Scan, rows: np.ndarray, cfg: ExtendedConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """What the detections ``rows`` (n ≥ 1) spread over: their centroid ``c``, their sample
    covariance ``Ȳ/max(1, n − 1)``, the extent ``X = (Ȳ/(n − 1) − R̄) / z`` with each
    eigenvalue at least R̄'s largest (that floor times the identity for one detection), and
    the floor."""
    Z = scan.z[rows]
    n = Z.shape[0]
    Rm = np.mean(scan.R[rows], axis=0)
    c = Z.mean(axis=0)
    spread = (Z - c).T @ (Z - c) / max(1, n - 1)
    X = (spread - Rm) / cfg.z_scale
    w, V = np.linalg.eigh(0.5 * (X + X.T))
    floor = float(np.max(np.linalg.eigvalsh(Rm)))
    return c, spread, (V * np.maximum(w, floor)) @ V.T, floor


def _merge(
    tracks: list[ExtendedTrack], cfg: ExtendedConfig
) -> tuple[list[ExtendedTrack], list[str]]:
    """Tracks that have become one: where a track's centroid lies inside another's extent
    (grown by half the resolution distance) and both move alike, they become one track with
    the id, hits and history of the one with more hits and the moment-matched estimate of
    both (:func:`~trackers.extended.random_matrix.merged`, weighted by their expected
    detections; their expected detections add up). Returns the tracks kept and the ids of
    confirmed tracks removed."""
    if len(tracks) < 2:
        return tracks, []
    tracks = list(tracks)
    gone: set[int] = set()
    order = sorted(range(len(tracks)), key=lambda i: (-tracks[i].hits, tracks[i].created))
    for a_pos, a in enumerate(order):
        if a in gone:
            continue
        for b in order[a_pos + 1 :]:
            if b in gone:
                continue
            ta, tb = tracks[a], tracks[b]
            ea, eb = ta.estimate, tb.estimate
            d = eb.x[:2] - ea.x[:2]
            if _mahalanobis(d[None], _grown(ea.X, 0.5 * cfg.resolution_distance)[0])[0] > 1.0:
                continue
            if _moves_with(
                eb.x[None, 2:4],
                eb.P[None, 2:4, 2:4],
                ea.x[2:4],
                ea.P[2:4, 2:4],
                cfg.group_speed_spread,
            )[0]:
                gone.add(b)
                tracks[a] = replace(
                    ta,
                    estimate=merged((ea, eb), (ta.gamma, tb.gamma), cfg.z_scale),
                    gamma=ta.gamma + tb.gamma,
                    score=max(ta.score, tb.score),
                    peak=max(ta.peak, tb.peak),
                    confirmed=ta.confirmed or tb.confirmed,
                    created=min(ta.created, tb.created),
                    origin=min(ta.origin, tb.origin),
                    visitors=ta.visitors | tb.visitors,
                    detection_ids=ta.detection_ids + tb.detection_ids,
                    split_evidence=0,
                )
    kept = [tr for i, tr in enumerate(tracks) if i not in gone]
    return kept, [tracks[i].id for i in sorted(gone) if tracks[i].confirmed]


def _born(
    track_id: str,
    scan: Scan,
    rows: np.ndarray,
    velocity: np.ndarray,
    confirmed: bool,
    score: float,
    gamma: float,
    cfg: ExtendedConfig,
    tm: TrackManagementConfig,
    velocity_std: float = BIRTH_VELOCITY_STD,
    origin: float | None = None,
) -> ExtendedTrack:
    """A new track from the detections ``rows`` of ``scan`` moving at ``velocity``;
    ``origin`` the time its cluster was first seen (default: now)."""
    n = rows.size
    c, spread, X, floor = _spread(scan, rows, cfg)
    # the centroid of what was seen, not yet of the whole: the object may reach a resolution
    # distance beyond its detections on any side, so the centroid is uncertain by half of it
    pos_var = max(float(np.trace(spread)) / (2.0 * n) + floor, (0.5 * cfg.resolution_distance) ** 2)
    P = np.diag([pos_var, pos_var, velocity_std**2, velocity_std**2])
    est = ExtendedEstimate(
        x=np.concatenate([c, np.asarray(velocity, dtype=float)]), P=P, X=X, alpha=2.0 + n
    )
    t = float(scan.time)
    return ExtendedTrack(
        id=track_id,
        estimate=est,
        time=t,
        score=score,
        peak=score,
        hits=1,
        confirmed=confirmed,
        created=t,
        updated=t,
        gamma=max(MIN_GAMMA, gamma),
        detection_ids=_ids(scan, rows),
        origin=t if origin is None else float(origin),
    )


def _ids(scan: Scan, rows: np.ndarray) -> tuple[str, ...]:
    """The ids of the detections ``rows`` that have one."""
    ids = scan.detection_ids
    return tuple(str(ids[i]) for i in rows.tolist() if ids[i] is not None)


def _runs_in_view(
    runs: tuple[_Candidate, ...], scan: Scan, cfg: ExtendedConfig, t: float
) -> list[bool]:
    """Whether each birth run's predicted centroid, grown by the resolution distance and the
    reach of ``extended.max_speed`` since it was last seen, is in the scan's coverage (all
    when the scan covers everything)."""
    if scan.coverage is None or not runs:
        return [True] * len(runs)
    at = np.array([run.predicted(t) for run in runs], dtype=float).reshape(-1, 2)
    reach = np.array([cfg.resolution_distance + cfg.max_speed * max(t - r.time, 0.0) for r in runs])
    return scan.coverage.contains(at, reach).tolist()


def _in_view(coverage: Coverage, est: ExtendedEstimate) -> bool:
    """Whether an extended track's predicted centroid, or its extent and its 3-sigma centroid
    uncertainty about it, reach into the scan's coverage."""
    P = est.P[:2, :2]
    reach = math.sqrt(float(np.linalg.eigvalsh(est.X)[-1])) + 3.0 * math.sqrt(
        float(np.linalg.eigvalsh(P)[-1])
    )
    return bool(coverage.contains(est.x[None, :2], reach)[0])


def _dead(track: ExtendedTrack, t: float, cfg: ExtendedConfig, tm: TrackManagementConfig) -> bool:
    if not track.confirmed:
        return track.score <= tm.delete_threshold or t - track.updated > cfg.max_coast_time
    return (
        track.peak - track.score > tm.delete_drop_from_peak
        or t - track.updated > cfg.max_coast_time
    )


def snapshot_of(track: ExtendedTrack) -> TrackSnapshot:
    """The track as a snapshot at its own time (as :meth:`ExtendedTracker.snapshot` gives it)."""
    return _snapshot(track, track.time)


def _snapshot(track: ExtendedTrack, t: float) -> TrackSnapshot:
    est = track.estimate
    P = np.array(est.P, dtype=float)
    P.flags.writeable = False
    return TrackSnapshot(
        id=track.id,
        kind="extended",
        status="confirmed" if track.confirmed else "tentative",
        time=t,
        position=(float(est.x[0]), float(est.x[1])),
        velocity=(float(est.x[2]), float(est.x[3])),
        covariance=P,
        score=float(track.score),
        hits=int(track.hits),
        created=float(track.created),
        updated=float(track.updated),
        detection_ids=track.detection_ids,
        extent=extent_ellipse(est.X),
    )
