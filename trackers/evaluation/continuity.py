"""Track continuity per true target over a run: track breaks and identity swaps.

Definitions
-----------
Scans are the successive calls to :meth:`ContinuityCounter.add`.

*Following.* At each scan, tracks are assigned one-to-one to the true targets present in that
scan, as in the CLEAR MOT metrics (Bernardin and Stiefelhagen, 2008): a (target, track) pair
of the previous scan is kept while both are present and ``‖target − track‖ ≤ gate``; the
other targets and tracks are then assigned among pairs within the gate, choosing the
assignment with the most pairs and, among those, the smallest sum of distances. A track
assigned to a target *follows* it at that scan. Keeping pairs stops two close targets from
trading tracks in the count each time estimation noise reorders their distances.
A target absent from a scan's truth is simply not followed at that scan.

*Last follower.* For target ``t`` at scan ``k``, the track that followed ``t`` at the most
recent earlier scan at which ``t`` was followed at all (gaps without a follower are skipped).

*Change of follower.* Scan ``k`` is a change of follower for ``t`` if ``t`` is followed at
``k`` by track ``B``, ``t`` has a last follower ``A``, and ``B ≠ A``. Exactly the changes of
follower are counted, each either as an identity swap or as a break:

- an *identity swap* if ``B`` followed another target ``t' ≠ t`` at the previous scan
  ``k − 1`` (``B`` jumped from ``t'`` to ``t``). When two crossing targets exchange their
  tracks, each of the two targets counts one swap.
- a *break* otherwise (``B`` is a new track, or a track that followed nothing at ``k − 1``).
  Losing the follower and later regaining a different one is a break; losing it and later
  regaining the *same* track is not (the track coasted through the gap).

Not counted: the first track ever to follow a target (initiation), a follower lost and never
replaced, and the end of the run. ``track_ids_per_target`` lists, for each target, the
distinct tracks that followed it, in order of their first following.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from trackers.types import TrackSnapshot

__all__ = ["ContinuityCounter", "ContinuityResult", "gated_assignment"]


@dataclass(frozen=True)
class ContinuityResult:
    """Counts per true target (every target seen, zeros included) and their totals."""

    breaks: dict[int, int]
    swaps: dict[int, int]
    total_breaks: int
    total_swaps: int
    track_ids_per_target: dict[int, list[str]]


def gated_assignment(
    truth_pos: np.ndarray, track_pos: np.ndarray, gate: float
) -> tuple[np.ndarray, np.ndarray]:
    """The one-to-one ``(truth_indices, track_indices)`` pairs within ``gate``.

    Maximises the number of pairs with ``D_ij = ‖x_i − y_j‖ ≤ gate`` and, among those, minimises
    ``Σ D_ij``. This is a single ``linear_sum_assignment`` on the costs
    ``C_ij = D_ij`` if ``D_ij ≤ gate`` else ``B``, with ``B > (min(n, m) + 1) · gate`` so that
    one more gated pair always lowers the total; pairs at cost ``B`` are dropped.
    """
    X = np.asarray(truth_pos, dtype=float).reshape(-1, 2)
    Y = np.asarray(track_pos, dtype=float).reshape(-1, 2)
    empty = np.empty(0, dtype=np.intp)
    if X.shape[0] == 0 or Y.shape[0] == 0:
        return empty, empty
    dist = np.sqrt(np.sum((X[:, np.newaxis, :] - Y[np.newaxis, :, :]) ** 2, axis=-1))
    inside = dist <= gate
    if not inside.any():
        return empty, empty
    big = 2.0 * (min(X.shape[0], Y.shape[0]) + 1) * gate + 1.0
    rows, cols = linear_sum_assignment(np.where(inside, dist, big))
    keep = inside[rows, cols]
    return rows[keep].astype(np.intp), cols[keep].astype(np.intp)


class ContinuityCounter:
    """Accumulates track breaks and identity swaps per true target, scan by scan.

    See the module docstring for the exact definitions. ``gate`` (m) is the largest
    target-to-track distance at which a track counts as following a target.
    """

    def __init__(self, gate: float) -> None:
        if not (np.isfinite(gate) and gate > 0):
            raise ValueError(f"gate must be a finite number > 0, got {gate!r}")
        self.gate = float(gate)
        self._last: dict[int, str] = {}
        self._previous: dict[str, int] = {}
        self._breaks: dict[int, int] = {}
        self._swaps: dict[int, int] = {}
        self._tracks: dict[int, list[str]] = {}

    def add(
        self,
        truth_ids: Sequence[int],
        truth_pos: np.ndarray,
        track_ids: Sequence[str],
        track_pos: np.ndarray,
    ) -> None:
        """Record one scan: true targets ``truth_ids`` at ``truth_pos`` ``(k, 2)`` and tracks
        ``track_ids`` at ``track_pos`` ``(m, 2)``."""
        t_ids = [int(t) for t in truth_ids]
        k_ids = [str(k) for k in track_ids]
        X = np.asarray(truth_pos, dtype=float).reshape(-1, 2)
        Y = np.asarray(track_pos, dtype=float).reshape(-1, 2)
        if X.shape[0] != len(t_ids):
            raise ValueError(f"{len(t_ids)} truth ids but {X.shape[0]} truth positions")
        if Y.shape[0] != len(k_ids):
            raise ValueError(f"{len(k_ids)} track ids but {Y.shape[0]} track positions")
        if len(set(t_ids)) != len(t_ids):
            raise ValueError("duplicate truth ids in one scan")
        if len(set(k_ids)) != len(k_ids):
            raise ValueError("duplicate track ids in one scan")
        follower = self._kept_followers(t_ids, X, k_ids, Y)
        free_t = [i for i, t in enumerate(t_ids) if t not in follower]
        taken = set(follower.values())
        free_k = [j for j, k in enumerate(k_ids) if k not in taken]
        rows, cols = gated_assignment(X[free_t], Y[free_k], self.gate)
        follower.update(
            {t_ids[free_t[r]]: k_ids[free_k[c]] for r, c in zip(rows, cols, strict=True)}
        )
        for t in t_ids:
            self._breaks.setdefault(t, 0)
            self._swaps.setdefault(t, 0)
            self._tracks.setdefault(t, [])
            new = follower.get(t)
            if new is None:
                continue
            last = self._last.get(t)
            if last is not None and new != last:
                before = self._previous.get(new)
                if before is not None and before != t:
                    self._swaps[t] += 1
                else:
                    self._breaks[t] += 1
            self._last[t] = new
            if new not in self._tracks[t]:
                self._tracks[t].append(new)
        self._previous = {k: t for t, k in follower.items()}

    def _kept_followers(
        self, t_ids: list[int], X: np.ndarray, k_ids: list[str], Y: np.ndarray
    ) -> dict[int, str]:
        """The previous scan's (target, track) pairs that are still present and within the gate."""
        t_index = {t: i for i, t in enumerate(t_ids)}
        k_index = {k: j for j, k in enumerate(k_ids)}
        kept: dict[int, str] = {}
        for k, t in self._previous.items():
            i, j = t_index.get(t), k_index.get(k)
            if i is not None and j is not None and np.linalg.norm(X[i] - Y[j]) <= self.gate:
                kept[t] = k
        return kept

    def add_tracks(
        self,
        truth_ids: Sequence[int],
        truth_pos: np.ndarray,
        tracks: Iterable[TrackSnapshot],
        confirmed_only: bool = True,
    ) -> None:
        """:meth:`add` with the ids and positions of ``tracks`` (confirmed ones only if
        ``confirmed_only``)."""
        chosen = [t for t in tracks if t.confirmed or not confirmed_only]
        pos = np.asarray([t.position for t in chosen], dtype=float).reshape(-1, 2)
        self.add(truth_ids, truth_pos, [t.id for t in chosen], pos)

    def result(self) -> ContinuityResult:
        """The counts so far (a snapshot; later :meth:`add` calls do not change it)."""
        order = sorted(self._breaks)
        breaks = {t: self._breaks[t] for t in order}
        swaps = {t: self._swaps[t] for t in order}
        return ContinuityResult(
            breaks=breaks,
            swaps=swaps,
            total_breaks=sum(breaks.values()),
            total_swaps=sum(swaps.values()),
            track_ids_per_target={t: list(self._tracks[t]) for t in order},
        )
