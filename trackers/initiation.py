"""Track initiation: velocity-gated two-point initiation (Blackman and Popoli, 1999, ch. 6).

A detection that no track explains opens a *candidate*: a position ``z_c`` with covariance
``R_c`` at time ``t_c`` and the score of a one-detection track, ``L₁ = ln(λ_nt / λ_fa)``.
At each later scan, within ``candidate_max_age`` seconds, the candidate is paired with the free
detections ``z_j`` (covariance ``R_j``) whose displacement ``d = z_j − z_c`` a target of speed
at most ``v_max`` could make in ``Δt = t − t_c``:

    e = d − d · min(1, v_max Δt / |d|),      eᵀ (R_c + R_j)⁻¹ e ≤ γ.

A search around each candidate with radius ``v_max Δt + sqrt(γ (λ_max(R_c) + max_j
λ_max(R_j)))`` (:func:`trackers.association.spatial.pairs_within`, a k-d tree over the free
detections in large scenes) finds every such pair without forming all pairs of a scan.

The velocity prior is a two-component mixture: with weight ``w`` a *slow* target,
``v ~ N(0, σ_v² I)``; with weight ``1 − w`` a *fast* one, ``v`` uniform over the disc
``|v| ≤ v_max``. The likelihood of the second detection is

    g₂ = w · N(d; 0, S_s) + (1 − w) · g_f,
    S_s = R_c + R_j + (σ_v² Δt² + q Δt³/3) I,
    g_f = 1 / (π (v_max Δt)² + 2π |R_c + R_j|^½)

(``g_f`` is the uniform disc density, smoothed by the noise so that it stays finite as
``Δt → 0``), and the pair's score is the candidate's plus the hit increment
``ln(P_D g₂ / λ_fa)``. The state of the two-point track is the moment-matched mixture of the
two components' Kalman posteriors: each starts at ``[z_c, 0]`` with covariance
``diag(R_c, σ² I)`` (``σ² = σ_v²`` for the slow component, ``v_max²/2`` for the fast one, a
Gaussian as wide as the disc's second moment), is predicted by the nearly constant velocity
model over ``Δt`` and updated with ``z_j``; the component weights are proportional to
``w N(d; 0, S_s)`` and ``(1 − w) g_f``. For ``v_max Δt`` large against the noise the fast
component is the classical two-point difference, ``v = d / Δt`` with covariance
``(R_c + R_j) / Δt²``.

A candidate offered a scan continues as its *missed* branch, ``L ← L + ln(1 − P_D)``, whether
or not it paired; it is dropped when ``L ≤ T_d`` or when older than ``candidate_max_age``.
A pair less likely than 1/100 of the best pair of its candidate or of its detection is pruned
(``PAIR_PRUNE_LOG_RATIO``), and at most ``max_pairs_per_candidate`` pairs a scan (the
likeliest) start tentative tracks, each holding its two detections, which meet their third
detection in the tracker's IMM update like any track: the number of new tracks per scan is
bounded by that many times the number of candidates, whatever the clutter. Tracks started
from one candidate are rival hypotheses; the tracker keeps the likeliest once each has met a scan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trackers.association.gating import max_eigenvalue_2x2
from trackers.association.spatial import pairs_within
from trackers.rows import RowArrays, sort_within_groups

__all__ = [
    "Candidates",
    "TwoPointTracks",
    "pair_candidates",
    "search_radius",
    "two_point_estimate",
]

#: Candidates and detections less than this far apart in time (s) are not paired: they say
#: nothing about velocity (two sensors' scans at the same instant).
MIN_PAIR_INTERVAL = 1e-3

#: A pair whose likelihood is below 1/100 of the best pair of its candidate, or of its
#: detection, starts no track: in a field of slow targets a candidate pairs with every
#: neighbour as a fast mover, and those rivals would take the neighbours' detections from
#: the right tracks. Pairs of equal likelihood (the members of a fast formation) all stay.
PAIR_PRUNE_LOG_RATIO = math.log(100.0)


@dataclass(frozen=True, eq=False)
class Candidates(RowArrays):
    """Detections waiting for a second one: ``z (n, 2)``, ``R (n, 2, 2)``, ``time (n,)``,
    ``score (n,)`` (the LLR of a track holding this one detection, misses included),
    ``detection_ids (n,)`` (objects) and ``origin (n,)``, a number unique to each candidate
    that the tracks it starts inherit."""

    z: np.ndarray
    R: np.ndarray
    time: np.ndarray
    score: np.ndarray
    detection_ids: np.ndarray
    origin: np.ndarray

    @staticmethod
    def empty() -> Candidates:
        return Candidates(
            z=np.zeros((0, 2)),
            R=np.zeros((0, 2, 2)),
            time=np.zeros(0),
            score=np.zeros(0),
            detection_ids=np.zeros(0, dtype=object),
            origin=np.zeros(0, dtype=np.int64),
        )


@dataclass(frozen=True, eq=False)
class TwoPointTracks:
    """The pairs that start tracks: ``candidate`` and ``detection`` indices, the state
    ``x (k, 4)`` = ``[x, y, vx, vy]`` at the detection's time with covariance ``P (k, 4, 4)``,
    and the score ``score (k,)`` of the two-detection track."""

    candidate: np.ndarray
    detection: np.ndarray
    x: np.ndarray
    P: np.ndarray
    score: np.ndarray

    @property
    def size(self) -> int:
        return int(self.candidate.size)


def _entries(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The entries ``(r₀₀, r₀₁, r₁₁)`` of symmetric 2x2 matrices ``R (k, 2, 2)``."""
    return R[:, 0, 0], R[:, 0, 1], R[:, 1, 1]


