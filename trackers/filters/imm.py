"""Interacting Multiple Model estimator (Blom and Bar-Shalom 1988), batched over tracks.

Shapes: ``N`` tracks, ``M`` modes, state dimension ``n``, measurement dimension ``m``.
Per-mode estimates are ``x (N, M, n)``, ``P (N, M, n, n)``, mode probabilities ``mu (N, M)``.
The mode transition matrix ``Pi (M, M)`` has ``Pi[i, j] = P(mode j at k | mode i at k−1)``,
rows summing to 1 (Bar-Shalom, Li and Kirubarajan 2001, section 11.6).

A cycle is :func:`imm_predict` (interaction/mixing, then mode-matched prediction) followed by
:func:`imm_update` (mode-matched Kalman updates, mode probability update);
:func:`imm_combine` gives the moment-matched output estimate.

Mode probabilities are kept away from exactly 0: wherever they are produced (and when they
enter the mixing) they are raised to at least :data:`MU_FLOOR` and renormalized, so that a
mode can always come back and the mixing weights never divide by zero. Mode likelihoods are
handled as logarithms (log-sum-exp), so nothing underflows.

Internally everything runs in the state-major layout of :mod:`trackers.models.motion`
(``xs (n, M, N)``, ``Ps (n, n, M, N)``, ``mu (M, N)``), block by block over the tracks; the
public functions convert on the way in and out and return C-contiguous batch-major arrays.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np

from trackers.filters.kalman import update_state_major
from trackers.models.measurement import range_rate_update
from trackers.models.motion import (
    MotionModel,
    batch_major,
    batch_major_cov,
    row_blocks,
    state_major,
    state_major_cov,
)

__all__ = [
    "MU_FLOOR",
    "imm_combine",
    "imm_mix",
    "imm_predict",
    "imm_range_rate_update",
    "imm_update",
    "transition_matrix",
]

MU_FLOOR = 1e-12
"""Lower bound applied to every mode probability before renormalization."""

_TINY = np.finfo(float).tiny


def _floor_probabilities(mu: np.ndarray, axis: int) -> np.ndarray:
    """``μ ← max(μ, MU_FLOOR) / Σ max(μ, MU_FLOOR)`` along ``axis`` (a new array)."""
    mu = np.maximum(mu, MU_FLOOR)
    mu /= mu.sum(axis=axis, keepdims=True)
    return mu


def transition_matrix(sojourn_times: Sequence[float], dt: float) -> np.ndarray:
    """Mode transition matrix for an interval ``T = dt`` from mean sojourn times ``τ_j`` (s).

    ``π_jj = exp(−T/τ_j)`` and ``π_ji = (1 − π_jj)/(M − 1)`` for ``i ≠ j``; ``[[1]]`` for
    M = 1. ``Pi[i, j]`` is the probability of being in mode j now given mode i at the
    previous time; every row sums to 1. ``dt = 0`` gives the identity.
    """
    # Plain floats: the IMM needs this every scan, for a handful of modes, mostly at one
    # revisit interval: the matrices are kept (read-only) for the last intervals asked.
    tau = tuple(float(t) for t in np.asarray(sojourn_times, dtype=float).reshape(-1))
    return _transition_matrix(tau, float(dt))


@functools.lru_cache(maxsize=64)
def _transition_matrix(tau: tuple[float, ...], dt: float) -> np.ndarray:
    if not tau:
        raise ValueError("sojourn_times: at least one mode")
    if not all(math.isfinite(t) and t > 0 for t in tau):
        raise ValueError(f"sojourn_times: must be finite and > 0, got {tau!r}")
    if not (math.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt: must be a finite number >= 0, got {dt!r}")
    M = len(tau)
    if M == 1:
        out = np.ones((1, 1))
        out.flags.writeable = False
        return out
    rows = []
    for i, t in enumerate(tau):
        stay = math.exp(-dt / t)
        row = [(1.0 - stay) / (M - 1)] * M
        row[i] = stay
        rows.append(row)
    out = np.array(rows)
    out.flags.writeable = False
    return out


def _add_spread(out: np.ndarray, tmp: np.ndarray, xs: np.ndarray, w: np.ndarray) -> None:
    """``out += Σ_i w_i (x_i − x̄)(x_i − x̄)ᵀ`` with ``x̄ = Σ_i w_i x_i`` and ``Σ_i w_i = 1``.

    Evaluated as ``Σ_{i<k} w_i w_k (x_i − x_k)(x_i − x_k)ᵀ``, the same quantity written with
    differences of the mode states only (no cancellation of large positions).
    xs (n, M, N), w (M, ..., N); out and the scratch array tmp are (n, n, ..., N).
    """
    n, M = xs.shape[0], xs.shape[1]
    extra = (1,) * (w.ndim - 2)  # the axes of w between the mode axis and N
    for i in range(M):
        for k in range(i + 1, M):
            d = xs[:, i] - xs[:, k]  # (n, N)
            outer = (d[:, None] * d[None]).reshape(n, n, *extra, -1)
            out += np.multiply(outer, w[i] * w[k], out=tmp)


def _mix(
    xs: np.ndarray, Ps: np.ndarray, mus: np.ndarray, Pi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """State-major :func:`imm_mix`: xs (n, M, N), Ps (n, n, M, N), mus (M, N)."""
    M = xs.shape[1]
    mus = _floor_probabilities(mus, axis=0)
    joint = Pi[:, :, None] * mus[:, None, :]  # (i, j, N): π_ij μ_i
    c_bar = joint.sum(axis=0)  # (j, N)
    w = joint / np.maximum(c_bar, _TINY)  # (i, j, N): μ_{i|j}
    x0 = xs[:, 0, None] * w[0]  # (n, j, N)
    P0 = np.multiply(Ps[:, :, 0, None], w[0])  # (n, n, j, N)
    if M > 1:
        tmp = np.empty_like(P0)
        for i in range(1, M):
            x0 += xs[:, i, None] * w[i]
            P0 += np.multiply(Ps[:, :, i, None], w[i], out=tmp)
        _add_spread(P0, tmp, xs, w)
    return x0, P0, c_bar


def _check_shapes(x: np.ndarray, P: np.ndarray, mu: np.ndarray) -> tuple[int, int, int]:
    if x.ndim != 3 or P.shape != (*x.shape, x.shape[-1]) or mu.shape != x.shape[:2]:
        raise ValueError(
            f"expected x (N, M, n), P (N, M, n, n), mu (N, M); got {x.shape}, {P.shape}, {mu.shape}"
        )
    N, M, n = x.shape
    return N, M, n


def imm_mix(
    x: np.ndarray, P: np.ndarray, mu: np.ndarray, Pi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IMM interaction (mixing) step.

    x (N, M, n), P (N, M, n, n), mu (N, M), Pi (M, M) → x0 (N, M, n), P0 (N, M, n, n),
    c̄ (N, M)::

        c̄_j     = Σ_i π_ij μ_i                      (predicted mode probability)
        μ_{i|j} = π_ij μ_i / c̄_j                    (mixing probability)
        x0_j    = Σ_i μ_{i|j} x_i
        P0_j    = Σ_i μ_{i|j} (P_i + (x_i − x0_j)(x_i − x0_j)ᵀ)

    ``mu`` is first floored at :data:`MU_FLOOR` and renormalized.
    """
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    mu = np.asarray(mu, dtype=float)
    Pi = np.asarray(Pi, dtype=float)
    N, M, n = _check_shapes(x, P, mu)
    x_out = np.empty((N, M, n))
    P_out = np.empty((N, M, n, n))
    c_out = np.empty((N, M))
    for rows in row_blocks(N, M):
        x0, P0, c_bar = _mix(state_major(x[rows]), state_major_cov(P[rows]), mu[rows].T, Pi)
        x_out[rows] = batch_major(x0)
        P_out[rows] = batch_major_cov(P0)
        c_out[rows] = c_bar.T
    return x_out, P_out, c_out


