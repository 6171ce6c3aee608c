"""A second look for confirmed tracks that found nothing in their gate: the manoeuvre search.

A fast target that starts a turn between two scans can leave the chi-square gate of its own
track: a 250 m/s airliner turning at 4°/s is 140 m off a straight line after 4 s, a jet
pulling 5 g 390 m, and several times that when a detection was missed on the way. The track
then coasts away while a new track starts on the target. This module gives such a track one
more chance, on the detections that no confirmed track has in its gate, under the hypothesis
that the target manoeuvred since its last update τ ago.

The manoeuvre is an unknown acceleration held since the last update, mostly across the
track (aircraft and ships manoeuvre by turning). With the unit vectors u along the estimated
velocity v and n across it, the acceleration's covariance is

    A = σ_a² (n nᵀ + κ² u uᵀ),   σ_a² = a(|v|)² / 3,   a(|v|) = min(a_max, ω_max |v|),

a uniform acceleration in [−a, a] across the track (variance a²/3) and κ = 1/5 of it along;
the lateral acceleration of a turn at rate ω is ω |v|, so slow targets get a small bound and
parked ones none. Held over τ it adds to the predicted covariance of every IMM mode

    Q_m(τ) = [[τ⁴/4 A, τ³/2 A, 0], [τ³/2 A, τ² A, 0], [0, 0, 0]]   on (position, velocity, ω).

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

from trackers.association.gating import gate, max_eigenvalue_2x2
from trackers.association.gnn import gnn_assign
from trackers.filters.imm import imm_update
from trackers.models.measurement import H_POSITION
from trackers.models.motion import STATE_DIM
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

#: Tracks are searched for when the manoeuvre's across-track position std exceeds this
#: fraction of their largest predicted position std.
REACH_FRACTION = 0.5


def _acceleration_bound(velocity: np.ndarray, a_max: float, omega_max: float) -> np.ndarray:
    """a(|v|) = min(a_max, ω_max |v|) for velocities (N, 2)."""
    return np.minimum(a_max, omega_max * np.hypot(velocity[:, 0], velocity[:, 1]))


def reaches_beyond(
    x_comb: np.ndarray, P_comb: np.ndarray, tau: np.ndarray, a_max: float, omega_max: float
) -> np.ndarray:
    """Mask of the tracks (``x_comb (N, 5)``, ``P_comb (N, 5, 5)``, ``τ`` since their last
    update) whose manoeuvre reaches beyond their own uncertainty, which their gate searched
    already: the across-track std ``a/√3 · τ²/2`` above ``REACH_FRACTION`` of the largest
    predicted position std,

        (a² / 3) (τ⁴ / 4) > REACH_FRACTION² λ_max(P_pos),   a = min(a_max, ω_max |v|).
    """
    a = _acceleration_bound(x_comb[:, 2:4], a_max, omega_max)
    reach = (a * a / 3.0) * (tau**4 / 4.0)
    return reach > REACH_FRACTION**2 * max_eigenvalue_2x2(P_comb[:, :2, :2])


def manoeuvre_covariance(
    velocity: np.ndarray, tau: np.ndarray, a_max: float, omega_max: float
) -> np.ndarray:
    """Q_m(τ) (N, 5, 5) for velocities (N, 2) and times since the last update τ (N,):
    ``A = a²/3 (n nᵀ + κ² u uᵀ)`` with ``a = min(a_max, ω_max |v|)``, then
    ``[[τ⁴/4 A, τ³/2 A], [τ³/2 A, τ² A]]`` on (position, velocity) and 0 on ω."""
    velocity = np.asarray(velocity, dtype=float).reshape(-1, 2)
    tau = np.asarray(tau, dtype=float).reshape(-1)
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    a = _acceleration_bound(velocity, a_max, omega_max)
    u = velocity / np.where(speed > 0, speed, 1.0)[:, None]
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    A = n[:, :, None] * n[:, None, :] + ALONG_TRACK_FRACTION**2 * (u[:, :, None] * u[:, None, :])
    A *= (a * a / 3.0)[:, None, None]
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
) -> np.ndarray:
    """Mask of the updated pairs (IMM posteriors ``x (K, M, 5)``, ``mu (K, M)``) whose speed
    stays within three standard deviations of the track's (``x_comb``, ``P_comb`` before,
    ``τ`` since its last update) under the manoeuvre's along-track part and goes no more
    than that beyond ``max_speed`` (``v_max``) or the track's own speed::

        | |v⁺| − |v⁻| | ≤ 3 σ_s,   σ_s² = (κ a τ)² / 3 + uᵀ P_v u + (2/τ)² uᵀ R u,
        |v⁺| ≤ max(v_max, |v⁻|) + 3 σ_s,

    ``v⁺ = Σ_j μ_j v_j`` the combined velocity after the update, ``u`` the unit vector along
    ``v⁻`` (``uᵀ P_v u``: the variance of the speed; the turn rate's uncertainty widens
    ``P_v`` across the track, in direction, by hundreds of m/s after 20 s of coasting at
    450 m/s), ``a = min(a_max, ω_max |v⁻|)``, and the detection's own noise ``R``, which the
    update turns into a velocity over ``τ`` (an aircraft 150 km from a radar of 1.5 mrad is
    seen 225 m across the beam: 45 m/s over 10 s).
    A turn at constant speed passes (90° in 20 s by a 236 m/s aircraft: about +75 m/s from
    the Gaussian update against 3 σ_s ≈ 165 m/s); a false alarm 6 km across it does not."""
    v_new = np.einsum("km,kmi->ki", mu, x[:, :, 2:4])
    v_old = x_comb[:, 2:4]
    before = np.hypot(v_old[:, 0], v_old[:, 1])
    u = v_old / np.where(before > 0, before, 1.0)[:, None]
    a = _acceleration_bound(v_old, a_max, omega_max)
    var = (
        (ALONG_TRACK_FRACTION * a * tau) ** 2 / 3.0
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
) -> ManoeuvreMatch | None:
    """Tracks (predicted mode states ``x_pred (N, M, 5)``, ``P_pred``, ``c_bar (N, M)``, their
    combination ``x_comb (N, 5)``, ``P_comb``, time since the last update ``tau``, detection
    probability ``pd (N,)``) matched to detections ``z (n, 2)``, ``R (n, 2, 2)`` (false-alarm
    density ``clutter_density``, one number or one per detection) under the
    manoeuvre hypothesis: the chi-square gate ``γ`` on ``P_comb + Q_m``, the gain
    ``G = hit + ln p_m − ln(1 − P_D)`` and GNN over the positive gains (module docstring),
    among the pairs whose updated speed is kept (:func:`_speed_kept`: the speed of a turn,
    and not much beyond ``max_speed``). None when nothing is taken."""
    N = x_comb.shape[0]
    if N == 0 or z.shape[0] == 0 or a_max <= 0:
        return None
    # Only where the manoeuvre reaches beyond the track's own uncertainty, which the gate
    # searched already: its across-track std, a/√3 · τ²/2, above half the largest predicted
    # position std. (Slow targets in the reference scenario never get there; the cut leaves
    # the mixed-speed scenarios' answers as they are and saves 4/5 of the search's time.)
    wide = np.flatnonzero(reaches_beyond(x_comb, P_comb, tau, a_max, omega_max))
    if wide.size == 0:
        return None
    Q = manoeuvre_covariance(x_comb[wide, 2:4], tau[wide], a_max, omega_max)
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
    pairs = gate(x_comb[wide[hopeful], :2], S0[hopeful], z, R, gamma)
    if pairs.size == 0:
        return None
    ti, dj = wide[hopeful[pairs.track]], pairs.detection
    Q_t, p_m = Q[hopeful[pairs.track]], p_m[hopeful[pairs.track]]
    x, P, mu, loglik = imm_update(
        x_pred[ti], P_pred[ti] + Q_t[:, None], c_bar[ti], z[dj], R[dj], H_POSITION
    )
    with np.errstate(divide="ignore"):
        hit = hit_increment(pd[ti], loglik, lam[dj]) + np.log(p_m)
    # A turn keeps the speed: a detection that only a change of speed beyond the along-track
    # part of the manoeuvre reaches (a false alarm kilometres across the track of an
    # aircraft coasting through two misses) is no manoeuvre of this target.
    keep = _speed_kept(x, mu, x_comb[ti], P_comb[ti], R[dj], tau[ti], a_max, omega_max, max_speed)
    ti, dj, x, P, mu, hit = ti[keep], dj[keep], x[keep], P[keep], mu[keep], hit[keep]
    sel = gnn_assign(ti, dj, hit - miss_increment(pd[ti]), N, z.shape[0])
    if sel.size == 0:
        return None
    return ManoeuvreMatch(ti[sel], dj[sel], x[sel], P[sel], mu[sel], hit[sel])
