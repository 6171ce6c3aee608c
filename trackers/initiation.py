"""Track initiation: velocity-gated two-point initiation (Blackman and Popoli, 1999, ch. 6).

A detection that no track explains opens a *candidate*: a position ``z_c`` with covariance
``R_c`` at time ``t_c`` and the score of a one-detection track,
``L₁ = max(ln(λ_nt / λ_fa), ln κ)`` (:func:`trackers.scoring.initial_score`).
At each later scan, within ``candidate_max_age`` seconds, the candidate is paired with the free
detections ``z_j`` (covariance ``R_j``) whose displacement ``d = z_j − z_c`` a target of speed
at most ``v_max`` could make in ``Δt = t − t_c``:

    e = d − d · min(1, v_max Δt / |d|),      eᵀ (R_c + R_j)⁻¹ e ≤ γ.

In large problems (more than ``BRUTE_FORCE_CELLS`` candidate-detection pairs) a search around
each candidate with radius ``v_max Δt + sqrt(γ (λ_max(R_c) + max_j λ_max(R_j)))``, shrunk by
the score bound of :func:`search_radius` (:func:`trackers.association.spatial.pairs_within`,
a k-d tree over the free detections in large scenes) finds every such pair without forming
all pairs of a scan; in small ones every pair is scored, which costs fewer operations, and
the gate and the score floor reject exactly the pairs the search would not have found.

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

Targets move in groups. A candidate that opened near a fast confirmed track carries that
track's velocity ``v_g`` (:attr:`Candidates.group_velocity`), and its prior has a third
component, weight ``w_g``: the target moves with the track, ``v ~ N(v_g, σ_g² I)``, so

    g₂ = (1 − w_g) (w N(d; 0, S_s) + (1 − w) g_f) + w_g N(d − v_g Δt; 0, S_g),
    S_g = R_c + R_j + (σ_g² Δt² + q Δt³/3) I,

and its Kalman posterior (the prior ``[z_c, v_g]``) joins the mixture. A formation member's
own pair then outweighs the pairs that join it to a neighbour's detection, which the uniform
fast component alone cannot tell apart, and starts with the group's velocity.

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
from scipy.spatial import cKDTree

from trackers.association.gating import max_eigenvalue_2x2
from trackers.association.spatial import BRUTE_FORCE_CELLS, pairs_within
from trackers.rows import RowArrays, sort_within_groups

__all__ = [
    "Candidates",
    "TwoPointTracks",
    "next_hit_allowance",
    "pair_candidates",
    "search_radius",
    "two_point_estimate",
]

#: A candidate whose reach holds fewer free detections than this fraction of what the clutter
#: density predicts may start pairs below the deletion threshold (:func:`next_hit_allowance`).
SPARSE_FRACTION = 0.2

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
    ``detection_ids (n,)`` (objects), ``origin (n,)``, a number unique to each candidate
    that the tracks it starts inherit, ``group_velocity (n, 2)``, the velocity of the
    fast confirmed track nearest to it when it opened (NaN: none within reach), and
    ``offered (n,)``, the scans that have looked at it since (0: it is at its first), and
    ``serial (n,)``, the tracker's serial number of its detection (−1: unknown), what the
    clutter map counted it under."""

    z: np.ndarray
    R: np.ndarray
    time: np.ndarray
    score: np.ndarray
    detection_ids: np.ndarray
    origin: np.ndarray
    group_velocity: np.ndarray
    offered: np.ndarray
    serial: np.ndarray

    @staticmethod
    def empty() -> Candidates:
        return Candidates(
            z=np.zeros((0, 2)),
            R=np.zeros((0, 2, 2)),
            time=np.zeros(0),
            score=np.zeros(0),
            detection_ids=np.zeros(0, dtype=object),
            origin=np.zeros(0, dtype=np.int64),
            group_velocity=np.zeros((0, 2)),
            offered=np.zeros(0, dtype=np.int64),
            serial=np.zeros(0, dtype=np.int64),
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


def _no_pairs() -> TwoPointTracks:
    empty = np.zeros(0, dtype=np.intp)
    return TwoPointTracks(empty, empty, np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0))