def _component_logliks(
    d: np.ndarray,
    s: tuple[np.ndarray, np.ndarray, np.ndarray],
    dt: np.ndarray,
    *,
    max_speed: float,
    velocity_std: float,
    slow_fraction: float,
    q: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``ln(w N(d; 0, S_s))`` and ``ln((1 − w) g_f)`` of each pair (module docstring), with
    ``s`` the entries of ``R_c + R_j``:

        S_s = R_c + R_j + α I,  α = σ_v² Δt² + q Δt³/3,
        ln N(d; 0, S_s) = −½ dᵀ S_s⁻¹ d − ln 2π − ½ ln |S_s|,
        g_f = 1 / (π (v_max Δt)² + 2π |R_c + R_j|^½).
    """
    s00, s01, s11 = s
    alpha = velocity_std**2 * dt**2 + q * dt**3 / 3.0
    t00, t11 = s00 + alpha, s11 + alpha
    det_s = t00 * t11 - s01 * s01
    d0, d1 = d[:, 0], d[:, 1]
    m2 = (t11 * d0 * d0 - 2.0 * s01 * d0 * d1 + t00 * d1 * d1) / det_s
    ll_s = -0.5 * m2 - math.log(2.0 * math.pi) - 0.5 * np.log(det_s)
    det = s00 * s11 - s01 * s01
    ll_f = -np.log(math.pi * (max_speed * dt) ** 2 + 2.0 * math.pi * np.sqrt(det))
    return math.log(slow_fraction) + ll_s, math.log1p(-slow_fraction) + ll_f


def _log_add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """ln(eᵃ + eᵇ) without overflow."""
    top = np.maximum(a, b)
    return top + np.log(np.exp(a - top) + np.exp(b - top))


def two_point_estimate(
    z_c: np.ndarray,
    R_c: np.ndarray,
    z_j: np.ndarray,
    R_j: np.ndarray,
    dt: np.ndarray,
    *,
    max_speed: float,
    velocity_std: float,
    slow_fraction: float,
    q: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """State and likelihood of the tracks started by pairs ``(z_c, z_j)`` ``Δt`` apart.

    With the mixture prior of the module docstring, returns ``x (k, 4)`` and ``P (k, 4, 4)``
    over ``[x, y, vx, vy]`` at the second detection (the moment-matched mixture
    ``x = Σ β_m x_m``, ``P = Σ β_m (P_m + (x_m − x)(x_m − x)ᵀ)``) and ``ln g₂ (k,)``,

        g₂ = w N(d; 0, S_s) + (1 − w) / (π (v_max Δt)² + 2π |R_c + R_j|^½).
    """
    z_c = np.asarray(z_c, dtype=float).reshape(-1, 2)
    z_j = np.asarray(z_j, dtype=float).reshape(-1, 2)
    R_c = np.asarray(R_c, dtype=float).reshape(-1, 2, 2)
    R_j = np.asarray(R_j, dtype=float).reshape(-1, 2, 2)
    dt = np.broadcast_to(np.asarray(dt, dtype=float), (z_c.shape[0],))
    d = z_j - z_c
    a_s, a_f = _component_logliks(
        d,
        _entries(R_c + R_j),
        dt,
        max_speed=max_speed,
        velocity_std=velocity_std,
        slow_fraction=slow_fraction,
        q=q,
    )
    x, P, loglik = _mixture_state(
        d, R_c, R_j, dt, a_s, a_f, max_speed=max_speed, velocity_std=velocity_std, q=q
    )
    x[:, :2] += z_c
    return x, P, loglik


def _mixture_state(
    d: np.ndarray,
    R_c: np.ndarray,
    R_j: np.ndarray,
    dt: np.ndarray,
    a_s: np.ndarray,
    a_f: np.ndarray,
    *,
    max_speed: float,
    velocity_std: float,
    q: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The moment-matched mixture of the two components' Kalman posteriors of
    ``[p − z_c, v]`` at the second detection, given their log weights ``a_s`` and ``a_f``;
    and ``ln g₂ = ln(e^{a_s} + e^{a_f})``.

    Component m has the prior ``p ~ N(z_c, R_c)``, ``v ~ N(0, σ_m² I)`` (σ_s = σ_v,
    σ_f² = v_max²/2), predicted over Δt by the nearly constant velocity model (PSD q):

        P_pp = R_c + a I,  P_pv = b I,  P_vv = c I,
        a = σ² Δt² + q Δt³/3,  b = σ² Δt + q Δt²/2,  c = σ² + q Δt,

    and updated with ``d = z_j − z_c`` (covariance ``R_j``). With ``A = (P_pp + R_j)⁻¹``:

        x_p = d − R_j A d,  x_v = b A d,
        P_pp = R_j − R_j A R_j,  P_pv = b R_j A,  P_vv = c I − b² A.

    The mixture is ``x = β_s x_s + β_f x_f`` and
    ``P = β_s P_s + β_f P_f + β_s β_f δ δᵀ`` with ``δ = x_s − x_f``. Both components are
    computed at once, entry by entry, on ``(2, k)`` arrays.
    """
    loglik = _log_add(a_s, a_f)
    beta = np.exp(np.stack([a_s, a_f]) - loglik)
    var = np.array([[velocity_std**2], [0.5 * max_speed**2]])
    a = var * dt**2 + q * dt**3 / 3.0
    b = var * dt + q * dt**2 / 2.0
    c = var + q * dt
    c00, c01, c11 = _entries(R_c)
    j00, j01, j11 = _entries(R_j)
    s00, s11 = c00 + j00 + a, c11 + j11 + a
    s01 = c01 + j01
    det = s00 * s11 - s01 * s01
    A00, A01, A11 = s11 / det, -s01 / det, s00 / det
    d0, d1 = d[:, 0], d[:, 1]
    Ad0, Ad1 = A00 * d0 + A01 * d1, A01 * d0 + A11 * d1
    RA00, RA01 = j00 * A00 + j01 * A01, j00 * A01 + j01 * A11
    RA10, RA11 = j01 * A00 + j11 * A01, j01 * A01 + j11 * A11
    k = d.shape[0]
    X = np.empty((2, k, 4))
    X[:, :, 0] = d0 - (j00 * Ad0 + j01 * Ad1)
    X[:, :, 1] = d1 - (j01 * Ad0 + j11 * Ad1)
    X[:, :, 2] = b * Ad0
    X[:, :, 3] = b * Ad1
    P = np.empty((2, k, 4, 4))
    P[:, :, 0, 0] = j00 - (RA00 * j00 + RA01 * j01)
    P[:, :, 0, 1] = P[:, :, 1, 0] = j01 - (RA00 * j01 + RA01 * j11)
    P[:, :, 1, 1] = j11 - (RA10 * j01 + RA11 * j11)
    P[:, :, 0, 2] = P[:, :, 2, 0] = b * RA00
    P[:, :, 0, 3] = P[:, :, 3, 0] = b * RA01
    P[:, :, 1, 2] = P[:, :, 2, 1] = b * RA10
    P[:, :, 1, 3] = P[:, :, 3, 1] = b * RA11
    b2 = b * b
    P[:, :, 2, 2] = c - b2 * A00
    P[:, :, 2, 3] = P[:, :, 3, 2] = -b2 * A01
    P[:, :, 3, 3] = c - b2 * A11
    x = beta[0][:, None] * X[0] + beta[1][:, None] * X[1]
    delta = X[0] - X[1]
    P_mix = (
        beta[0][:, None, None] * P[0]
        + beta[1][:, None, None] * P[1]
        + (beta[0] * beta[1])[:, None, None] * (delta[:, :, None] * delta[:, None, :])
    )
    return x, P_mix, loglik


def search_radius(
    dt: np.ndarray,
    base: np.ndarray,
    noise: np.ndarray,
    floor: float,
    *,
    max_speed: float,
    velocity_std: float,
    slow_fraction: float,
    q: float,
    gamma: float,
) -> np.ndarray:
    """How far from each candidate a detection can make a pair that scores above ``floor``
    (−1 where none can), given ``base = L_c + ln(P_D/λ_fa)`` and ``noise``, an upper bound of
    ``λ_max(R_c) + λ_max(R_j)``; a bound, so no pair that :func:`pair_candidates` would keep
    lies beyond it.

    A pair scores ``base + ln g₂`` with ``g₂ = w N(d; 0, S_s) + (1 − w) g_f`` and
    ``g_f ≤ ḡ_f = 1/(π (v_max Δt)²)``. Where the fast term alone can pass, ``(1 − w) ḡ_f >
    η₀ = e^{floor − base}``, the search covers the velocity gate, ``v_max Δt + √(γ noise)``.
    Otherwise the slow term must exceed ``η = η₀ − (1 − w) ḡ_f``; since ``|S_s| ≥ α²``
    (``α = σ_v² Δt² + q Δt³/3``) and ``|d|² ≤ λ_max(S_s) dᵀ S_s⁻¹ d``, that needs

        |d|² < (noise + α) · (−2 ln(2π α η / w)),

    and no detection qualifies when the logarithm is not negative. In dense clutter this
    shrinks the search from kilometres to the slow targets' reach: older candidates, whose
    score the misses have lowered, can no longer start a fast track."""
    reach = max_speed * dt
    fast = reach + np.sqrt(gamma * noise)
    g_fast = (1.0 - slow_fraction) / (math.pi * np.maximum(reach, 1e-9) ** 2)
    with np.errstate(over="ignore"):
        eta = np.exp(floor - base) - g_fast
    alpha = velocity_std**2 * dt**2 + q * dt**3 / 3.0
    with np.errstate(divide="ignore", invalid="ignore"):
        m2 = -2.0 * np.log(2.0 * math.pi * alpha * np.maximum(eta, 1e-300) / slow_fraction)
    slow = np.where(m2 > 0.0, np.sqrt((noise + alpha) * np.maximum(m2, 0.0)), -1.0)
    return np.where(eta > 0.0, np.minimum(slow, fast), fast)


def pair_candidates(
    candidates: Candidates,
    z: np.ndarray,
    R: np.ndarray,
    free: np.ndarray,
    t: float,
    *,
    max_speed: float,
    velocity_std: float,
    slow_fraction: float,
    q: float,
    gamma: float,
    max_pairs: int,
    pd: float,
    clutter_density: float,
    min_score: float | np.ndarray = -math.inf,
) -> TwoPointTracks:
    """Every (candidate, free detection) pair a target no faster than ``max_speed`` could
    make, at most ``max_pairs`` per candidate (the highest scores), with the two-point state
    and the score ``L = L_c + ln(P_D g₂ / λ_fa)``; pairs with ``L ≤ min_score`` (a number,
    such as the deletion threshold of the sequential test, or one per detection of ``z``)
    are left out. Detections are indexed into ``z``.

    The velocity gate of the module docstring is ``ρ² dᵀ (R_c + R_j)⁻¹ d ≤ γ`` with
    ``ρ = max(0, 1 − v_max Δt / |d|)``: the part of ``d`` beyond the reach of ``v_max``."""
    empty_i = np.zeros(0, dtype=np.intp)
    none = TwoPointTracks(empty_i, empty_i, np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0))
    dt_all = t - candidates.time
    offered = np.flatnonzero(dt_all >= MIN_PAIR_INTERVAL)
    free_idx = np.flatnonzero(free)
    if offered.size == 0 or free_idx.size == 0:
        return none
    zf, Rf = z[free_idx], R[free_idx]
    noise = float(max_eigenvalue_2x2(Rf).max())
    floor_min = float(min_score) if np.ndim(min_score) == 0 else float(np.min(min_score[free_idx]))
    lam_c = max_eigenvalue_2x2(candidates.R[offered])
    radius = search_radius(
        dt_all[offered],
        candidates.score[offered] + (math.log(pd) - math.log(clutter_density)),
        lam_c + noise,
        floor_min,
        max_speed=max_speed,
        velocity_std=velocity_std,
        slow_fraction=slow_fraction,
        q=q,
        gamma=gamma,
    )
    searched = np.flatnonzero(radius >= 0.0)
    offered = offered[searched]
    if offered.size == 0:
        return none
    i, fj = pairs_within(candidates.z[offered], radius[searched], zf)
    n = i.size
    if n == 0:
        return none
    ci = offered[i]  # grouped by candidate, in candidate order
    dt = dt_all[ci]
    d = zf[fj] - candidates.z[ci]
    R_sum = candidates.R[ci] + Rf[fj]
    s = _entries(R_sum)
    d0, d1 = d[:, 0], d[:, 1]
    rho = np.maximum(0.0, 1.0 - max_speed * dt / np.maximum(np.hypot(d0, d1), 1e-300))
    s00, s01, s11 = s
    m2 = (s11 * d0 * d0 - 2.0 * s01 * d0 * d1 + s00 * d1 * d1) / (s00 * s11 - s01 * s01)
    a_s, a_f = _component_logliks(
        d,
        s,
        dt,
        max_speed=max_speed,
        velocity_std=velocity_std,
        slow_fraction=slow_fraction,
        q=q,
    )
    score = candidates.score[ci] + (math.log(pd) - math.log(clutter_density)) + _log_add(a_s, a_f)
    score[rho * rho * m2 > gamma] = -np.inf
    # Rival pairs of one candidate, or of one detection, are pruned when far less likely than
    # the best of them; then the ``max_pairs`` best of each candidate are kept.
    new_group = np.empty(n, dtype=bool)
    new_group[0] = True
    np.not_equal(ci[1:], ci[:-1], out=new_group[1:])
    group = np.cumsum(new_group) - 1
    best_c = np.maximum.reduceat(score, np.flatnonzero(new_group))[group]
    best_d = np.full(free_idx.size, -np.inf)
    np.maximum.at(best_d, fj, score)
    floor = min_score if np.ndim(min_score) == 0 else np.asarray(min_score)[free_idx][fj]
    good = np.flatnonzero(
        (score > floor)
        & (score >= best_c - PAIR_PRUNE_LOG_RATIO)
        & (score >= best_d[fj] - PAIR_PRUNE_LOG_RATIO)
    )
    if good.size == 0:
        return none
    by_candidate, rank = sort_within_groups(ci[good], score[good])
    order = good[by_candidate[rank < max_pairs]]
    ci, fj = ci[order], fj[order]
    x, P, _ = _mixture_state(
        d[order],
        candidates.R[ci],
        Rf[fj],
        dt[order],
        a_s[order],
        a_f[order],
        max_speed=max_speed,
        velocity_std=velocity_std,
        q=q,
    )
    x[:, :2] += candidates.z[ci]
    return TwoPointTracks(candidate=ci, detection=free_idx[fj], x=x, P=P, score=score[order])
