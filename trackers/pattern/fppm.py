"""Fast point-pattern matching with a chi-square similarity test (paper 000, section 4.3).

The reference pattern ``𝒫 = {xᵢ}`` (``m`` points, the target's shape) is matched to the
detections ``𝒬 = {y_j}`` (``n`` points) under an unknown similarity ``y = s R(θ) x + T``
(:mod:`trackers.pattern.registration`) with detection noise ``b ~ N(0, σ² I)`` (eq. 14),
missed points and clutter. A *matching* is a one-to-one set of ``p`` pairs ``(i, j)``; its
*support* in the paper's sense is ``w = p − 1``, the pairs that agree with one of them.

Points are handled as complex numbers ``x = x¹ + i x²``: the similarity is then the affine map
``y = a x + T`` with ``a = s e^{iθ}`` (the paper's ``a = [s cos θ, s sin θ]'`` of eq. 17), and
``A_x' a`` of eqs. 31-39 is the product ``x a``. Noise ``b`` is circular complex Gaussian with
``E|b|² = 2σ²``; a squared modulus divided by ``σ²`` is a chi-square with 2 degrees of freedom.

**Similarity test (section 4.3.2, case 2; eqs. 34-39).** For an anchor pair ``(xᵢ, y_j)``
the vectors ``u_h = x_h − xᵢ`` and ``v_k = y_k − y_j`` satisfy ``v_k = a u_h + b_k − b_j``
(eq. 20): the noises share ``b_j``, ``cov = σ² (I_N + 1 1') ⊗ I`` (eq. 37). Its
triangularization ``L D L'`` (eq. 38) has ``L_{ik} = 1/(k+1)``, ``D_i = (i+1)/i σ²``, and
``L⁻¹`` has entries ``−1/i`` in row ``i`` (*not* ``−1/(k+1)``: the printed
``T_i⁻¹ = A'_{x_i} − Σ_{k<i} A'_{x_k}/(k+1)`` is garbled or wrong; we checked ``L⁻¹``
numerically), so the decorrelated vectors are

    z̃ᵢ = vᵢ − (1/i) Σ_{k<i} v_k ~ N(tᵢ a, (i+1)/i σ²),    tᵢ = uᵢ − (1/i) Σ_{k<i} u_k,

independent. Eq. 36 with ``αᵢ = tᵢ``, ``Pᵢ = Dᵢ`` is the normalized innovation of the new
vector given the cluster's GLS estimate of ``a``. Working the sums out, it is the same as the
innovation of the new *point* given the least-squares similarity fitted to the cluster's
``N`` points, anchor included (the common ``b_j`` is exactly what the free translation
absorbs):

    ε = |y_new − â x_new − T̂|² / (σ² (1 + 1/N + |x_new − x̄|² / Sₓₓ)) ~ χ²₂   under H₀,

``x̄`` the cluster points' mean, ``Sₓₓ = Σ |x − x̄|²``. :func:`similarity_statistic` computes
this form (no ``O(N²)`` matrices, no division by the new vector). The paper's test is two-sided
(``ε ∈ [r₁, r₂]``); here ``H₀`` is rejected only for ``ε > χ²₂(1 − α) = −2 ln α``. A small
``ε`` (too good a fit) is no evidence against a match, and a lower bound would reject every
noise-free match; the stated false-rejection rate ``α`` then holds exactly.

**CMPSF (section 4.3.3) and FPPM (section 4.3.4)**, as implemented by :func:`match_fppm`:

- The FPPM scans the anchors ``(i, j)`` row by row (``i`` in pattern order). A matching is
  found in full from the row of its *smallest* pattern index, so row ``i`` looks only at
  pattern points ``h > i``: this is the paper's match-flag pruning taken to its limit (every
  ``Mflag(h, k)``, ``h < i``, cleared), exact for the maximum support, and it is why the
  paper's exit "``w* ≥ min(m, n) − i``" holds. Both early exits are kept (``w_max``; no later
  row can reach ``w*``). ``mflag`` is the flag array as a prior (``False`` = cannot match).
- CMPSF for anchor ``(i, j)``, vectorized over all ``j`` of the row and all candidate pairs:
  the paper grows clusters by visiting the candidate pairs in an arbitrary order, so its
  result depends on that order. Here every candidate pair ``(h, k)`` *seeds* a cluster
  ``{(i, j), (h, k)}`` and is scored, for each pattern point ``h' > h``, by the nearest
  detection ``k'`` under the case-2 test against that two-pair cluster (``N = 2``:
  ``1 + 1/N + … = 3/2 + 2 |u_{h'} − u_h/2|² / |u_h|²``): its count of passing ``h'`` (the
  paper's support of the cluster) and its MSAC cost ``Σ_{h'} min(ε, γ)``. The seed of a
  matching's full cluster is its second-smallest pattern index.
- The :data:`MAX_GROWN` seeds of smallest cost among those whose count can reach the best
  support so far are then grown as the paper's clusters grow, with the estimate updated:
  refit the similarity (GLSE), test every pattern point outside the cluster with every
  unused detection, add the pair of smallest ``ε`` if it passes, repeat. Each pair is tested
  once, against the cluster before it joined (the paper's test; re-testing members would
  reject true pairs a second time). The support ``w`` is the grown cluster's size minus one;
  ties go to the smallest MSE (eq. 16), as section 4.3.3 asks.
- Greedy growth can swap two detections; the winner is re-associated once (Hungarian, same
  test against the whole matching) and the result kept if it has more pairs or a smaller
  MSE. (The paper's FPPM ends with the best conditional matching as is.)
- ``scale_range``: seeds whose scale ``|v_k| / |u_h|`` is outside the range by more than the
  test's noise allowance, and grown clusters whose fitted ``s`` is outside it, support nothing.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from trackers.pattern.registration import Similarity, fit_similarity

__all__ = [
    "PatternMatch",
    "checked_points",
    "chi2_threshold",
    "match_fppm",
    "pattern_match",
    "similar",
    "similarity_statistic",
]

#: Most grown clusters per row of anchors (the best seeds first).
MAX_GROWN = 8
#: Largest complex array of stage-one distances held at once (elements).
CHUNK_ELEMENTS = 1 << 20

_FAR = 1e30
_FAR32 = 1e12  # far, yet squares stay finite in float32


@dataclass(frozen=True)
class PatternMatch:
    """A one-to-one matching of pattern points to detections and its registration.

    ``pairs`` ``(p, 2)`` int64 rows ``(i, j)``: pattern point ``i`` ↔ detection ``j``, sorted by
    ``i``; ``registration`` the similarity fitted on the pairs (:func:`fit_similarity`);
    ``mse`` the mean of ``‖y_j − G(xᵢ)‖²`` over the pairs (eq. 16 with ``P_bb = I``).
    """

    pairs: np.ndarray
    registration: Similarity
    mse: float

    @property
    def support(self) -> int:
        """``p``, the number of pairs (the paper's support ``w`` is ``p − 1``)."""
        return int(self.pairs.shape[0])


def pattern_match(pattern: np.ndarray, detections: np.ndarray, pairs: np.ndarray) -> PatternMatch:
    """The :class:`PatternMatch` of the given one-to-one ``pairs`` ``(p, 2)``, ``p ≥ 2``: sorts
    them by pattern index, fits the similarity (eq. 19) and computes the MSE (eq. 16)."""
    P = np.asarray(pattern, dtype=float).reshape(-1, 2)
    Q = np.asarray(detections, dtype=float).reshape(-1, 2)
    pr = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    pr = pr[np.argsort(pr[:, 0], kind="stable")]
    if (np.diff(pr[:, 0]) == 0).any() or len(np.unique(pr[:, 1])) != len(pr):
        raise ValueError("pairs: must be one-to-one")
    return _match(P, Q, pr)


def _match(P: np.ndarray, Q: np.ndarray, pr: np.ndarray) -> PatternMatch:
    """:func:`pattern_match` of one-to-one ``pairs`` already sorted by pattern index."""
    x = np.take(P, pr[:, 0], axis=0)
    y = np.take(Q, pr[:, 1], axis=0)
    G = fit_similarity(x, y)
    r = y - G.apply(x)
    mse = float(np.vdot(r, r)) / pr.shape[0]
    pr.setflags(write=False)
    return PatternMatch(pr, G, mse)


def chi2_threshold(false_rejection: float) -> float:
    """The ``1 − α`` quantile of the chi-square with 2 degrees of freedom,
    ``χ²₂(1 − α) = −2 ln α`` (its CDF is ``1 − e^{−ε/2}``), ``α`` = ``false_rejection``."""
    if not (0.0 < false_rejection < 1.0):
        raise ValueError(f"false_rejection: must be in (0, 1), got {false_rejection!r}")
    return -2.0 * math.log(false_rejection)


def similarity_statistic(
    x_cluster: np.ndarray,
    y_cluster: np.ndarray,
    x_new: np.ndarray,
    y_new: np.ndarray,
    sigma: float,
) -> np.ndarray:
    """The chi-square statistic ``ε`` of eq. 36 (case 2, correlated vectors) that the pair
    ``(x_new, y_new)`` belongs to the cluster of pairs ``(x_cluster, y_cluster)``.

    ``x_cluster``, ``y_cluster`` ``(..., N, 2)`` with ``N ≥ 2``: the anchor pair and the
    cluster's ``N − 1`` pairs (the cluster's vectors are taken from the anchor; any of the
    ``N`` points may be the anchor, ``ε`` does not depend on which); ``x_new``, ``y_new``
    ``(..., 2)``; ``sigma`` the per-axis detection noise. With ``â``, ``T̂`` the least-squares
    similarity of the cluster (complex form ``y = a x + T``),

        ε = |y_new − â x_new − T̂|² / (σ² (1 + 1/N + |x_new − x̄|² / Sₓₓ)),

    which equals eq. 36 after the decorrelation of eqs. 38-39 (see the module docstring);
    ``ε ~ χ²₂`` when all the pairs follow one similarity with noise ``σ``. Shape ``(...)``.
    """
    xc = np.asarray(x_cluster, dtype=float)
    yc = np.asarray(y_cluster, dtype=float)
    if xc.shape[-1] != 2 or yc.shape != xc.shape or xc.ndim < 2 or xc.shape[-2] < 2:
        raise ValueError(f"x_cluster, y_cluster: must be (..., N >= 2, 2), got {xc.shape}")
    if not (math.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma: must be a finite number > 0, got {sigma!r}")
    X = xc[..., 0] + 1j * xc[..., 1]
    Y = yc[..., 0] + 1j * yc[..., 1]
    xn = np.asarray(x_new, dtype=float)
    yn = np.asarray(y_new, dtype=float)
    Xn = xn[..., 0] + 1j * xn[..., 1]
    Yn = yn[..., 0] + 1j * yn[..., 1]
    N = X.shape[-1]
    xm = X.mean(axis=-1)
    ym = Y.mean(axis=-1)
    Xc = X - xm[..., None]
    Sxx = np.sum(Xc.real**2 + Xc.imag**2, axis=-1)
    if (Sxx <= 0).any():
        raise ValueError("x_cluster: the cluster's pattern points coincide")
    a = np.sum(np.conj(Xc) * (Y - ym[..., None]), axis=-1) / Sxx
    e = Yn - (ym + a * (Xn - xm))
    d = Xn - xm
    lev = 1.0 + 1.0 / N + (d.real**2 + d.imag**2) / Sxx
    return (e.real**2 + e.imag**2) / (sigma * sigma * lev)


def similar(
    x_cluster: np.ndarray,
    y_cluster: np.ndarray,
    x_new: np.ndarray,
    y_new: np.ndarray,
    sigma: float,
    false_rejection: float = 0.01,
) -> np.ndarray:
    """The similarity test of section 4.3.2: accept ``H₀`` ("the new pair and the cluster follow
    the same similarity") when ``ε ≤ χ²₂(1 − α)`` (:func:`similarity_statistic`,
    :func:`chi2_threshold`); a true ``H₀`` is rejected with probability ``α``. Boolean ``(...)``."""
    eps = similarity_statistic(x_cluster, y_cluster, x_new, y_new, sigma)
    return eps <= chi2_threshold(false_rejection)


def _complex(a: np.ndarray) -> np.ndarray:
    return a[:, 0] + 1j * a[:, 1]


@functools.lru_cache(maxsize=64)
def _off_diagonal(n: int) -> np.ndarray:
    """``(n, n)`` boolean, ``True`` off the diagonal (read-only)."""
    out = ~np.eye(n, dtype=bool)
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=256)
def _seed_pairs(r: int, w_min: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Seed ``h`` and candidate ``h' > h`` of each pair (indices among the ``r`` pattern points
    above the anchor; a seed needs ``w_min − 1`` candidates), grouped by ``h``: ``(ph, ph2)``,
    each group's first pair and its ``h``."""
    ph, ph2 = np.triu_indices(r, 1)
    keep = ph <= r - w_min
    ph, ph2 = ph[keep], ph2[keep]
    starts = np.flatnonzero(np.r_[True, ph[1:] != ph[:-1]]) if ph.size else ph
    out = (ph, ph2, starts, ph[starts])
    for arr in out:
        arr.setflags(write=False)
    return out


def _row_seeds(
    Pc: np.ndarray,
    V: np.ndarray,
    i: int,
    sigma2: float,
    gamma: float,
    w_min: int,
    w_floor: int,
    scale_range: tuple[float, float] | None,
    mflag: np.ndarray | None,
) -> np.ndarray:
    """Stage one of the CMPSF for every anchor ``(i, j)`` of row ``i``: every seed ``(h, k)``,
    ``h > i``, and the nearest passing detection of every ``h' > h``. Returns the seed
    clusters ``{(i, j), (h, k)}`` worth growing, as ``(K, m)`` assignments (detection index
    or −1), by increasing MSAC cost ``Σ_{h'} min(ε, γ)`` of their two-pair model (``γ`` for
    the pattern points between ``i`` and ``h``, which the seed assumes missed)."""
    m, n = Pc.shape[0], V.shape[0]
    U = Pc[i + 1 :] - Pc[i]  # u_h, h > i
    r = U.shape[0]
    need = max(w_min, w_floor)  # the support worth growing: ties with the best so far
    ph, ph2, starts, seeds_h = _seed_pairs(r, need)
    if ph.shape[0] == 0:
        return np.empty((0, m), dtype=np.intp)
    Uh, Uh2 = U[ph], U[ph2]
    ratio = (Uh2 / Uh).astype(np.complex64)  # predicted v_{k'} = v_k · u_{h'} / u_h
    d = Uh2 - 0.5 * Uh
    lev = 1.5 + 2.0 * (d.real**2 + d.imag**2) / (Uh.real**2 + Uh.imag**2)
    thr = (gamma * sigma2 * lev).astype(np.float32)  # ε ≤ γ ⇔ |v_{k'} − â u_{h'}|² ≤ thr
    # pairs (h, k) that may match given the anchor (i, j): k ≠ j, flags, scale
    valid = np.broadcast_to(_off_diagonal(n)[:, None, :], (n, r, n))
    if scale_range is not None:
        absU = np.abs(U)
        slack = math.sqrt(gamma * 2.0 * sigma2)
        absV = np.abs(V)[:, None, :]
        valid = valid & (absV >= (scale_range[0] * absU - slack)[None, :, None])
        valid = valid & (absV <= (scale_range[1] * absU + slack)[None, :, None])
    if mflag is not None:
        valid = valid & mflag[i + 1 :][None, :, :] & mflag[i][:, None, None]
    # each (j, h)'s valid k, first, padded to L with a far point
    cnt = valid.sum(axis=2)
    L = int(cnt.max())
    if L == 0:
        return np.empty((0, m), dtype=np.intp)
    idx = np.argsort(~valid, axis=2, kind="stable")[:, :, :L]  # (j, h, l) → k
    pad = np.arange(L)[None, None, :] >= cnt[:, :, None]
    Vs = np.take_along_axis(V, idx.reshape(n, r * L), axis=1).reshape(n, r, L)
    Vs = np.where(pad, _FAR32, Vs).astype(np.complex64)
    pred = Vs[:, ph, :] * ratio[None, :, None]  # (j, c, l): seeds' predictions
    E = Vs[:, ph2, None, :] - pred[:, :, :, None]  # (j, c, l, l')
    D = E.real * E.real
    D += E.imag * E.imag
    dmin = D.min(axis=3)
    # the seed's own detection k is among the candidates of h', at |v_k|² |1 − u_{h'}/u_h|²;
    # when that is in the gate and is the nearest, it is no hit (k' ≠ k)
    own = np.abs(ratio - 1.0) ** 2
    Vh = Vs[:, ph, :]
    own_d = (Vh.real * Vh.real + Vh.imag * Vh.imag) * own[None, :, None]
    eps = dmin * (gamma / thr)[None, :, None]
    hit = (eps <= gamma) & ~((own_d <= thr[None, :, None]) & (dmin >= own_d * (1.0 - 1e-4)))
    cost = np.minimum(eps, gamma)
    count = np.add.reduceat(hit.astype(np.int32), starts, axis=1) + 1  # (j, H, l): w
    count *= ~pad[:, seeds_h, :]
    flat = count.reshape(-1)
    sel = np.flatnonzero(flat >= need)
    if sel.shape[0] == 0:
        return np.empty((0, m), dtype=np.intp)
    msac = np.add.reduceat(cost, starts, axis=1) + (gamma * seeds_h)[None, :, None]
    order = np.argsort(msac.reshape(-1)[sel], kind="stable")[:MAX_GROWN]
    sel = sel[order]
    H = seeds_h.shape[0]
    jj, hg, ll = np.unravel_index(sel, (n, H, L))
    K = sel.shape[0]
    asg = np.full((K, m), -1, dtype=np.intp)
    asg[:, i] = jj
    asg[np.arange(K), i + 1 + seeds_h[hg]] = idx[jj, seeds_h[hg], ll]
    return asg


def _pair_terms(Pc: np.ndarray, Qc: np.ndarray) -> np.ndarray:
    """Per pair ``(h, k)``, row ``h n + k``: ``[1, x, |x|², y, x* y, |y|²]`` (complex), the
    terms whose sums over a cluster give its least-squares similarity."""
    m, n = Pc.shape[0], Qc.shape[0]
    terms = np.empty((m, n, 6), dtype=complex)
    terms[..., 0] = 1.0
    terms[..., 1] = Pc[:, None]
    terms[..., 2] = (Pc.real**2 + Pc.imag**2)[:, None]
    terms[..., 3] = Qc[None, :]
    terms[..., 4] = np.conj(Pc)[:, None] * Qc[None, :]
    terms[..., 5] = (Qc.real**2 + Qc.imag**2)[None, :]
    return terms.reshape(m * n, 6)


def _grow(
    Pc: np.ndarray,
    Qc: np.ndarray,
    asg: np.ndarray,
    sigma2: float,
    gamma: float,
    scale_range: tuple[float, float] | None,
    mflag: np.ndarray | None,
    terms: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grow the ``(K, m)`` seed clusters ``asg`` (detection index or −1; two pairs each) as
    the paper's clusters grow, one pair at a time with the estimate updated: refit the
    similarity to the cluster (eq. 19), test every pattern point outside it with every unused
    detection (:func:`similarity_statistic`'s ``ε``), add the pair of smallest ``ε`` if
    ``ε ≤ γ``, and repeat until none passes. Each pair is thus tested once, against the
    cluster as it was before it joined, as in section 4.3.3 (the order is by evidence
    instead of by index).

    The fits come from running sums (points centred beforehand): ``x̄ = Σx / p``,
    ``Sₓₓ = Σ|x|² − p|x̄|²``, ``Sₓᵧ = Σ x* y − p x̄* ȳ``, ``a = Sₓᵧ / Sₓₓ``,
    ``ŷ = ȳ + a (x − x̄)``, and the residual sum ``Σ|y − ŷ|² = Σ|y|² − p|ȳ|² − |Sₓᵧ|² / Sₓₓ``.
    Returns the final clusters, their sizes ``p`` (0 for one out of ``scale_range``) and
    their MSEs (eq. 16).
    """
    K, m = asg.shape
    n = Qc.shape[0]
    asg = asg.copy()
    rows = np.arange(K)
    if terms is None:
        terms = _pair_terms(Pc, Qc)
    member = asg >= 0
    r_, h_ = np.nonzero(member)
    flat_idx = np.arange(m) * n + np.maximum(asg, 0)
    stats = np.einsum("khc,kh->kc", np.take(terms, flat_idx, axis=0), member.astype(complex))
    block = np.zeros((K, m, n))
    block[member] = _FAR  # members are not candidates …
    block[r_, :, asg[r_, h_]] = _FAR  # … nor are their detections
    if mflag is not None:
        block += np.where(mflag, 0.0, _FAR)[None]
    block_flat = block.reshape(K, m * n)
    Qv = Qc.view(float).reshape(1, 1, n, 2)
    lev0 = np.empty((K, m))
    active = np.ones(K, dtype=bool)
    for _ in range(m - 2):
        p, sx, sxx, sy, sxy = (
            stats[:, 0].real,
            stats[:, 1],
            stats[:, 2].real,
            stats[:, 3],
            stats[:, 4],
        )
        xm, ym = sx / p, sy / p
        S = sxx - (sx.real * xm.real + sx.imag * xm.imag)
        a = (sxy - np.conj(sx) * ym) / S
        Xc = Pc[None, :] - xm[:, None]
        pred = (ym[:, None] + a[:, None] * Xc).view(float).reshape(K, m, 1, 2)
        X2 = Xc.view(float).reshape(K, m, 2)
        # ε = |y_k − ŷ_h|² / (σ² (1 + 1/p + |x_h − x̄|² / Sₓₓ))
        np.einsum("khi,khi->kh", X2, X2, out=lev0)
        lev0 /= S[:, None]
        lev0 += (1.0 + 1.0 / p)[:, None]
        E = Qv - pred
        D = np.einsum("khni,khni->khn", E, E)
        D /= (sigma2 * lev0)[:, :, None]
        flat = D.reshape(K, m * n)
        flat += block_flat
        best = flat.argmin(axis=1)
        active &= flat[rows, best] <= gamma
        if not active.any():
            break
        stats += np.take(terms, best, axis=0) * active[:, None]
        g, k = np.divmod(best, n)
        r_, g_, k_ = rows[active], g[active], k[active]
        asg[r_, g_] = k_
        block[r_, g_, :] = _FAR
        block[r_, :, k_] = _FAR
    p, sx, sxx, sy, sxy = stats[:, 0].real, stats[:, 1], stats[:, 2].real, stats[:, 3], stats[:, 4]
    syy = stats[:, 5].real
    xm, ym = sx / p, sy / p
    S = sxx - (sx.real * xm.real + sx.imag * xm.imag)
    Sxy = sxy - np.conj(sx) * ym
    rss = syy - (sy.real * ym.real + sy.imag * ym.imag) - (Sxy.real**2 + Sxy.imag**2) / S
    alive = p >= 3
    if scale_range is not None:
        s = np.abs(Sxy) / S
        alive &= (s >= scale_range[0]) & (s <= scale_range[1])
    return asg, np.where(alive, p, 0).astype(np.intp), np.maximum(rss, 0.0) / p


def checked_points(
    pattern: np.ndarray, detections: np.ndarray, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """``pattern (m, 2)`` and ``detections (n, 2)`` as float arrays, after checking their
    shapes, that they are finite, and that the noise ``sigma`` is a finite number > 0: the
    inputs every matcher takes. Raises ``ValueError`` naming what is wrong."""
    P = np.asarray(pattern, dtype=float)
    Q = np.asarray(detections, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2 or Q.ndim != 2 or Q.shape[1] != 2:
        raise ValueError(f"pattern, detections: must be (m, 2), (n, 2), got {P.shape}, {Q.shape}")
    if not (np.isfinite(P).all() and np.isfinite(Q).all()):
        raise ValueError("pattern, detections: must be finite")
    if not (math.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma: must be a finite number > 0, got {sigma!r}")
    return P, Q


def match_fppm(
    pattern: np.ndarray,
    detections: np.ndarray,
    sigma: float,
    *,
    scale_range: tuple[float, float] | None = None,
    w_min: int = 2,
    w_max: int | None = None,
    false_rejection: float = 0.01,
    mflag: np.ndarray | None = None,
) -> PatternMatch | None:
    """The FPPM (section 4.3.4) with the chi-square CMPSF (section 4.3.3): the one-to-one
    matching of largest support ``w = p − 1`` (``p`` pairs) of the ``(m, 2)`` ``pattern`` to the
    ``(n, 2)`` ``detections`` under one similarity, ties to the smallest MSE (eq. 16).

    ``sigma`` the per-axis detection noise standard deviation; ``false_rejection`` the
    similarity test's ``α`` (threshold ``χ²₂(1 − α)``); ``scale_range`` ``(s_lo, s_hi)``: only
    registrations with ``s`` in it; ``w_min`` (≥ 2) the paper's least support, a match has
    ``p ≥ w_min + 1`` pairs; ``w_max`` stop scanning once a support ``w ≥ w_max`` is found;
    ``mflag`` an optional ``(m, n)`` boolean prior, ``False`` where ``xᵢ`` cannot match ``y_j``.
    Returns ``None`` when no matching has support ``w ≥ w_min``. Algorithm and departures from
    the paper: see the module docstring.
    """
    P, Q = checked_points(pattern, detections, sigma)
    if int(w_min) != w_min or w_min < 2:
        raise ValueError(f"w_min: must be an integer >= 2, got {w_min!r}")
    w_min = int(w_min)
    if scale_range is not None:
        lo, hi = float(scale_range[0]), float(scale_range[1])
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise ValueError(f"scale_range: must be 0 < lo <= hi, got {scale_range!r}")
        scale_range = (lo, hi)
    gamma = chi2_threshold(false_rejection)
    m, n = P.shape[0], Q.shape[0]
    if mflag is not None:
        mflag = np.asarray(mflag, dtype=bool)
        if mflag.shape != (m, n):
            raise ValueError(f"mflag: must be ({m}, {n}), got {mflag.shape}")
    if min(m, n) < w_min + 1:
        return None
    Pc, Qc = _complex(P), _complex(Q)
    Pc, Qc = Pc - Pc.mean(), Qc - Qc.mean()  # centred: the fits' sums do not cancel
    dP = Pc[:, None] - Pc[None, :]
    if np.count_nonzero(dP == 0) > m:
        raise ValueError("pattern: two reference points coincide")
    V = Qc[None, :] - Qc[:, None]  # V[j, k] = y_k − y_j
    sigma2 = float(sigma) ** 2
    best_w, best_mse, best_asg = -1, math.inf, None
    terms = _pair_terms(Pc, Qc)
    for i in range(m - w_min):  # rows with at least w_min points above them
        # no matching whose smallest pattern index is ≥ i has more than min(m − i, n) pairs
        if best_w > min(m - i, n) - 1 or (w_max is not None and best_w >= w_max):
            break
        init = _row_seeds(Pc, V, i, sigma2, gamma, w_min, best_w, scale_range, mflag)
        if init.shape[0] == 0:
            continue
        asg, p, mse = _grow(Pc, Qc, init, sigma2, gamma, scale_range, mflag, terms)
        w = p - 1
        top = int(w.max())
        if top < w_min:
            continue
        cand = np.flatnonzero(w == top)
        k = int(cand[np.argmin(mse[cand])])
        if top > best_w or (top == best_w and mse[k] < best_mse):
            best_w, best_mse, best_asg = top, float(mse[k]), asg[k]
    if best_asg is None or best_w < w_min:
        return None
    i_idx = np.flatnonzero(best_asg >= 0)
    match = _match(P, Q, np.stack([i_idx, best_asg[i_idx]], axis=1).astype(np.int64))
    return _reassociate(P, Q, match, sigma2, gamma, scale_range, mflag)


def _reassociate(
    P: np.ndarray,
    Q: np.ndarray,
    match: PatternMatch,
    sigma2: float,
    gamma: float,
    scale_range: tuple[float, float] | None,
    mflag: np.ndarray | None,
) -> PatternMatch:
    """Undo the greedy growth's swaps: under the winner's registration, the one-to-one
    assignment (Hungarian) of all pattern points to detections minimizing ``Σ min(ε, γ)``
    with ``ε = ‖y_k − G(x_h)‖² / (σ² (1 + ℓ_h))`` (the test of a point against the matching;
    ``ℓ_h`` its leverage); kept when it has more pairs, or as many and a smaller MSE."""
    for _ in range(3):
        x = np.take(P, match.pairs[:, 0], axis=0)
        xm = x.mean(axis=0)
        Sxx = float(np.vdot(x - xm, x - xm))
        d = P - xm
        lev = 1.0 / match.support + np.einsum("ij,ij->i", d, d) / Sxx
        E = Q[None, :, :] - match.registration.apply(P)[:, None, :]
        eps = np.einsum("hki,hki->hk", E, E) / (sigma2 * (1.0 + lev))[:, None]
        cost = np.where(eps <= gamma, eps, _FAR)
        if mflag is not None:
            cost = np.where(mflag, cost, _FAR)
        m, n = cost.shape
        near = cost.argmin(axis=1)
        mine = np.full(m, -1)
        mine[match.pairs[:, 0]] = match.pairs[:, 1]
        if np.array_equal(np.where(cost[np.arange(m), near] < gamma, near, -1), mine):
            break  # every point at its nearest passing detection, all distinct: optimal
        dummy = np.full((m, m), _FAR)
        np.fill_diagonal(dummy, gamma)
        rows, cols = linear_sum_assignment(np.hstack([cost, dummy]))
        keep = cols < n
        pairs = np.stack([rows[keep], cols[keep]], axis=1).astype(np.int64)
        if pairs.shape[0] < 3 or np.array_equal(pairs, match.pairs):
            break
        new = _match(P, Q, pairs)
        if scale_range is not None and not (scale_range[0] <= new.registration.s <= scale_range[1]):
            break
        if new.support < match.support or (new.support == match.support and new.mse >= match.mse):
            break
        match = new
    return match