#: Rows of the tables of pairs (one column a pair): the displacement ``d = z_j − z_c``, the
#: entries of ``R_c + R_j`` and of ``R_j``, the interval ``Δt``, the candidate's group
#: velocity ``v_g`` (NaN: none); then, filled by :func:`_score_pairs`, ``ln(w_s N(d; 0, S_s))``,
#: ``ln(w_f g_f)``, ``ln g₂``, the score and ``ln(w_g N(d − v_g Δt; 0, S_g))``.
_D0, _D1, _S00, _S01, _S11, _J00, _J01, _J11, _DT, _LS, _LF, _LL, _SCORE = range(13)
_G0, _G1, _LG = 13, 14, 15
_ROWS = 16

#: Rows of the table of the mixture in :func:`_mixture_state`: 0-3 the state, 4-13 the
#: entries P00, P01, P11, P02, P03, P12, P13, P22, P33, P23; the row of each entry of ``P``
#: (row-major, the lower triangle from the upper one)...
_P_ROWS = np.array([4, 5, 7, 8, 5, 6, 9, 10, 7, 9, 11, 13, 8, 10, 13, 12])
#: ... and the two state entries whose product is the spread term of rows 4-13.
_SPREAD_I = np.array([0, 0, 1, 0, 0, 1, 1, 2, 3, 2])
_SPREAD_J = np.array([0, 1, 1, 2, 3, 2, 3, 2, 3, 3])

# Constants as 0-d arrays: an operation with one costs less than with a Python float.
_ZERO, _HALF, _ONE, _TWO, _THREE = (np.array(v) for v in (0.0, 0.5, 1.0, 2.0, 3.0))
_NEG_HALF, _TINY, _NEG_INF = np.array(-0.5), np.array(1e-300), np.array(-np.inf)
_PI, _TWO_PI, _LOG_2PI = np.array(math.pi), np.array(2.0 * math.pi), np.array(math.log(2 * math.pi))


def _pair_table(
    d: np.ndarray,
    R_c: np.ndarray,
    R_j: np.ndarray,
    dt: np.ndarray,
    v_g: np.ndarray | None = None,
) -> np.ndarray:
    """The table of k pairs (``_ROWS`` rows, one column a pair) with the rows of the inputs
    filled: the displacements ``d (k, 2)``, the entries of ``R_c + R_j`` and of ``R_j``
    (``(k, 2, 2)`` each), the intervals ``dt`` (``(k,)`` or a number) and the group
    velocities ``v_g (k, 2)`` (NaN: none; ``None``: rows left unset, for a scoring without
    the group component)."""
    T = np.empty((_ROWS, d.shape[0]))
    T[_D0 : _D1 + 1] = d.T
    R_sum = R_c + R_j
    T[_S00], T[_S01], T[_S11] = R_sum[:, 0, 0], R_sum[:, 0, 1], R_sum[:, 1, 1]
    T[_J00], T[_J01], T[_J11] = R_j[:, 0, 0], R_j[:, 0, 1], R_j[:, 1, 1]
    T[_DT] = dt
    if v_g is not None:
        T[_G0 : _G1 + 1] = v_g.T
    return T


