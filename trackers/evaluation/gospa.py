"""GOSPA and OSPA distances between a set of true positions and a set of estimates.

Both metrics compare two finite sets ``X = {x_1..x_n}`` (truth) and ``Y = {y_1..y_m}``
(estimates) of points in ℝ^d with the base distance ``d(x, y) = ‖x − y‖₂`` cut off at
``c``: ``d^(c)(x, y) = min(d(x, y), c)``.

- :func:`gospa`: generalised OSPA (Rahmathullah, García-Fernández and Svensson, "Generalized
  optimal sub-pattern assignment metric", FUSION 2017). Not normalised by the set size, so it
  grows with the number of localisation errors, missed targets and false tracks.
- :func:`ospa`: optimal sub-pattern assignment (Schuhmacher, Vo and Vo, "A consistent metric
  for performance evaluation of multi-object filters", IEEE TSP 2008), normalised by
  ``max(n, m)``.

Optimal assignments come from ``scipy.optimize.linear_sum_assignment``. Neither function
modifies its inputs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from trackers.types import TrackSnapshot

__all__ = ["GospaResult", "gospa", "ospa", "track_positions"]


@dataclass(frozen=True, eq=False)
class GospaResult:
    """The GOSPA distance and its decomposition.

    Attributes
    ----------
    distance : the GOSPA distance ``d_p^(c,α)(X, Y)``.
    localisation : ``(Σ_{(i,j)∈γ} d(x_i, y_j)^p)^(1/p)`` over the assigned pairs ``γ``
        (pairs of the optimal assignment closer than ``c``), i.e. the localisation term in the
        same p-th-root form as the distance.
    missed : number of true points left unassigned (missed targets).
    false : number of estimates left unassigned (false tracks).
    assignment : ``(n,)`` int array, the estimate index assigned to each true point, or -1.

    For ``α = 2``: ``distance^p = localisation^p + c^p/2 · (missed + false)``. For other α the
    optimal assignment is forced to pair ``min(n, m)`` points, and
    ``distance^p = localisation^p + c^p · k + c^p/α · |n − m|`` where
    ``k = min(n, m) − len(γ)`` is the number of forced pairs at distance ≥ ``c`` (those are
    still reported as one missed target and one false track each).
    """

    distance: float
    localisation: float
    missed: int
    false: int
    assignment: np.ndarray


def _points(a: np.ndarray, dim: int | None = None) -> np.ndarray:
    """``a`` as a float ``(k, d)`` array; an empty input becomes ``(0, dim)``."""
    arr = np.asarray(a, dtype=float)
    if arr.size == 0:
        width = arr.shape[-1] if arr.ndim == 2 else (dim if dim is not None else 2)
        return np.empty((0, width))
    if arr.ndim == 1:
        arr = arr[np.newaxis, :]
    if arr.ndim != 2:
        raise ValueError(f"points must be a (k, d) array, got shape {arr.shape}")
    return arr


def _pair(truth: np.ndarray, estimates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    X = _points(truth)
    Y = _points(estimates, X.shape[1])
    if X.size == 0 and Y.size > 0:
        X = np.empty((0, Y.shape[1]))
    if X.shape[1] != Y.shape[1]:
        raise ValueError(f"truth is {X.shape[1]}-dimensional, estimates {Y.shape[1]}-dimensional")
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Y))):
        raise ValueError("points must be finite")
    return X, Y


def _distances(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """``(n, m)`` Euclidean distances ``D_ij = ‖x_i − y_j‖₂``."""
    return np.sqrt(np.sum((X[:, np.newaxis, :] - Y[np.newaxis, :, :]) ** 2, axis=-1))


def _check(c: float, p: float) -> None:
    if not (math.isfinite(c) and c > 0):
        raise ValueError(f"c must be a finite number > 0, got {c!r}")
    if not (math.isfinite(p) and p >= 1):
        raise ValueError(f"p must be a finite number >= 1, got {p!r}")


def gospa(
    truth: np.ndarray, estimates: np.ndarray, c: float, p: float = 2.0, alpha: float = 2.0
) -> GospaResult:
    """GOSPA distance between true positions ``truth`` ``(n, d)`` and ``estimates`` ``(m, d)``.

    For ``n ≤ m`` (the definition is symmetric otherwise), with ``1 ≤ p < ∞``, ``c > 0`` and
    ``0 < α ≤ 2``::

        d_p^(c,α)(X, Y) = ( min_{π ∈ Π_m} Σ_{i=1}^{n} d^(c)(x_i, y_π(i))^p
                            + c^p/α · (m − n) )^(1/p)

    where ``Π_m`` is the set of permutations of ``{1..m}`` and ``d^(c) = min(d, c)``.
    For ``α = 2`` this equals the assignment-set form

        d = ( min_γ Σ_{(i,j)∈γ} d(x_i, y_j)^p + c^p/2 · (n + m − 2|γ|) )^(1/p)

    over partial one-to-one assignments ``γ``: a localisation cost plus ``c^p/2`` per missed
    target and per false estimate. Empty sets are allowed (both empty gives 0).

    The assignment minimising ``Σ min(D_ij, c)^p`` is found with
    ``linear_sum_assignment``; its pairs with ``D_ij < c`` form ``γ`` (see
    :class:`GospaResult` for the decomposition).
    """
    _check(c, p)
    if not (math.isfinite(alpha) and 0 < alpha <= 2):
        raise ValueError(f"alpha must be in (0, 2], got {alpha!r}")
    X, Y = _pair(truth, estimates)
    n, m = X.shape[0], Y.shape[0]
    assignment = np.full(n, -1, dtype=np.intp)
    if n == 0 or m == 0:
        total = c**p / alpha * (n + m)
        return GospaResult(float(total ** (1.0 / p)), 0.0, n, m, assignment)
    D = _distances(X, Y)
    cost = np.minimum(D, c) ** p
    rows, cols = linear_sum_assignment(cost)
    total = float(np.sum(cost[rows, cols])) + c**p / alpha * abs(n - m)
    close = D[rows, cols] < c
    rows, cols = rows[close], cols[close]
    assignment[rows] = cols
    localisation = float(np.sum(D[rows, cols] ** p)) ** (1.0 / p)
    kept = int(rows.size)
    return GospaResult(float(total ** (1.0 / p)), localisation, n - kept, m - kept, assignment)


def ospa(truth: np.ndarray, estimates: np.ndarray, c: float, p: float = 2.0) -> float:
    """OSPA distance between ``truth`` ``(n, d)`` and ``estimates`` ``(m, d)``.

    For ``n ≤ m`` (symmetric otherwise), ``1 ≤ p < ∞``, ``c > 0``::

        d_p^(c)(X, Y) = ( 1/m · ( min_{π ∈ Π_m} Σ_{i=1}^{n} d^(c)(x_i, y_π(i))^p
                                  + c^p · (m − n) ) )^(1/p)

    with ``d^(c) = min(d, c)``; 0 if both sets are empty, ``c`` if exactly one is. It relates
    to GOSPA by ``ospa^p · max(n, m) = gospa(α=1)^p``.
    """
    _check(c, p)
    X, Y = _pair(truth, estimates)
    n, m = X.shape[0], Y.shape[0]
    big = max(n, m)
    if big == 0:
        return 0.0
    if n == 0 or m == 0:
        return float(c)
    cost = np.minimum(_distances(X, Y), c) ** p
    rows, cols = linear_sum_assignment(cost)
    total = float(np.sum(cost[rows, cols])) + c**p * abs(n - m)
    return float((total / big) ** (1.0 / p))


def track_positions(tracks: Iterable[TrackSnapshot], confirmed_only: bool = True) -> np.ndarray:
    """The ``(m, 2)`` positions of ``tracks`` (only confirmed ones if ``confirmed_only``)."""
    pos = [t.position for t in tracks if t.confirmed or not confirmed_only]
    return np.asarray(pos, dtype=float).reshape(-1, 2)
