"""Track initiation: velocity-gated two-point initiation (Blackman and Popoli, 1999, ch. 6).

A detection that no track explains opens a *candidate*: a position ``z_c`` with covariance
``R_c`` at time ``t_c`` and the score of a one-detection track, ``L₁ = ln(λ_nt / λ_fa)``.
At each later scan, within ``candidate_max_age`` seconds, the candidate is paired with the free
detections ``z_j`` (covariance ``R_j``) whose displacement ``d = z_j − z_c`` a target of speed
at most ``v_max`` could make in ``Δt = t − t_c``:

    e = d − d · min(1, v_max Δt / |d|),      eᵀ (R_c + R_j)⁻¹ e ≤ γ.

A k-d tree over the free detections, queried with radius
``v_max Δt + sqrt(γ (λ_max(R_c) + max_j λ_max(R_j)))`` per candidate, finds every such pair
without forming all pairs of a scan.

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
likeliest) start tracks: the number of new tracks per scan is bounded by that many times the
number of candidates, whatever the clutter. Tracks started from one candidate are rival
hypotheses; the tracker keeps the likeliest once each has met a scan.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from trackers.association.gating import gate, inverse_2x2, log_gaussian_2d, max_eigenvalue_2x2
from trackers.association.gnn import gnn_assign
from trackers.rows import RowArrays, sort_within_groups

__all__ = [
    "Candidates",
    "Pairs",
    "ThirdDetections",
    "TwoPointTracks",
    "cv_predict",
    "pair_candidates",
    "position_update",
    "third_detections",
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
class Pairs(RowArrays):
    """Two-detection hypotheses waiting for a third: the state ``x (k, 4)`` =
    ``[x, y, vx, vy]`` with covariance ``P (k, 4, 4)`` at ``time (k,)``, the score
    ``score (k,)``, the candidate's ``origin (k,)`` and time ``created (k,)``, and the
    ``detection_ids (k,)`` of the pair's second detection."""

    x: np.ndarray
    P: np.ndarray
    time: np.ndarray
    score: np.ndarray
    origin: np.ndarray
    created: np.ndarray
    detection_ids: np.ndarray

    @staticmethod
    def empty() -> Pairs:
        return Pairs(
            x=np.zeros((0, 4)),
            P=np.zeros((0, 4, 4)),
            time=np.zeros(0),
            score=np.zeros(0),
            origin=np.zeros(0, dtype=np.int64),
            created=np.zeros(0),
            detection_ids=np.zeros(0, dtype=object),
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


@dataclass(frozen=True, eq=False)
class ThirdDetections:
    """Pairs that met a third detection: ``pair`` and ``detection`` indices, the updated
    state ``x (k, 4)``, ``P (k, 4, 4)`` and score ``score (k,)``."""

    pair: np.ndarray
    detection: np.ndarray
    x: np.ndarray
    P: np.ndarray
    score: np.ndarray

    @property
    def size(self) -> int:
        return int(self.pair.size)


def cv_predict(
    x: np.ndarray, P: np.ndarray, dt: np.ndarray, q: float
) -> tuple[np.ndarray, np.ndarray]:
    """Nearly constant velocity prediction of ``[x, y, vx, vy]`` over per-row intervals Δt:

    x⁻ = F x,  F = [[I, Δt I], [0, I]],
    P⁻_pp = P_pp + Δt (P_pv + P_vp) + Δt² P_vv + q Δt³/3 I,
    P⁻_pv = P_pv + Δt P_vv + q Δt²/2 I,   P⁻_vv = P_vv + q Δt I.
    """
    dt = np.asarray(dt, dtype=float)
    t1 = dt[:, None, None]
    I2 = np.eye(2)
    x_new = x.copy()
    x_new[:, :2] += dt[:, None] * x[:, 2:]
    Ppp, Ppv, Pvp, Pvv = P[:, :2, :2], P[:, :2, 2:], P[:, 2:, :2], P[:, 2:, 2:]
    P_new = np.empty_like(P)
    P_new[:, :2, :2] = Ppp + t1 * (Ppv + Pvp) + t1**2 * Pvv + (q * t1**3 / 3.0) * I2
    P_new[:, :2, 2:] = Ppv + t1 * Pvv + (q * t1**2 / 2.0) * I2
    P_new[:, 2:, :2] = P_new[:, :2, 2:].transpose(0, 2, 1)
    P_new[:, 2:, 2:] = Pvv + (q * t1) * I2
    return x_new, P_new


def position_update(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update of ``[x, y, vx, vy]`` with a position ``z`` (covariance R):
    ``S = P_pp + R``, ``K = P Hᵀ S⁻¹``, ``x = x⁻ + K (z − x⁻_p)``, ``P = P⁻ − K S Kᵀ``."""
    S = P[:, :2, :2] + R
    S_inv, _ = inverse_2x2(S)
    K = np.einsum("kij,kjl->kil", P[:, :, :2], S_inv)
    x_new = x + np.einsum("kij,kj->ki", K, z - x[:, :2])
    P_new = P - np.einsum("kij,kjl,kml->kim", K, S, K)
    return x_new, 0.5 * (P_new + P_new.transpose(0, 2, 1))


def third_detections(
    pairs: Pairs,
    z: np.ndarray,
    R: np.ndarray,
    free: np.ndarray,
    t: float,
    *,
    q: float,
    gamma: float,
    pd: float,
    clutter_density: float,
) -> ThirdDetections:
    """Test every pair against this scan's free detections: predicted by :func:`cv_predict`,
    gated by chi-square, assigned one-to-one by GNN on the score gain
    ``ln(P_D g / λ_fa) − ln(1 − P_D)``, and updated by :func:`position_update`. The score of
    an extended pair is ``L + ln(P_D g / λ_fa)``."""
    empty_i = np.zeros(0, dtype=np.intp)
    none = ThirdDetections(empty_i, empty_i, np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0))
    free_idx = np.flatnonzero(free)
    if len(pairs) == 0 or free_idx.size == 0:
        return none
    x_pred, P_pred = cv_predict(pairs.x, pairs.P, t - pairs.time, q)
    zf, Rf = z[free_idx], R[free_idx]
    gated = gate(x_pred[:, :2], P_pred[:, :2, :2], zf, Rf, gamma)
    if gated.size == 0:
        return none
    pi, fj = gated.track, gated.detection
    _, loglik = log_gaussian_2d(zf[fj] - x_pred[pi, :2], P_pred[pi, :2, :2] + Rf[fj])
    hit = math.log(pd) + loglik - math.log(clutter_density)
    miss = math.log(max(1.0 - pd, 1e-12))
    sel = gnn_assign(pi, fj, hit - miss, len(pairs), free_idx.size)
    pi, fj = pi[sel], fj[sel]
    x, P = position_update(x_pred[pi], P_pred[pi], zf[fj], Rf[fj])
    return ThirdDetections(
        pair=pi, detection=free_idx[fj], x=x, P=P, score=pairs.score[pi] + hit[sel]
    )


def _cv_component(
    d: np.ndarray, R_c: np.ndarray, R_j: np.ndarray, dt: np.ndarray, var_v: float, q: float
) -> tuple[np.ndarray, np.ndarray]:
    """Kalman posterior of ``[p − z_c, v]`` at the second detection.

    Prior at ``t_c``: ``p ~ N(z_c, R_c)``, ``v ~ N(0, σ² I)``; predicted over Δt by the nearly
    constant velocity model (PSD q):

        P_pp = R_c + a I,  P_pv = b I,  P_vv = c I,
        a = σ² Δt² + q Δt³/3,  b = σ² Δt + q Δt²/2,  c = σ² + q Δt,

    then updated with ``d = z_j − z_c`` (covariance ``R_j``). With ``S = P_pp + R_j`` and
    ``A = S⁻¹`` the update reduces to

        x_p = d − R_j A d,  x_v = b A d,
        P_pp = R_j − R_j A R_j,  P_pv = b R_j A,  P_vv = c I − b² A.

    Returns the mean ``(k, 4)`` and covariance ``(k, 4, 4)``.
    """
    a = (var_v * dt**2 + q * dt**3 / 3.0)[:, None, None]
    b = (var_v * dt + q * dt**2 / 2.0)[:, None, None]
    c = (var_v + q * dt)[:, None, None]
    I2 = np.eye(2)
    A, _ = inverse_2x2(R_c + R_j + a * I2)
    Ad = _matvec_2x2(A, d)
    RA = _matmul_2x2(R_j, A)
    x = np.empty((d.shape[0], 4))
    x[:, :2] = d - _matvec_2x2(R_j, Ad)
    x[:, 2:] = b[:, :, 0] * Ad
    P = np.empty((d.shape[0], 4, 4))
    P[:, :2, :2] = R_j - _matmul_2x2(RA, R_j)
    P[:, :2, 2:] = b * RA
    P[:, 2:, :2] = b * RA.transpose(0, 2, 1)
    P[:, 2:, 2:] = c * I2 - b**2 * A
    return x, 0.5 * (P + P.transpose(0, 2, 1))


def _matmul_2x2(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A B`` for stacks of 2x2 matrices, entry by entry (numpy's matmul is slow on them)."""
    C = np.empty_like(A)
    C[:, 0, 0] = A[:, 0, 0] * B[:, 0, 0] + A[:, 0, 1] * B[:, 1, 0]
    C[:, 0, 1] = A[:, 0, 0] * B[:, 0, 1] + A[:, 0, 1] * B[:, 1, 1]
    C[:, 1, 0] = A[:, 1, 0] * B[:, 0, 0] + A[:, 1, 1] * B[:, 1, 0]
    C[:, 1, 1] = A[:, 1, 0] * B[:, 0, 1] + A[:, 1, 1] * B[:, 1, 1]
    return C


def _matvec_2x2(A: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``A v`` for stacks of 2x2 matrices and 2-vectors."""
    return np.stack(
        [A[:, 0, 0] * v[:, 0] + A[:, 0, 1] * v[:, 1], A[:, 1, 0] * v[:, 0] + A[:, 1, 1] * v[:, 1]],
        axis=1,
    )


def _component_logliks(
    d: np.ndarray,
    R_sum: np.ndarray,
    dt: np.ndarray,
    *,
    max_speed: float,
    velocity_std: float,
    slow_fraction: float,
    q: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``ln(w N(d; 0, S_s))`` and ``ln((1 − w) g_f)`` of each pair (module docstring)."""
    S_s = R_sum + (velocity_std**2 * dt**2 + q * dt**3 / 3.0)[:, None, None] * np.eye(2)
    _, ll_s = log_gaussian_2d(d, S_s)
    det = R_sum[:, 0, 0] * R_sum[:, 1, 1] - R_sum[:, 0, 1] * R_sum[:, 1, 0]
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
        R_c + R_j,
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
    """The moment-matched mixture of the two components' posteriors, relative to ``z_c``,
    given their log weights ``a_s`` and ``a_f``; and ``ln g₂``."""
    loglik = _log_add(a_s, a_f)
    x_s, P_s = _cv_component(d, R_c, R_j, dt, velocity_std**2, q)
    x_f, P_f = _cv_component(d, R_c, R_j, dt, 0.5 * max_speed**2, q)
    beta_s = np.exp(a_s - loglik)[:, None]
    beta_f = 1.0 - beta_s
    x_rel = beta_s * x_s + beta_f * x_f
    ds, df = x_s - x_rel, x_f - x_rel
    P = beta_s[:, :, None] * (P_s + ds[:, :, None] * ds[:, None, :]) + beta_f[:, :, None] * (
        P_f + df[:, :, None] * df[:, None, :]
    )
    return x_rel, P, loglik


def _group_max(group: np.ndarray, value: np.ndarray) -> np.ndarray:
    """For each element, the largest ``value`` among the elements of its ``group``."""
    top = np.full(int(group.max()) + 1, -np.inf)
    np.maximum.at(top, group, value)
    return top[group]


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
    min_score: float = -math.inf,
) -> TwoPointTracks:
    """Every (candidate, free detection) pair a target no faster than ``max_speed`` could
    make, at most ``max_pairs`` per candidate (the highest scores), with the two-point state
    and the score ``L = L_c + ln(P_D g₂ / λ_fa)``; pairs with ``L ≤ min_score`` (the deletion
    threshold of the sequential test) are left out. Detections are indexed into ``z``."""
    empty_i = np.zeros(0, dtype=np.intp)
    none = TwoPointTracks(empty_i, empty_i, np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0))
    dt_all = t - candidates.time
    offered = np.flatnonzero(dt_all >= MIN_PAIR_INTERVAL)
    free_idx = np.flatnonzero(free)
    if offered.size == 0 or free_idx.size == 0:
        return none
    zf, Rf = z[free_idx], R[free_idx]
    noise = float(max_eigenvalue_2x2(Rf).max())
    zc, Rc = candidates.z[offered], candidates.R[offered]
    radius = max_speed * dt_all[offered] + np.sqrt(gamma * (max_eigenvalue_2x2(Rc) + noise))
    hits = cKDTree(zf).query_ball_point(zc, radius, return_sorted=False)
    counts = np.fromiter(map(len, hits), dtype=np.intp, count=len(hits))
    if counts.sum() == 0:
        return none
    ci = np.repeat(offered, counts)
    fj = np.fromiter(itertools.chain.from_iterable(hits), dtype=np.intp, count=int(counts.sum()))
    dt = dt_all[ci]
    d = zf[fj] - candidates.z[ci]
    R_sum = candidates.R[ci] + Rf[fj]
    dist = np.sqrt(np.einsum("ki,ki->k", d, d))
    reach = max_speed * dt
    e = d * (1.0 - np.minimum(1.0, reach / np.maximum(dist, 1e-300)))[:, None]
    S_inv, _ = inverse_2x2(R_sum)
    keep = np.einsum("ki,kij,kj->k", e, S_inv, e) <= gamma
    if not keep.any():
        return none
    ci, fj, dt, d, R_sum = ci[keep], fj[keep], dt[keep], d[keep], R_sum[keep]
    a_s, a_f = _component_logliks(
        d,
        R_sum,
        dt,
        max_speed=max_speed,
        velocity_std=velocity_std,
        slow_fraction=slow_fraction,
        q=q,
    )
    score = candidates.score[ci] + math.log(pd) + _log_add(a_s, a_f) - math.log(clutter_density)
    # Rival pairs of one candidate, or of one detection, are pruned when far less likely than
    # the best of them; then the ``max_pairs`` best of each candidate are kept.
    good = (
        (score > min_score)
        & (score >= _group_max(ci, score) - PAIR_PRUNE_LOG_RATIO)
        & (score >= _group_max(fj, score) - PAIR_PRUNE_LOG_RATIO)
    )
    good = np.flatnonzero(good)
    by_candidate, rank = sort_within_groups(ci[good], score[good])
    order = good[by_candidate[rank < max_pairs]]
    ci, fj, score = ci[order], fj[order], score[order]
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
    return TwoPointTracks(candidate=ci, detection=free_idx[fj], x=x, P=P, score=score)