def _score_pairs(
    T: np.ndarray,
    base: np.ndarray,
    *,
    max_speed: float,
    velocity_std: float,
    slow_fraction: float,
    q: float,
    gamma: float,
    group_fraction: float = 0.0,
    group_velocity_std: float = 1.0,
) -> None:
    """Fill the rows ``_LS``, ``_LF``, ``_LL``, ``_SCORE`` and ``_LG`` of the table ``T`` of
    pairs: ``a_s = ln(w_s N(d; 0, S_s))``, ``a_f = ln(w_f g_f)``, ``a_g = ln(w_g N(d − v_g Δt;
    0, S_g))`` (module docstring; ``a_g = −∞`` for a candidate without a group velocity),
    ``ln g₂ = ln(e^{a_s} + e^{a_f} + e^{a_g})`` and the score ``base + ln g₂``, with ``base =
    L_c + ln(P_D/λ_fa)`` (broadcasting to a row); the score is ``−∞`` where the pair fails
    the velocity gate (:func:`pair_candidates`). With ``s`` the entries of ``R_c + R_j``:

        S_s = R_c + R_j + α I,  α = σ_v² Δt² + q Δt³/3,
        ln N(d; 0, S_s) = −½ dᵀ S_s⁻¹ d − ln 2π − ½ ln |S_s|,
        g_f = 1 / (π (v_max Δt)² + 2π |R_c + R_j|^½),
        S_g = R_c + R_j + α_g I,  α_g = σ_g² Δt² + q Δt³/3,

    and the weights ``w_s = w (1 − w_g)``, ``w_f = (1 − w) (1 − w_g)``, ``w_g`` for a candidate
    with a group velocity, ``w``, ``1 − w`` and 0 for one without. With ``group_fraction`` 0
    the group rows are neither read nor written (a table without group velocities).
    """
    d0, d1, s00, s01, s11, dt = T[_D0], T[_D1], T[_S00], T[_S01], T[_S11], T[_DT]
    q = np.array(q)
    det = s00 * s11 - s01 * s01
    cross = _TWO * s01 * d0 * d1
    dt2 = dt * dt
    alpha = dt2 * (np.array(velocity_std**2) + q * dt / _THREE)
    t00, t11 = s00 + alpha, s11 + alpha
    det_s = t00 * t11 - s01 * s01
    m2 = (t11 * d0 * d0 - cross + t00 * d1 * d1) / det_s
    ll_s = _NEG_HALF * m2 - _LOG_2PI - _HALF * np.log(det_s)
    reach = np.array(max_speed) * dt
    ll_f = -np.log(_PI * reach**2 + _TWO_PI * np.sqrt(det))
    a_s = np.add(np.array(math.log(slow_fraction)), ll_s, out=T[_LS])
    a_f = np.add(np.array(math.log1p(-slow_fraction)), ll_f, out=T[_LF])
    if group_fraction <= 0.0:
        loglik = np.logaddexp(a_s, a_f, out=T[_LL])
    else:
        grouped = np.isfinite(T[_G0]) & np.isfinite(T[_G1])
        g0, g1 = np.where(grouped, T[_G0], 0.0), np.where(grouped, T[_G1], 0.0)
        e0, e1 = d0 - g0 * dt, d1 - g1 * dt
        alpha_g = np.array(group_velocity_std**2) * dt**2 + q * dt**3 / _THREE
        u00, u11 = s00 + alpha_g, s11 + alpha_g
        det_g = u00 * u11 - s01 * s01
        m2_g = (u11 * e0 * e0 - _TWO * s01 * e0 * e1 + u00 * e1 * e1) / det_g
        ll_g = _NEG_HALF * m2_g - _LOG_2PI - _HALF * np.log(det_g)
        rest = np.where(grouped, math.log1p(-group_fraction), 0.0)
        a_s += rest
        a_f += rest
        a_g = np.where(grouped, math.log(group_fraction) + ll_g, -np.inf)
        T[_LG] = a_g
        top = np.maximum(np.maximum(a_s, a_f), a_g)
        total = np.exp(a_s - top) + np.exp(a_f - top) + np.exp(a_g - top)
        loglik = np.add(top, np.log(total), out=T[_LL])
    score = np.add(base, loglik, out=T[_SCORE])
    rho = np.maximum(_ZERO, _ONE - reach / np.maximum(np.hypot(d0, d1), _TINY))
    m2 = (s11 * d0 * d0 - cross + s00 * d1 * d1) / det
    np.copyto(score, _NEG_INF, where=rho * rho * m2 > np.array(gamma))


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
    group_velocity: np.ndarray | None = None,
    group_fraction: float = 0.0,
    group_velocity_std: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """State and likelihood of the tracks started by pairs ``(z_c, z_j)`` ``Δt`` apart.

    With the mixture prior of the module docstring, returns ``x (k, 4)`` and ``P (k, 4, 4)``
    over ``[x, y, vx, vy]`` at the second detection (the moment-matched mixture
    ``x = Σ β_m x_m``, ``P = Σ β_m (P_m + (x_m − x)(x_m − x)ᵀ)``) and ``ln g₂ (k,)``,

        g₂ = w_s N(d; 0, S_s) + w_f / (π (v_max Δt)² + 2π |R_c + R_j|^½)
             + w_g N(d − v_g Δt; 0, S_g),

    the last term for the pairs given a ``group_velocity`` ``v_g`` (rows of NaN: none).
    """
    z_c = np.asarray(z_c, dtype=float).reshape(-1, 2)
    z_j = np.asarray(z_j, dtype=float).reshape(-1, 2)
    R_c = np.asarray(R_c, dtype=float).reshape(-1, 2, 2)
    R_j = np.asarray(R_j, dtype=float).reshape(-1, 2, 2)
    v_g = None if group_velocity is None else np.asarray(group_velocity, float).reshape(-1, 2)
    grouped = v_g is not None and group_fraction > 0.0 and bool(np.isfinite(v_g).all(axis=1).any())
    T = _pair_table(z_j - z_c, R_c, R_j, dt, v_g if grouped else None)
    group = dict(group_fraction=group_fraction, group_velocity_std=group_velocity_std)
    _score_pairs(
        T,
        _ZERO,
        max_speed=max_speed,
        velocity_std=velocity_std,
        slow_fraction=slow_fraction,
        q=q,
        gamma=math.inf,
        **(group if grouped else {}),
    )
    loglik = T[_LL].copy()
    x, P = _mixed(T, max_speed, velocity_std, q, group_velocity_std if grouped else None)
    x[:, :2] += z_c
    return x, P, loglik


