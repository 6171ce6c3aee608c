"""A second look for confirmed tracks that found nothing in their gate: the manoeuvre search.

A fast target that starts a turn between two scans can leave the chi-square gate of its own
track: a 250 m/s airliner turning at 4°/s is 140 m off a straight line after 4 s, a jet
pulling 5 g 390 m, and several times that when a detection was missed on the way. The track
then coasts away while a new track starts on the target. This module gives such a track one
more chance, on the detections that no confirmed track has in its gate, under the hypothesis
that the target manoeuvred since its last update τ ago.

The manoeuvre is an unknown acceleration held since the last update, across the track (a
turn) and along it (a change of speed). With the unit vectors u along the estimated velocity
v and n across it, the acceleration's covariance is

    A = a_n²/3 n nᵀ + a_u²/3 u uᵀ,   a_n = min(a_max, ω_max |v|),
                                       a_u = max(κ a_n, min(a_s, a_max)),

a uniform acceleration in [−a_n, a_n] across the track (variance a_n²/3) and in [−a_u, a_u]
along it: at least κ = 1/5 of a_n, and at least a_s (``gating.manoeuvre_speed_change``), a
target setting off, speeding up or braking. The lateral acceleration of a turn at rate ω is
ω |v|, so slow targets turn little and parked ones not at all; a track whose speed is within
two standard deviations of zero has no known direction to set off along, and gets a_u in
every direction (a_n = a_u). Held over τ it adds to the predicted covariance of every IMM
mode

    Q_m(τ) = [[τ⁴/4 A, τ³/2 A, 0], [τ³/2 A, τ² A, 0], [0, 0, 0]]   on (position, velocity, ω).

A change of speed is searched for only where its gate expects fewer than 0.1 false alarms
(λ π γ √det S): a wide search among many false alarms takes one now and then, and a slow
target's track flies off with the velocity it gives. Elsewhere a pair is one of a turn alone.

The pair (i, j) is then scored like any other, with the likelihood g_ij under P⁻ + Q_m and
the prior probability that the target started to manoeuvre within τ, p_m = 1 − e^(−τ/τ_cv)
with τ_cv the sojourn time of the first (straight-flight) mode:

    G_ij = ln(P_D p_m g_ij / λ_fa) − ln(1 − P_D),

and GNN keeps the pairs of positive gain. In sparse clutter that reaches a turning target
hundreds of metres off; in dense clutter the wide likelihood loses to λ_fa and nothing is
taken, as it should be.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trackers.association.gating import (
    expected_false_alarms,
    gate,
    inverse_2x2,
    max_eigenvalue_2x2,
)
from trackers.association.gnn import gnn_assign
from trackers.filters.imm import imm_update
from trackers.models.measurement import H_POSITION
from trackers.models.motion import STATE_DIM, agile_turn_rate
from trackers.scoring import hit_increment, miss_increment

__all__ = [
    "ALONG_TRACK_FRACTION",
    "REACH_FRACTION",
    "ManoeuvreMatch",
    "manoeuvre_covariance",
    "manoeuvre_search",
    "reaches_beyond",
]

#: κ: the along-track acceleration's std as a fraction of the across-track one.
ALONG_TRACK_FRACTION = 0.2

#: The largest heading change (rad) over the time since its last update that the search looks
#: for an agile target (25 m/s or more) to have turned by (:func:`_acceleration_bounds`): a
#: vehicle seen every 10 s is not searched for across its road as far as 0.5 rad/s would reach.
MAX_AGILE_SEARCH_TURN = 1.0

#: Tracks are searched for when the manoeuvre's across-track position std exceeds this
#: fraction of their largest predicted position std.
REACH_FRACTION = 0.5


def _acceleration_bounds(
    velocity: np.ndarray,
    a_max: float,
    omega_max: float,
    a_speed: float | np.ndarray = 0.0,
    at_rest: np.ndarray | None = None,
    agile: float = 0.0,
    tau: float | np.ndarray = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The bounds across and along the track for velocities (N, 2):
    ``a_n = min(a_max, ω |v|)`` and ``a_u = max(κ a_n, min(a_speed, a_max))``; where
    ``at_rest``, whose direction is unknown, ``a_u`` across too. ``ω = max(ω_max, min(0.5,
    agile / |v|, 1 / τ))`` from 25 m/s on, else ``ω_max``
    (:func:`~trackers.models.motion.agile_turn_rate` over the time ``τ`` since the last
    update): a slower target turns faster on the same lateral acceleration, within
    :data:`MAX_AGILE_SEARCH_TURN` over ``τ`` (``agile`` 0: ``ω_max``)."""
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    rate = agile_turn_rate(speed, omega_max, agile, tau, MAX_AGILE_SEARCH_TURN)
    a_n = np.minimum(a_max, rate * speed)
    a_u = np.maximum(ALONG_TRACK_FRACTION * a_n, np.minimum(a_speed, a_max))
    if at_rest is not None:
        a_n = np.where(at_rest, np.maximum(a_n, a_u), a_n)
    return a_n, a_u