def imm_predict(
    models: Sequence[MotionModel],
    x: np.ndarray,
    P: np.ndarray,
    mu: np.ndarray,
    Pi: np.ndarray,
    dt: float,
    revisit: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mix (:func:`imm_mix`), then let each model j predict its own mixed estimate.

    ``x⁻_j, P⁻_j = model_j.predict(x0_j, P0_j, dt)``. Returns x⁻ (N, M, n), P⁻ (N, M, n, n)
    and the predicted mode probabilities c̄ (N, M), which :func:`imm_update` needs.
    ``revisit`` (N,), each track's interval between its detections, goes to the models that
    take one (a constant-velocity mode's agile turn prior is per revisit, not per batch:
    :class:`~trackers.models.motion.ConstantVelocity`).
    """
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    mu = np.asarray(mu, dtype=float)
    Pi = np.asarray(Pi, dtype=float)
    N, M, n = _check_shapes(x, P, mu)
    if len(models) != M or Pi.shape != (M, M):
        raise ValueError(f"{len(models)} models and Pi {Pi.shape} for {M} modes")
    x_out = np.empty((N, M, n))
    P_out = np.empty((N, M, n, n))
    c_out = np.empty((N, M))
    for rows in row_blocks(N, M):
        x0, P0, c_bar = _mix(state_major(x[rows]), state_major_cov(P[rows]), mu[rows].T, Pi)
        for j, model in enumerate(models):
            predict_sm = getattr(model, "predict_state_major", None)
            if predict_sm is not None:
                if revisit is not None and getattr(model, "agile", False):
                    xj, Pj = predict_sm(x0[:, j], P0[:, :, j], dt, revisit[rows])
                else:
                    xj, Pj = predict_sm(x0[:, j], P0[:, :, j], dt)
                x_out[rows, j] = batch_major(xj)
                P_out[rows, j] = batch_major_cov(Pj)
            else:  # a model with only the batch-major predict
                xj, Pj = model.predict(batch_major(x0[:, j]), batch_major_cov(P0[:, :, j]), dt)
                x_out[rows, j] = xj
                P_out[rows, j] = Pj
        c_out[rows] = c_bar.T
    return x_out, P_out, c_out


def _mode_probabilities(ll_modes: np.ndarray, c_bar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``μ_j ∝ Λ_j c̄_j`` (floored) and ``ln Σ_j c̄_j Λ_j`` from ``ln Λ (M, N)``, c̄ (M, N)."""
    log_w = ll_modes + np.log(np.maximum(c_bar, _TINY))  # ln(Λ_j c̄_j)
    peak = log_w.max(axis=0)  # (N,)
    ok = np.isfinite(peak)
    peak_ok = np.where(ok, peak, 0.0)
    shifted = np.exp(log_w - peak_ok)
    total = np.where(ok, shifted.sum(axis=0), 1.0)  # >= 1 where ok
    mu = _floor_probabilities(np.where(ok, shifted / total, c_bar), axis=0)
    return mu, np.where(ok, np.log(total) + peak_ok, peak)


def imm_update(
    x_pred: np.ndarray,
    P_pred: np.ndarray,
    c_bar: np.ndarray,
    z: np.ndarray,
    R: np.ndarray,
    H: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mode-matched Kalman updates and mode probability update.

    x_pred (N, M, n), P_pred (N, M, n, n), c̄ (N, M), z (N, m), R (N, m, m), H (m, n)::

        x_j, P_j, ln Λ_j = kalman_update(x⁻_j, P⁻_j, z, R, H)      Λ_j = N(ν_j; 0, S_j)
        μ_j  = Λ_j c̄_j / Σ_i Λ_i c̄_i
        ln Λ = ln Σ_j c̄_j Λ_j          (log-sum-exp over j)

    Returns ``(x (N, M, n), P (N, M, n, n), mu (N, M), ln Λ (N,))``; mu is floored at
    :data:`MU_FLOOR` and renormalized. ln Λ is the log-likelihood of z under the IMM. A track
    whose every mode has Λ_j = 0 (ln Λ_j = −inf) keeps μ = c̄ and gets ln Λ = −inf.
    """
    x_pred = np.asarray(x_pred, dtype=float)
    P_pred = np.asarray(P_pred, dtype=float)
    c_bar = np.asarray(c_bar, dtype=float)
    H = np.asarray(H, dtype=float)
    N, M, n = _check_shapes(x_pred, P_pred, c_bar)
    m = H.shape[0]
    z = np.asarray(z, dtype=float)
    R = np.asarray(R, dtype=float)
    if z.shape != (N, m):  # (broadcast_to costs as much as the arithmetic: only when needed)
        z = np.broadcast_to(z, (N, m))
    if R.shape != (N, m, m):
        R = np.broadcast_to(R, (N, m, m))
    x_out = np.empty((N, M, n))
    P_out = np.empty((N, M, n, n))
    mu_out = np.empty((N, M))
    ll_out = np.empty(N)
    for rows in row_blocks(N, M):
        xs, Ps, ll_modes = update_state_major(
            state_major(x_pred[rows]),
            state_major_cov(P_pred[rows]),
            state_major(z[rows])[:, None],  # (m, 1, b): the same z for every mode
            state_major_cov(R[rows])[:, :, None],
            H,
        )
        mu, ll = _mode_probabilities(ll_modes, c_bar[rows].T)
        x_out[rows] = batch_major(xs)
        P_out[rows] = batch_major_cov(Ps)
        mu_out[rows] = mu.T
        ll_out[rows] = ll
    return x_out, P_out, mu_out, ll_out


def imm_range_rate_update(
    x: np.ndarray,
    P: np.ndarray,
    mu: np.ndarray,
    rdot: np.ndarray,
    sensor: np.ndarray,
    variance: float,
    sensor_velocity: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The mode-conditioned posteriors of :func:`imm_update` updated again, in sequence, with
    range-rates ``rdot (N,)`` of variance ``σ_ṙ²`` from ``sensor (2,)`` moving at
    ``sensor_velocity (2,)`` (None: at rest)
    (:func:`trackers.models.measurement.range_rate_update` in every mode)::

        x_j, P_j, ln Λ_j = range_rate_update(x_j, P_j, ṙ)
        μ_j ← μ_j Λ_j / Σ_i μ_i Λ_i,        Δ ln Λ = ln Σ_j μ_j Λ_j

    x (N, M, n), P (N, M, n, n), mu (N, M). Returns new ``x``, ``P``, ``mu`` (floored at
    :data:`MU_FLOOR`) and ``Δ ln Λ (N,)``, to add to the position's log-likelihood."""
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    mu = np.asarray(mu, dtype=float)
    N, M, n = _check_shapes(x, P, mu)
    rdot = np.repeat(np.asarray(rdot, dtype=float).reshape(N), M)
    xs, Ps, ll = range_rate_update(
        x.reshape(N * M, n), P.reshape(N * M, n, n), rdot, sensor, variance, sensor_velocity
    )
    ll = ll.reshape(N, M)
    log_w = ll + np.log(np.maximum(mu, _TINY))
    peak = log_w.max(axis=1, keepdims=True)
    w = np.exp(log_w - peak)
    total = w.sum(axis=1, keepdims=True)
    mu_new = _floor_probabilities(w / total, axis=1)
    return xs.reshape(N, M, n), Ps.reshape(N, M, n, n), mu_new, (np.log(total) + peak)[:, 0]


def imm_combine(x: np.ndarray, P: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Moment-matched combination of the mode estimates.

    x (N, M, n), P (N, M, n, n), mu (N, M) (rows summing to 1) → x̂ (N, n), P̂ (N, n, n)::

        x̂ = Σ_j μ_j x_j         P̂ = Σ_j μ_j (P_j + (x_j − x̂)(x_j − x̂)ᵀ)
    """
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    mu = np.asarray(mu, dtype=float)
    N, M, n = _check_shapes(x, P, mu)
    x_out = np.empty((N, n))
    P_out = np.empty((N, n, n))
    for rows in row_blocks(N, M):
        xs = state_major(x[rows])
        Ps = state_major_cov(P[rows])
        mus = mu[rows].T
        x_hat = xs[:, 0] * mus[0]
        P_hat = np.multiply(Ps[:, :, 0], mus[0])
        if M > 1:
            tmp = np.empty_like(P_hat)
            for j in range(1, M):
                x_hat += xs[:, j] * mus[j]
                P_hat += np.multiply(Ps[:, :, j], mus[j], out=tmp)
            _add_spread(P_hat, tmp, xs, mus)
        x_out[rows] = batch_major(x_hat)
        P_out[rows] = batch_major_cov(P_hat)
    return x_out, P_out