def _mixed(
    T: np.ndarray,
    max_speed: float,
    velocity_std: float,
    q: float,
    group_velocity_std: float | None,
    cols: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_mixture_state` of the pairs of the scored table ``T`` (one column a pair; or
    its columns ``cols`` only): of two components, or of three when the table was scored
    with group velocities (``group_velocity_std`` given)."""
    m = 2 if group_velocity_std is None else 3
    copies = (
        np.concatenate((T,) * m, axis=1)
        if cols is None
        else T.take(np.concatenate((cols,) * m), axis=1)
    )
    return _mixture_state(
        copies,
        max_speed=max_speed,
        velocity_std=velocity_std,
        q=q,
        group_velocity_std=group_velocity_std,
    )


def _mixture_state(
    T: np.ndarray,
    *,
    max_speed: float,
    velocity_std: float,
    q: float,
    group_velocity_std: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The moment-matched mixture of the two components' Kalman posteriors of
    ``[p − z_c, v]`` at the second detection of each of the k pairs of the table ``T``
    (rows up to ``_LL`` filled, by :func:`_score_pairs`), whose ``2k`` columns hold the pairs
    twice (the slow component, then the fast one; ``T`` is overwritten); the component
    weights are ``β_s = e^{a_s − ln g₂}``, ``β_f = e^{a_f − ln g₂}``.

    Component m has the prior ``p ~ N(z_c, R_c)``, ``v ~ N(0, σ_m² I)`` (σ_s = σ_v,
    σ_f² = v_max²/2), predicted over Δt by the nearly constant velocity model (PSD q):

        P_pp = R_c + a I,  P_pv = b I,  P_vv = c I,
        a = σ² Δt² + q Δt³/3,  b = σ² Δt + q Δt²/2,  c = σ² + q Δt,

    and updated with ``d = z_j − z_c`` (covariance ``R_j``). With ``A = (P_pp + R_j)⁻¹``:

        x_p = d − R_j A d,  x_v = b A d,
        P_pp = R_j − R_j A R_j,  P_pv = b R_j A,  P_vv = c I − b² A.

    The mixture is ``x = β_s x_s + β_f x_f`` and
    ``P = β_s P_s + β_f P_f + β_s β_f δ δᵀ`` with ``δ = x_s − x_f``. Both components are
    computed at once, entry by entry, on the rows of ``T``; the state and the upper triangle
    of ``P`` go into one table that is mixed in a few operations.

    With ``group_velocity_std`` given, ``T`` holds the pairs three times, the third the
    *group* component: the prior ``v ~ N(v_g, σ_g² I)``, so ``z_c + v_g Δt`` predicted, which
    is the update above with ``d − v_g Δt`` for ``d`` and ``v_g Δt``, ``v_g`` added to the
    state; the mixture's spread is then ``Σ_m β_m (x_m − x)(x_m − x)ᵀ``."""
    m = 2 if group_velocity_std is None else 3
    k = T.shape[1] // m
    T[_LS, k : 2 * k] = T[_LF, k : 2 * k]  # the components' log weights a_s, a_f (, a_g)
    if m == 3:
        T[_LS, 2 * k :] = T[_LG, 2 * k :]
        g = np.nan_to_num(T[_G0 : _G1 + 1, 2 * k :])  # (2, k); no group: weight 0
        T[_D0 : _D1 + 1, 2 * k :] -= g * T[_DT, 2 * k :]
    d0, d1, j00, j01, j11, dt = T[_D0], T[_D1], T[_J00], T[_J01], T[_J11], T[_DT]
    q = np.array(q)
    beta = np.exp(T[_LS] - T[_LL])
    var = np.empty(m * k)
    var[:k], var[k : 2 * k] = velocity_std**2, 0.5 * max_speed**2
    if m == 3:
        var[2 * k :] = group_velocity_std**2
    dt2 = dt**2
    a = var * dt2 + q * dt**3 / _THREE
    b = var * dt + q * dt2 / _TWO
    c = var + q * dt
    s00, s01, s11 = T[_S00] + a, T[_S01], T[_S11] + a
    det = s00 * s11 - s01 * s01
    A00, A01, A11 = s11 / det, -s01 / det, s00 / det
    Ad0, Ad1 = A00 * d0 + A01 * d1, A01 * d0 + A11 * d1
    RA00, RA01 = j00 * A00 + j01 * A01, j00 * A01 + j01 * A11
    RA10, RA11 = j01 * A00 + j11 * A01, j01 * A01 + j11 * A11
    E = np.empty((14, m * k))
    np.subtract(d0, j00 * Ad0 + j01 * Ad1, out=E[0])
    np.subtract(d1, j01 * Ad0 + j11 * Ad1, out=E[1])
    np.multiply(b, Ad0, out=E[2])
    np.multiply(b, Ad1, out=E[3])
    np.subtract(j00, RA00 * j00 + RA01 * j01, out=E[4])
    np.subtract(j01, RA00 * j01 + RA01 * j11, out=E[5])
    np.subtract(j11, RA10 * j01 + RA11 * j11, out=E[6])
    np.multiply(b, RA00, out=E[7])
    np.multiply(b, RA01, out=E[8])
    np.multiply(b, RA10, out=E[9])
    np.multiply(b, RA11, out=E[10])
    b2 = b * b
    np.subtract(c, b2 * A00, out=E[11])
    np.subtract(c, b2 * A11, out=E[12])
    np.multiply(-b2, A01, out=E[13])
    if m == 2:
        delta = E[:4, :k] - E[:4, k:]
        E *= beta
        mix = E[:, :k] + E[:, k:]
        spread = delta.take(_SPREAD_I, axis=0) * delta.take(_SPREAD_J, axis=0)
        spread *= beta[:k] * beta[k:]
    else:
        E[0:2, 2 * k :] += g * dt[2 * k :]
        E[2:4, 2 * k :] += g
        x_m = E[:4].reshape(4, 3, k).copy()
        E *= beta
        mix = E[:, :k] + E[:, k : 2 * k] + E[:, 2 * k :]
        delta = x_m - mix[:4, None, :]  # (4, 3, k)
        spread = (
            delta.take(_SPREAD_I, axis=0) * delta.take(_SPREAD_J, axis=0) * beta.reshape(3, k)
        ).sum(axis=1)
    mix[4:] += spread
    return mix[:4].T.copy(), mix.take(_P_ROWS, axis=0).T.copy().reshape(k, 4, 4)


def next_hit_allowance(
    candidates: Candidates,
    fresh: np.ndarray,
    z: np.ndarray,
    free: np.ndarray,
    t: float,
    *,
    pd: float,
    clutter_density: float,
    max_speed: float,
    slow_fraction: float,
    floor: float,
) -> np.ndarray:
    """How far below ``floor`` (the deletion threshold) the pairs of each candidate may score
    and still start a track (0 for most): the score a third detection at the next revisit is
    expected to add,

        h = max(0, ln(P_D / (2π √|S| λ_fa)) − 1),   S ≈ 6 R_c,

    ``S`` the innovation covariance of a two-point track one revisit ``Δt`` on, with
    detections about as noisy as the candidate's ``R_c``: its prediction ``z₂ + v Δt`` with
    ``v = (z₂ − z₁)/Δt`` has covariance ``R + 2R + 2R = 5R`` (position, velocity and their
    cross term ``R/Δt``), the third detection adds ``R``; ``−1`` is the mean of ``−χ²₂/2``.

    A pair's own score says whether two detections this far apart are likelier a target
    than clutter. At a long revisit the fast prior is spread over ``π (v_max Δt)²`` and the
    pair of a real fast target can fall below the threshold (a 250 m/s target every 4 s with
    λ_fa 1e-6 per m², the density assumed when a batch states none) although its third
    detection would lift it above; the test then decides one scan later. That is allowed
    only where it costs little and the density looks overstated: for a candidate at its
    first scan (``fresh``), whose fast pairs cannot pass ``floor`` without it, and around
    which fewer ``free`` detections of ``z`` lie within its reach ``v_max Δt`` than
    :data:`SPARSE_FRACTION` of the ``λ_fa π (v_max Δt)²`` that the density predicts (a
    fifth: a candidate at the edge or corner of a uniformly cluttered area sees a half or a
    quarter). In clutter as dense as assumed nothing changes (and when the scan's free
    detections are that dense over the square on the longer side of the rectangle they span,
    no candidate is looked at; a line of aircraft on one airway spans no area), and
    the extra tentative tracks are at most the few detections in reach."""
    out = np.zeros(candidates.time.size)
    fresh = np.asarray(fresh, dtype=bool)
    if not fresh.any():
        return out
    # The fresh candidates opened at one scan: when the lowest-scored of them passes, all do.
    # ln(P_D (1 − w) / (π λ_fa)): what a fast pair adds, less 2 ln(v_max Δt) (logs: the
    # quotient itself under- or overflows at extreme settings).
    log_fast = math.log(pd * (1.0 - slow_fraction)) - math.log(math.pi) - math.log(clutter_density)
    dt0 = t - float(candidates.time[fresh].max())
    if dt0 >= MIN_PAIR_INTERVAL:
        best = float(candidates.score[fresh].min()) + log_fast - 2.0 * math.log(max_speed * dt0)
        if best > floor:
            return out
    dt = t - candidates.time
    reach = max_speed * np.maximum(dt, MIN_PAIR_INTERVAL)
    # The best a fast pair can score: the candidate's score and ln(P_D ḡ_f / λ_fa).
    fast = candidates.score + log_fast - 2.0 * np.log(reach)
    need = np.flatnonzero(fresh & (dt >= MIN_PAIR_INTERVAL) & (fast <= floor))
    if need.size == 0:
        return out
    R = candidates.R.take(need, axis=0)
    det = np.maximum(R[:, 0, 0] * R[:, 1, 1] - R[:, 0, 1] * R[:, 1, 0], 1e-300)
    h = math.log(pd / (12.0 * math.pi * clutter_density)) - 0.5 * np.log(det) - 1.0
    keep = h > 0.0
    need, h = need[keep], h[keep]
    if need.size == 0:
        return out
    r = reach.take(need)
    expected = clutter_density * math.pi * r * r
    points = z.take(np.flatnonzero(free), axis=0)
    n = points.shape[0]
    if n < SPARSE_FRACTION * float(expected.min()):
        sparse = np.ones(need.size, dtype=bool)  # fewer in the whole scan
    elif n > SPARSE_FRACTION * clutter_density * float(np.ptp(points, axis=0).max()) ** 2:
        return out  # the scan is as dense as assumed over the square its detections span
    else:
        count = cKDTree(points).query_ball_point(
            candidates.z.take(need, axis=0), r, return_length=True
        )
        sparse = count < SPARSE_FRACTION * expected
    out[need[sparse]] = h[sparse]
    return out


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
    clutter_density: float | np.ndarray,
    min_score: float | np.ndarray = -math.inf,
    group_fraction: float = 0.0,
    group_velocity_std: float = 1.0,
    allowance: np.ndarray | None = None,
    rivals: np.ndarray | None = None,
) -> TwoPointTracks:
    """Every (candidate, free detection) pair a target no faster than ``max_speed`` could
    make, at most ``max_pairs`` per candidate (the highest scores), with the two-point state
    and the score ``L = L_c + ln(P_D g₂ / λ_fa)``; pairs with ``L ≤ min_score`` (a number,
    such as the deletion threshold of the sequential test, or one per detection of ``z``)
    are left out; a candidate's pairs may score ``allowance`` below it (one number per
    candidate, 0 by default; :func:`next_hit_allowance`), but never below ``rivals``, the
    score a pair on each detection must beat whatever the allowance (one per detection of
    ``z``, ``−inf`` for none: a tentative track that took the detection). Detections are
    indexed into ``z``.

    The velocity gate of the module docstring is ``ρ² dᵀ (R_c + R_j)⁻¹ d ≤ γ`` with
    ``ρ = max(0, 1 − v_max Δt / |d|)``: the part of ``d`` beyond the reach of ``v_max``.
    Up to ``BRUTE_FORCE_CELLS`` (candidate, free detection) pairs every pair is scored: the
    floor and the gate reject every pair that the search of larger problems leaves out, so
    both give the same pairs.

    A candidate with a ``group_velocity`` adds the group component (weight
    ``group_fraction``, spread ``group_velocity_std``) to its prior (:func:`_score_pairs`).
    ``clutter_density`` is one number, or one per detection of ``z`` (a clutter map's): a
    pair's hit increment then weighs its second detection against the density where it fell.
    """
    dt_all = t - candidates.time
    offered = (dt_all >= MIN_PAIR_INTERVAL).nonzero()[0]
    free_idx = np.asarray(free).nonzero()[0]
    n_c, n_f = offered.size, free_idx.size
    if n_c == 0 or n_f == 0:
        return _no_pairs()
    zf, Rf = z.take(free_idx, axis=0), R.take(free_idx, axis=0)
    # (isinstance first: np.ndim of a Python float costs as much as an array operation)
    per_floor = isinstance(min_score, np.ndarray) and min_score.ndim > 0
    floor = np.asarray(min_score).take(free_idx) if per_floor else min_score
    rival = None if rivals is None else np.asarray(rivals, dtype=float).take(free_idx)
    kw = dict(
        max_speed=max_speed,
        velocity_std=velocity_std,
        slow_fraction=slow_fraction,
        q=q,
        gamma=gamma,
    )
    cz, cR, dt_c, base = candidates.z, candidates.R, dt_all, candidates.score
    vg = candidates.group_velocity
    allow = np.zeros(dt_all.size) if allowance is None else np.asarray(allowance, dtype=float)
    if n_c < dt_all.size:
        cz, cR = cz.take(offered, axis=0), cR.take(offered, axis=0)
        dt_c, base = dt_c.take(offered), base.take(offered)
        vg = vg.take(offered, axis=0)
        allow = allow.take(offered)
    grouped = group_fraction > 0.0 and bool(np.isfinite(vg).all(axis=1).any())
    if grouped:
        group = dict(group_fraction=group_fraction, group_velocity_std=group_velocity_std)
    else:
        group = {}
    if not (isinstance(clutter_density, np.ndarray) and clutter_density.ndim > 0):
        base = base + (math.log(pd) - math.log(clutter_density))
        per_detection = None
    else:  # −ln λ_fa of each free detection, added to each pair below
        base = base + math.log(pd)
        per_detection = -np.log(np.asarray(clutter_density, dtype=float).take(free_idx))
    if n_c * n_f <= BRUTE_FORCE_CELLS:
        # Every pair, in (candidate, detection) grids.
        T = np.empty((_ROWS, n_c, n_f))
        np.subtract(zf[:, 0], cz[:, 0, None], out=T[_D0])
        np.subtract(zf[:, 1], cz[:, 1, None], out=T[_D1])
        T[_J00], T[_J01], T[_J11] = Rf[:, 0, 0], Rf[:, 0, 1], Rf[:, 1, 1]
        np.add(cR[:, 0, 0, None], T[_J00], out=T[_S00])
        np.add(cR[:, 0, 1, None], T[_J01], out=T[_S01])
        np.add(cR[:, 1, 1, None], T[_J11], out=T[_S11])
        T[_DT] = dt_c[:, None]
        if grouped:
            T[_G0 : _G1 + 1] = vg.T[:, :, None]
        pair_base = base[:, None] if per_detection is None else base[:, None] + per_detection
        _score_pairs(T, pair_base, **kw, **group)
        score = T[_SCORE]
        # Rival pairs of one candidate, or of one detection, are pruned when far less likely
        # than the best of them.
        best_c = np.maximum.reduce(score, axis=1, keepdims=True)
        best_d = np.maximum.reduce(score, axis=0)
        passes = score + allow[:, None] > floor
        if rival is not None:
            passes &= score > rival
        good = (
            passes
            & (score >= best_c - PAIR_PRUNE_LOG_RATIO)
            & (score >= best_d - PAIR_PRUNE_LOG_RATIO)
        )
        ci, fj = good.nonzero()  # by candidate, then detection
        if ci.size == 0:
            return _no_pairs()
        T, cols = T.reshape(_ROWS, -1), ci * n_f + fj
    else:
        ci, fj, T, cols = _searched_pairs(
            cz,
            cR,
            dt_c,
            base,
            zf,
            Rf,
            floor,
            vg if grouped else None,
            group,
            allow,
            rival,
            per_detection,
            **kw,
        )
        if ci.size == 0:
            return _no_pairs()
    # The ``max_pairs`` best of each candidate are kept, best first.
    order, rank = sort_within_groups(ci, T[_SCORE].take(cols))
    if ci.size > max_pairs:
        order = order[rank < max_pairs]
    ci, fj, cols = ci[order], fj[order], cols[order]
    score = T[_SCORE].take(cols)
    x, P = _mixed(T, max_speed, velocity_std, q, group_velocity_std if grouped else None, cols)
    x[:, :2] += cz.take(ci, axis=0)
    return TwoPointTracks(
        candidate=ci if n_c == dt_all.size else offered[ci],
        detection=free_idx[fj],
        x=x,
        P=P,
        score=score,
    )


def _searched_pairs(
    cz: np.ndarray,
    cR: np.ndarray,
    dt: np.ndarray,
    base: np.ndarray,
    zf: np.ndarray,
    Rf: np.ndarray,
    floor: float | np.ndarray,
    vg: np.ndarray | None,
    group: dict[str, float],
    allow: np.ndarray,
    rival: np.ndarray | None,
    per_detection: np.ndarray | None,
    **kw: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pairs of :func:`pair_candidates` in a large problem: each candidate ``i`` (``cz``,
    ``cR``, ``dt``, ``base`` its rows, to which ``per_detection``, when given, adds the
    detection's ``−ln λ_fa``) searches the free detections ``j`` (``zf``, ``Rf``,
    ``floor`` a number or theirs, less the candidate's ``allow``, above ``rival`` when
    given) within
    :func:`search_radius`, or within the whole velocity
    gate for a candidate with a group velocity (``vg``, NaN: none; ``group`` the weight and
    spread of the group component, empty without one). Returns ``i`` and ``j`` (by
    candidate, then detection) of the pairs that pass the floor and the pruning of rivals,
    the table of the pairs searched (``_ROWS``, one column a pair) and their columns."""
    empty = np.zeros(0, dtype=np.intp)
    none = empty, empty, np.zeros((_ROWS, 0)), empty
    noise = max_eigenvalue_2x2(cR) + float(max_eigenvalue_2x2(Rf).max())
    top = 0.0 if per_detection is None else float(per_detection.max())  # the best a pair adds
    radius = search_radius(dt, base + allow + top, noise, float(np.min(floor)), **kw)
    if vg is not None:  # the group term can pass anywhere in the velocity gate
        grouped = np.isfinite(vg).all(axis=1)
        radius[grouped] = kw["max_speed"] * dt[grouped] + np.sqrt(kw["gamma"] * noise[grouped])
    searched = (radius >= 0.0).nonzero()[0]
    if searched.size == 0:
        return none
    i, fj = pairs_within(cz.take(searched, axis=0), radius.take(searched), zf)
    n = i.size
    if n == 0:
        return none
    ci = searched[i]  # grouped by candidate, in candidate order
    T = _pair_table(
        zf.take(fj, axis=0) - cz.take(ci, axis=0),
        cR.take(ci, axis=0),
        Rf.take(fj, axis=0),
        dt.take(ci),
        None if vg is None else vg.take(ci, axis=0),
    )
    pair_base = base.take(ci) if per_detection is None else base.take(ci) + per_detection.take(fj)
    _score_pairs(T, pair_base, **kw, **group)
    score = T[_SCORE]
    # Rival pairs of one candidate, or of one detection, are pruned when far less likely than
    # the best of them.
    new_group = np.empty(n, dtype=bool)
    new_group[0] = True
    np.not_equal(ci[1:], ci[:-1], out=new_group[1:])
    group = np.cumsum(new_group) - 1
    best_c = np.maximum.reduceat(score, np.flatnonzero(new_group))[group]
    best_d = np.full(zf.shape[0], -np.inf)
    np.maximum.at(best_d, fj, score)
    f = floor if np.ndim(floor) == 0 else floor.take(fj)
    passes = score + allow.take(ci) > f
    if rival is not None:
        passes &= score > rival.take(fj)
    good = (
        passes
        & (score >= best_c - PAIR_PRUNE_LOG_RATIO)
        & (score >= best_d[fj] - PAIR_PRUNE_LOG_RATIO)
    ).nonzero()[0]
    return ci[good], fj[good], T, good