def _unit(velocity: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """The unit vectors along velocities (N, 2) of norms ``speed``; a velocity of exactly 0
    has no direction, and x is taken for it (at rest, the search is the same every way)."""
    ok = (speed > 0)[:, None]
    return np.where(ok, velocity / np.where(ok[:, 0], speed, 1.0)[:, None], [1.0, 0.0])


def at_rest(velocity: np.ndarray, P_v: np.ndarray) -> np.ndarray:
    """Mask of the velocities (N, 2) within two standard deviations of zero, whose direction
    is unknown: ``|v|² ≤ 4 λ_max(P_v)``."""
    return velocity[:, 0] ** 2 + velocity[:, 1] ** 2 <= 4.0 * max_eigenvalue_2x2(P_v)


def reaches_beyond(
    x_comb: np.ndarray,
    P_comb: np.ndarray,
    tau: np.ndarray,
    a_max: float,
    omega_max: float,
    a_speed: float = 0.0,
    agile: float = 0.0,
) -> np.ndarray:
    """Mask of the tracks (``x_comb (N, 5)``, ``P_comb (N, 5, 5)``, ``τ`` since their last
    update) whose manoeuvre reaches beyond their own uncertainty, which their gate searched
    already: the larger of its std across and along the track, ``a/√3 · τ²/2``, above
    ``REACH_FRACTION`` of the largest predicted position std,

        (a² / 3) (τ⁴ / 4) > REACH_FRACTION² λ_max(P_pos),   a = max(a_n, a_u)

    (:func:`manoeuvre_covariance`)."""
    a_n, a_u = _acceleration_bounds(x_comb[:, 2:4], a_max, omega_max, a_speed, agile=agile, tau=tau)
    a = np.maximum(a_n, a_u)
    reach = (a * a / 3.0) * (tau**4 / 4.0)
    return reach > REACH_FRACTION**2 * max_eigenvalue_2x2(P_comb[:, :2, :2])


def manoeuvre_covariance(
    velocity: np.ndarray,
    tau: np.ndarray,
    a_max: float,
    omega_max: float,
    a_speed: float | np.ndarray = 0.0,
    rest: np.ndarray | None = None,
    agile: float = 0.0,
) -> np.ndarray:
    """Q_m(τ) (N, 5, 5) for velocities (N, 2) and times since the last update τ (N,):
    ``A = a_n²/3 n nᵀ + a_u²/3 u uᵀ`` with ``a_n = min(a_max, ω_max |v|)`` across the track
    and ``a_u = max(κ a_n, min(a_speed, a_max))`` along it (``a_speed``: a change of speed,
    one number or one per track), then ``[[τ⁴/4 A, τ³/2 A], [τ³/2 A, τ² A]]`` on (position,
    velocity) and 0 on ω."""
    velocity = np.asarray(velocity, dtype=float).reshape(-1, 2)
    tau = np.asarray(tau, dtype=float).reshape(-1)
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    a_n, a_u = _acceleration_bounds(velocity, a_max, omega_max, a_speed, rest, agile, tau)
    u = _unit(velocity, speed)
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    A = (a_n * a_n / 3.0)[:, None, None] * (n[:, :, None] * n[:, None, :])
    A += (a_u * a_u / 3.0)[:, None, None] * (u[:, :, None] * u[:, None, :])
    Q = np.zeros((tau.size, STATE_DIM, STATE_DIM))
    Q[:, 0:2, 0:2] = A * (tau**4 / 4.0)[:, None, None]
    Q[:, 0:2, 2:4] = Q[:, 2:4, 0:2] = A * (tau**3 / 2.0)[:, None, None]
    Q[:, 2:4, 2:4] = A * (tau**2)[:, None, None]
    return Q


def _speed_kept(
    x: np.ndarray,
    mu: np.ndarray,
    x_comb: np.ndarray,
    P_comb: np.ndarray,
    R: np.ndarray,
    tau: np.ndarray,
    a_max: float,
    omega_max: float,
    max_speed: float,
    a_speed: float | np.ndarray = 0.0,
    agile: float = 0.0,
) -> np.ndarray:
    """Mask of the updated pairs (IMM posteriors ``x (K, M, 5)``, ``mu (K, M)``) whose speed
    stays within three standard deviations of the track's (``x_comb``, ``P_comb`` before,
    ``τ`` since its last update) under the manoeuvre's along-track part and goes no more
    than that beyond ``max_speed`` (``v_max``) or the track's own speed::

        | |v⁺| − |v⁻| | ≤ 3 σ_s,   σ_s² = (a_u τ)² / 3 + uᵀ P_v u + (2/τ)² uᵀ R u,
        |v⁺| ≤ max(v_max, |v⁻|) + 3 σ_s,

    ``v⁺ = Σ_j μ_j v_j`` the combined velocity after the update, ``u`` the unit vector along
    ``v⁻`` (``uᵀ P_v u``: the variance of the speed; the turn rate's uncertainty widens
    ``P_v`` across the track, in direction, by hundreds of m/s after 20 s of coasting at
    450 m/s), ``a_u`` the along-track bound of :func:`manoeuvre_covariance`, and the
    detection's own noise ``R``, which the update turns into a velocity over ``τ`` (an
    aircraft 150 km from a radar of 1.5 mrad is seen 225 m across the beam: 45 m/s over 10 s).
    A turn at constant speed passes (90° in 20 s by a 236 m/s aircraft: about +75 m/s from
    the Gaussian update against 3 σ_s ≈ 165 m/s); a false alarm 6 km across it does not."""
    v_new = np.einsum("km,kmi->ki", mu, x[:, :, 2:4])
    v_old = x_comb[:, 2:4]
    before = np.hypot(v_old[:, 0], v_old[:, 1])
    u = _unit(v_old, before)
    _, a_u = _acceleration_bounds(v_old, a_max, omega_max, a_speed, agile=agile, tau=tau)
    var = (
        (a_u * tau) ** 2 / 3.0
        + np.einsum("ki,kij,kj->k", u, P_comb[:, 2:4, 2:4], u)
        + (2.0 / tau) ** 2 * np.einsum("ki,kij,kj->k", u, R, u)
    )
    speed = np.hypot(v_new[:, 0], v_new[:, 1])
    change = speed - before
    return (change * change <= 9.0 * var) & (
        speed <= np.maximum(max_speed, before) + 3.0 * np.sqrt(var)
    )


@dataclass(frozen=True)
class ManoeuvreMatch:
    """The pairs taken: ``track`` (indices into the tracks searched for), ``detection``, and
    each track's IMM posterior ``x (K, M, 5)``, ``P (K, M, 5, 5)``, ``mu (K, M)`` and score
    increment ``hit (K,) = ln(P_D p_m g / λ_fa)``."""

    track: np.ndarray
    detection: np.ndarray
    x: np.ndarray
    P: np.ndarray
    mu: np.ndarray
    hit: np.ndarray


def manoeuvre_search(
    x_pred: np.ndarray,
    P_pred: np.ndarray,
    c_bar: np.ndarray,
    x_comb: np.ndarray,
    P_comb: np.ndarray,
    tau: np.ndarray,
    z: np.ndarray,
    R: np.ndarray,
    pd: np.ndarray,
    clutter_density: float | np.ndarray,
    *,
    a_max: float,
    omega_max: float,
    straight_sojourn: float,
    gamma: float,
    max_speed: float = np.inf,
    a_speed: float = 0.0,
    quiet: float = np.inf,
    agile: float = 0.0,
) -> ManoeuvreMatch | None:
    """Tracks (predicted mode states ``x_pred (N, M, 5)``, ``P_pred``, ``c_bar (N, M)``, their
    combination ``x_comb (N, 5)``, ``P_comb``, time since the last update ``tau``, detection
    probability ``pd (N,)``) matched to detections ``z (n, 2)``, ``R (n, 2, 2)`` (false-alarm
    density ``clutter_density``, one number or one per detection) under the
    manoeuvre hypothesis: the chi-square gate ``γ`` on ``P_comb + Q_m``, the gain
    ``G = hit + ln p_m − ln(1 − P_D)`` and GNN over the positive gains (module docstring),
    among the pairs whose updated speed is kept (:func:`_speed_kept`: the speed of a turn,
    and not much beyond ``max_speed``). None when nothing is taken.

    ``a_speed`` bounds a change of speed along the track (:func:`manoeuvre_covariance`); it
    widens the search of a pair (i, j) only where that search expects fewer than ``quiet``
    false alarms, ``λ_j π γ √det(P_pos + Q_m + R_j) < quiet``: elsewhere the pair is searched
    for a turn alone (``a_speed`` 0), as a wide search among many false alarms takes one
    now and then and sends the track off with its velocity."""
    N = x_comb.shape[0]
    if N == 0 or z.shape[0] == 0 or a_max <= 0:
        return None
    # Only where the manoeuvre reaches beyond the track's own uncertainty, which the gate
    # searched already: its larger std, a/√3 · τ²/2, above half the largest predicted
    # position std. (A turn of the reference scenario's slow targets never gets there, a
    # change of speed now and then: 30 searches in 100 scans. The cut leaves the mixed-speed
    # scenarios' answers as they are and saves 4/5 of the search's time.)
    wide = np.flatnonzero(
        reaches_beyond(x_comb, P_comb, tau, a_max, omega_max, a_speed, agile=agile)
    )
    if wide.size == 0:
        return None
    Q = manoeuvre_covariance(x_comb[wide, 2:4], tau[wide], a_max, omega_max, agile=agile)
    Q_u = (
        Q
        if a_speed <= 0
        else manoeuvre_covariance(
            x_comb[wide, 2:4],
            tau[wide],
            a_max,
            omega_max,
            a_speed,
            at_rest(x_comb[wide, 2:4], P_comb[wide, 2:4, 2:4]),
            agile,
        )
    )
    S0 = P_comb[wide, :2, :2] + Q[:, :2, :2]
    # No detection can do better than one at zero innovation, with S ⪰ S0:
    # G ≤ ln(P_D p_m / (2π √|S0| λ_fa)) − ln(1 − P_D). Tracks that cannot gain are left out.
    p_m = -np.expm1(-tau[wide] / straight_sojourn)
    det0 = S0[:, 0, 0] * S0[:, 1, 1] - S0[:, 0, 1] * S0[:, 1, 0]
    lam = np.broadcast_to(np.asarray(clutter_density, dtype=float), (z.shape[0],))
    with np.errstate(divide="ignore"):
        best = (
            np.log(pd[wide] * p_m / (2.0 * np.pi * float(lam.min()))) - 0.5 * np.log(det0)
        ) - miss_increment(pd[wide])
    hopeful = np.flatnonzero(best > 0)
    if hopeful.size == 0:
        return None
    S_u = P_comb[wide[hopeful], :2, :2] + Q_u[hopeful, :2, :2]  # ⪰ S0: gates all pairs
    pairs = gate(x_comb[wide[hopeful], :2], S_u, z, R, gamma)
    if pairs.size == 0:
        return None
    ti, dj, h = wide[hopeful[pairs.track]], pairs.detection, hopeful[pairs.track]
    Q_t, p_m = Q_u[h], p_m[h]
    a_pair: float | np.ndarray = a_speed
    if Q_u is not Q:
        # Where the change of speed's search is not quiet, the pair is one of a turn alone,
        # in that gate, and only for a track whose turn reaches beyond its own gate: as
        # without the change of speed.
        S_j = S_u[pairs.track] + R[dj]
        det_j = S_j[:, 0, 0] * S_j[:, 1, 1] - S_j[:, 0, 1] * S_j[:, 1, 0]
        calm = expected_false_alarms(lam[dj], det_j, gamma) < quiet
        S_n = S0[h] + R[dj]
        nu = z[dj] - x_comb[ti, :2]
        S_inv, _ = inverse_2x2(S_n)
        turning = reaches_beyond(
            x_comb[wide], P_comb[wide], tau[wide], a_max, omega_max, agile=agile
        )
        turn = ~calm & turning[h] & (np.einsum("ki,kij,kj->k", nu, S_inv, nu) <= gamma)
        keep = calm | turn
        ti, dj, h, calm, p_m = ti[keep], dj[keep], h[keep], calm[keep], p_m[keep]
        Q_t = np.where(calm[:, None, None], Q_u[h], Q[h])
        a_pair = np.where(calm, a_speed, 0.0)
        if ti.size == 0:
            return None
    x, P, mu, loglik = imm_update(
        x_pred[ti], P_pred[ti] + Q_t[:, None], c_bar[ti], z[dj], R[dj], H_POSITION
    )
    with np.errstate(divide="ignore"):
        hit = hit_increment(pd[ti], loglik, lam[dj]) + np.log(p_m)
    # A turn keeps the speed: a detection that only a change of speed beyond the along-track
    # part of the manoeuvre reaches (a false alarm kilometres across the track of an
    # aircraft coasting through two misses) is no manoeuvre of this target.
    keep = _speed_kept(
        x, mu, x_comb[ti], P_comb[ti], R[dj], tau[ti], a_max, omega_max, max_speed, a_pair, agile
    )
    ti, dj, x, P, mu, hit = ti[keep], dj[keep], x[keep], P[keep], mu[keep], hit[keep]
    sel = gnn_assign(ti, dj, hit - miss_increment(pd[ti]), N, z.shape[0])
    if sel.size == 0:
        return None
    return ManoeuvreMatch(ti[sel], dj[sel], x[sel], P[sel], mu[sel], hit[sel])
