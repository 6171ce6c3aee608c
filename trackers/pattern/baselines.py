"""Baseline point-pattern matchers to compare the FPPM with (:mod:`trackers.pattern.fppm`).

Both return the FPPM's :class:`~trackers.pattern.fppm.PatternMatch` (pairs, registration fitted
by eq. 19, MSE of eq. 16), so that a benchmark compares like with like. Points are complex
numbers ``x¹ + i x²`` inside, as in :mod:`trackers.pattern.fppm`.

- :func:`match_vote`: Chang et al. (1997), "Fast algorithm for point pattern matching:
  invariant to translations, rotations and scale changes" (Pattern Recognition 30(2)), the
  "arbitrary vote" that paper 000 (section 4.1) improves on: for each pair ``xᵢ ↔ y_j``, every
  other pair ``x_h ↔ y_k`` votes for the ``(log s, θ)`` of the vector ``x_h − xᵢ`` onto
  ``y_k − y_j`` in a discretized accumulator ``M_ij(s, θ)``; the pair whose accumulator has
  the highest count, and the votes in that count, give the matching.
- :func:`match_ransac`: RANSAC (Fischler and Bolles, 1981) with two-point similarity
  hypotheses, inliers within a chi-square radius, and a least-squares refit on the one-to-one
  inliers (Hungarian assignment).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from trackers.pattern.fppm import PatternMatch, checked_points, chi2_threshold, pattern_match

__all__ = ["match_ransac", "match_vote", "ransac_iterations"]

#: Largest complex array of RANSAC residuals held at once (elements).
CHUNK_ELEMENTS = 1 << 20
#: Most refits of the RANSAC winner on its one-to-one inliers.
REFITS = 4

_FAR = 1e30


def _check(
    pattern: np.ndarray, detections: np.ndarray, sigma: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    P, Q = checked_points(pattern, detections, sigma)
    return P, Q, P[:, 0] + 1j * P[:, 1], Q[:, 0] + 1j * Q[:, 1]


def _scale_range(scale_range: tuple[float, float] | None) -> tuple[float, float] | None:
    if scale_range is None:
        return None
    lo, hi = float(scale_range[0]), float(scale_range[1])
    if not (0 < lo <= hi and math.isfinite(hi)):
        raise ValueError(f"scale_range: must be 0 < lo <= hi, got {scale_range!r}")
    return lo, hi


def match_vote(
    pattern: np.ndarray,
    detections: np.ndarray,
    sigma: float,
    *,
    scale_range: tuple[float, float] | None = None,
    bins: int | None = None,
    w_min: int = 2,
) -> PatternMatch | None:
    """Chang et al.'s accumulator matching of the ``(m, 2)`` ``pattern`` to the ``(n, 2)``
    ``detections``.

    Every vote ``(i, j; h, k)``, ``h ≠ i``, ``k ≠ j``, is the complex log of the similarity
    taking ``u = x_h − xᵢ`` onto ``v = y_k − y_j``: ``log(v/u) = log(|v|/|u|) + i (arg v − arg u)``
    (noise spreads it about equally in both parts: ``δ log s ≈ δθ ≈ |δv| / |v|``). The
    accumulator ``M_ij`` has square cells of side ``Δ = 2π / bins`` on ``(log s, θ)`` (``θ``
    cyclic; ``log s`` over ``scale_range`` if given, votes outside it dropped, else over the
    votes' span). ``bins`` by default is ``2π / Δ`` with ``Δ = 4σ / median |u|`` (about ±1.4
    noise standard deviations at the median vector length), within ``[8, 96]``. A vote near a
    cell border would split, so counts are taken over 2×2 windows of cells (the four grids
    shifted by half a window). The pair ``(i, j)`` and window with the most votes give the
    matching: ``(i, j)`` and, for each ``h`` that voted in the window, the ``k`` whose vote is
    nearest the window's centre (a ``k`` claimed twice goes to the nearer vote); ties between
    windows go to the smallest MSE (at most 8 compared). Returns ``None`` when the best count
    is below ``w_min`` (the paper's support, ``p − 1``).
    """
    P, Q, Pc, Qc = _check(pattern, detections, sigma)
    scale_range = _scale_range(scale_range)
    m, n = Pc.shape[0], Qc.shape[0]
    if min(m, n) < w_min + 1:
        return None
    U = Pc[None, :] - Pc[:, None]  # U[i, h] = x_h − xᵢ
    V = Qc[None, :] - Qc[:, None]
    i_, h_ = np.nonzero(~np.eye(m, dtype=bool))
    j_, k_ = np.nonzero(~np.eye(n, dtype=bool))
    u, v = U[i_, h_], V[j_, k_]
    if (u == 0).any():
        raise ValueError("pattern: two reference points coincide")
    lu, au = np.log(np.abs(u)), np.angle(u)
    with np.errstate(divide="ignore"):
        lv = np.log(np.abs(v))  # coincident detections: −inf, dropped below
    av = np.angle(v)
    if bins is None:
        step = 4.0 * float(sigma) / float(np.median(np.abs(u)))
        bins = int(np.clip(round(2.0 * math.pi / step), 8, 96))
    if int(bins) != bins or bins < 4:
        raise ValueError(f"bins: must be an integer >= 4, got {bins!r}")
    n_t = int(bins)
    step = 2.0 * math.pi / n_t
    ls = lv[None, :] - lu[:, None]  # (pattern vectors, detection vectors)
    th = av[None, :] - au[:, None]
    finite = np.isfinite(ls)
    if scale_range is not None:
        lo_s, hi_s = math.log(scale_range[0]), math.log(scale_range[1])
        finite &= (ls >= lo_s) & (ls <= hi_s)
    else:
        lo_s = float(ls[finite].min()) if finite.any() else 0.0
        hi_s = float(ls[finite].max()) if finite.any() else 0.0
    n_s = math.floor((hi_s - lo_s) / step) + 2
    bs = np.floor((np.where(finite, ls, lo_s) - lo_s) / step).astype(np.int64)
    bt = np.floor((th + math.pi) / step).astype(np.int64) % n_t
    anchor = i_[:, None] * n + j_[None, :]  # (i, j)
    cells = n_s * n_t
    flat = np.where(finite, (anchor * n_s + bs) * n_t + bt, m * n * cells)
    M = np.bincount(flat.reshape(-1), minlength=m * n * cells + 1)[:-1]
    M = M.reshape(m * n, n_s, n_t)
    # 2×2 windows: W[b_s, b_t] = M[b_s, b_t] + M[b_s+1, b_t] + M[b_s, b_t+1] + M[b_s+1, b_t+1]
    Ms = M.copy()
    Ms[:, :-1, :] += M[:, 1:, :]
    W = Ms + np.roll(Ms, -1, axis=2)
    Wf = W.reshape(-1)
    top = int(Wf.max())
    if top < w_min:
        return None
    best: PatternMatch | None = None
    for idx in np.flatnonzero(Wf == top)[:8].tolist():
        a_idx, rem = divmod(idx, cells)
        ws, wt = divmod(rem, n_t)
        i0, j0 = divmod(a_idx, n)
        centre_s = lo_s + (ws + 1) * step
        centre_t = -math.pi + (wt + 1) * step
        rows = np.flatnonzero(i_ == i0)
        cols = np.flatnonzero(j_ == j0)
        sub_s, sub_t = bs[np.ix_(rows, cols)], bt[np.ix_(rows, cols)]
        inside = finite[np.ix_(rows, cols)] & ((sub_s == ws) | (sub_s == ws + 1))
        inside &= (sub_t == wt) | (sub_t == (wt + 1) % n_t)
        r_, c_ = np.nonzero(inside)
        if r_.shape[0] < w_min:
            continue
        dth = np.angle(np.exp(1j * (th[rows[r_], cols[c_]] - centre_t)))
        dist = (ls[rows[r_], cols[c_]] - centre_s) ** 2 + dth**2
        h_sel, k_sel = h_[rows[r_]], k_[cols[c_]]
        order = np.argsort(dist, kind="stable")
        seen_h, seen_k = {i0}, {j0}
        pairs = [(i0, j0)]
        for q in order.tolist():
            h, k = int(h_sel[q]), int(k_sel[q])
            if h not in seen_h and k not in seen_k:
                seen_h.add(h)
                seen_k.add(k)
                pairs.append((h, k))
        if len(pairs) < w_min + 1:
            continue
        try:
            match = pattern_match(P, Q, np.array(pairs))
        except ValueError:
            continue
        if (
            best is None
            or match.support > best.support
            or (match.support == best.support and match.mse < best.mse)
        ):
            best = match
    return best


def ransac_iterations(n: int, detection_probability: float = 0.9, confidence: float = 0.99) -> int:
    """Hypotheses for RANSAC to draw one all-true sample with probability ``confidence``:
    ``N = ⌈ln(1 − c) / ln(1 − q)⌉``, ``q = P_d² / (n (n − 1))`` the chance that two random
    detections are the true ones of two given pattern points; within ``[100, 20000]``."""
    q = detection_probability**2 / max(1, n * (n - 1))
    if q >= 1.0:
        return 100
    return int(np.clip(math.ceil(math.log(1.0 - confidence) / math.log1p(-q)), 100, 20000))


def _inlier_pairs(Pc: np.ndarray, Qc: np.ndarray, a: complex, T: complex, r2: float) -> np.ndarray:
    """One-to-one inliers of ``y = a x + T``: the Hungarian assignment of pattern points to
    detections on ``‖y − ŷ‖²``, pairs farther than ``r2`` (squared radius) left out."""
    E = Qc[None, :] - (a * Pc + T)[:, None]
    d2 = E.real**2 + E.imag**2
    cost = np.where(d2 <= r2, d2, _FAR)
    m = Pc.shape[0]
    # a dummy column per pattern point at the radius: leaving it unmatched costs r2
    dummy = np.full((m, m), _FAR)
    np.fill_diagonal(dummy, r2)
    rows, cols = linear_sum_assignment(np.hstack([cost, dummy]))
    keep = cols < Qc.shape[0]
    return np.stack([rows[keep], cols[keep]], axis=1).astype(np.int64)


def match_ransac(
    pattern: np.ndarray,
    detections: np.ndarray,
    sigma: float,
    *,
    scale_range: tuple[float, float] | None = None,
    iterations: int | None = None,
    rng: np.random.Generator | int | None = None,
    false_rejection: float = 0.01,
    w_min: int = 2,
) -> PatternMatch | None:
    """RANSAC matching of the ``(m, 2)`` ``pattern`` to the ``(n, 2)`` ``detections``.

    Each hypothesis draws two pattern points ``xᵢ, x_h`` and two detections ``y_j, y_k`` and
    takes the similarity through them, ``a = (y_k − y_j) / (x_h − xᵢ)``, ``T = y_j − a xᵢ``
    (skipped if ``|a|`` is outside ``scale_range``). Its inliers are the pattern points with a
    detection within ``‖y − ŷ‖² ≤ χ²₂(1 − α) σ²`` (``α`` = ``false_rejection``); the best
    hypothesis has the most, ties to the smallest MSAC cost ``Σₕ min(‖y − ŷ‖², χ²₂ σ²)``.
    Its one-to-one inliers (Hungarian assignment) are refitted by least squares (eq. 19),
    and the inliers re-found, until they stop changing (at most :data:`REFITS` times).
    ``iterations`` defaults to :func:`ransac_iterations`; ``rng`` a generator or a seed
    (``None``: seed 0, so that the result depends on the inputs only). Returns ``None`` when
    the best matching has fewer than ``w_min + 1`` pairs.
    """
    P, Q, Pc, Qc = _check(pattern, detections, sigma)
    scale_range = _scale_range(scale_range)
    m, n = Pc.shape[0], Qc.shape[0]
    if min(m, n) < w_min + 1:
        return None
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng or 0)
    N = ransac_iterations(n) if iterations is None else int(iterations)
    if N < 1:
        raise ValueError(f"iterations: must be >= 1, got {iterations!r}")
    r2 = chi2_threshold(false_rejection) * float(sigma) ** 2
    i = gen.integers(0, m, N)
    h = (i + gen.integers(1, m, N)) % m
    j = gen.integers(0, n, N)
    k = (j + gen.integers(1, n, N)) % n
    du = Pc[h] - Pc[i]
    if (du == 0).any():
        raise ValueError("pattern: two reference points coincide")
    a = (Qc[k] - Qc[j]) / du
    T = Qc[j] - a * Pc[i]
    ok = np.abs(a) > 0
    if scale_range is not None:
        s = np.abs(a)
        ok &= (s >= scale_range[0]) & (s <= scale_range[1])
    a, T = a[ok], T[ok]
    if a.shape[0] == 0:
        return None
    count = np.empty(a.shape[0], dtype=np.int64)
    cost = np.empty(a.shape[0])
    chunk = max(1, CHUNK_ELEMENTS // (m * n))
    for c0 in range(0, a.shape[0], chunk):
        c1 = min(a.shape[0], c0 + chunk)
        pred = a[c0:c1, None] * Pc[None, :] + T[c0:c1, None]
        E = Qc[None, None, :] - pred[:, :, None]
        d2 = (E.real**2 + E.imag**2).min(axis=2)
        count[c0:c1] = np.count_nonzero(d2 <= r2, axis=1)
        cost[c0:c1] = np.minimum(d2, r2).sum(axis=1)
    best = int(np.lexsort((cost, -count))[0])
    a_b, T_b = complex(a[best]), complex(T[best])
    pairs = _inlier_pairs(Pc, Qc, a_b, T_b, r2)
    for _ in range(REFITS):
        if pairs.shape[0] < max(3, w_min + 1):
            return None
        match = pattern_match(P, Q, pairs)
        G = match.registration
        a_b = G.s * complex(math.cos(G.theta), math.sin(G.theta))
        T_b = complex(G.t[0], G.t[1])
        new = _inlier_pairs(Pc, Qc, a_b, T_b, r2)
        if np.array_equal(new, pairs):
            break
        pairs = new
    if pairs.shape[0] < max(3, w_min + 1):
        return None
    match = pattern_match(P, Q, pairs)
    if scale_range is not None and not (scale_range[0] <= match.registration.s <= scale_range[1]):
        return None
    return match
