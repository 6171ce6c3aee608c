"""Effective tracking rate and false tracks, per scan and per target class.

At each scan (a call of :meth:`EffectiveRateCounter.add`), confirmed tracks are assigned one
to one to the true targets within ``gate`` metres, keeping the pairs of the previous scan that
are still within the gate and then maximising the number of pairs, the sum of distances least
(:func:`trackers.evaluation.continuity.gated_assignment`). A target is *held* at scan ``k``
when its track at ``k`` is the same track as at ``k − 1``. Confirmed tracks assigned to no
target are *false* at that scan (duplicates of a held target included). Scans before
``warmup`` are not counted (the first scan counted is number ``warmup``, from 0), but their
assignments are, so the first counted scan can be held.

    effective tracking rate = held target-scans / target-scans counted

The false tracks are split in two. A false track is *displaced* when it is a target's own
track gone astray: the target it was last assigned to is within ``displaced_gate`` metres
and held by no other track at this scan (an aircraft's track coasting through a missed
detection in a turn, more than ``gate`` off). The others are *spurious*: tracks of clutter,
duplicates, tracks that follow nothing. ``false_per_scan`` counts both; the track of a real
target that is more than ``gate`` off also counts as not held in the rate.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from trackers.evaluation.continuity import gated_assignment

__all__ = ["EffectiveRate", "EffectiveRateCounter"]


@dataclass(frozen=True)
class EffectiveRate:
    """``rate`` overall, ``rate_by_class`` per target class, ``false_per_scan`` (mean number of
    false confirmed tracks a counted scan), of which ``displaced_per_scan`` were targets' own
    tracks more than the gate off, and ``scans`` counted."""

    rate: float
    rate_by_class: dict[str, float]
    false_per_scan: float
    scans: int
    displaced_per_scan: float = 0.0

    @property
    def spurious_per_scan(self) -> float:
        """False tracks a scan that are not a target's own track gone astray."""
        return self.false_per_scan - self.displaced_per_scan


class EffectiveRateCounter:
    def __init__(
        self, gate: float = 150.0, warmup: int = 8, displaced_gate: float = 1000.0
    ) -> None:
        self.gate = float(gate)
        self.warmup = int(warmup)
        self.displaced_gate = float(displaced_gate)
        self._scan = 0
        self._previous: dict[int, str] = {}
        self._last_target: dict[str, int] = {}  # track → the target it was last assigned to
        self._held: dict[int, int] = defaultdict(int)
        self._seen: dict[int, int] = defaultdict(int)
        self._false = 0
        self._displaced = 0

    def add(
        self,
        truth_ids: Sequence[int] | np.ndarray,
        truth_positions: np.ndarray,
        track_ids: Sequence[str],
        track_positions: np.ndarray,
        gate: float | None = None,
    ) -> dict[int, str]:
        """Count one scan; ``gate`` (m) replaces the counter's for this scan. Returns the
        target → track pairs of the scan."""
        if gate is not None:
            self.gate = float(gate)
        truth_ids = [int(i) for i in truth_ids]
        X = np.asarray(truth_positions, dtype=float).reshape(-1, 2)
        Y = np.asarray(track_positions, dtype=float).reshape(-1, 2)
        track_ids = list(track_ids)
        index_of = {tid: j for j, tid in enumerate(track_ids)}
        current: dict[int, str] = {}
        used_tracks: set[int] = set()
        for i, target in enumerate(truth_ids):
            tid = self._previous.get(target)
            j = index_of.get(tid) if tid is not None else None
            if j is not None and j not in used_tracks and np.hypot(*(X[i] - Y[j])) <= self.gate:
                current[target] = tid  # type: ignore[assignment]
                used_tracks.add(j)
        free_t = [i for i, target in enumerate(truth_ids) if target not in current]
        free_k = [j for j in range(len(track_ids)) if j not in used_tracks]
        if free_t and free_k:
            rows, cols = gated_assignment(X[free_t], Y[free_k], self.gate)
            for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
                current[truth_ids[free_t[r]]] = track_ids[free_k[c]]
                used_tracks.add(free_k[c])
        if self._scan >= self.warmup:
            for target in truth_ids:
                self._seen[target] += 1
                tid = current.get(target)
                if tid is not None and self._previous.get(target) == tid:
                    self._held[target] += 1
            self._false += len(track_ids) - len(used_tracks)
            row_of = {target: i for i, target in enumerate(truth_ids)}
            for j, tid in enumerate(track_ids):
                target = self._last_target.get(tid)
                i = row_of.get(target) if target is not None else None
                if (
                    j not in used_tracks
                    and i is not None
                    and target not in current
                    and np.hypot(*(X[i] - Y[j])) <= self.displaced_gate
                ):
                    self._displaced += 1
        for target, tid in current.items():
            self._last_target[tid] = target
        self._previous = current
        self._scan += 1
        return current

    def result(self, classes: Mapping[int, str] | None = None) -> EffectiveRate:
        classes = classes or {}
        by_class_held: dict[str, int] = defaultdict(int)
        by_class_seen: dict[str, int] = defaultdict(int)
        for target, n in self._seen.items():
            name = classes.get(target, "all")
            by_class_seen[name] += n
            by_class_held[name] += self._held[target]
        seen = sum(self._seen.values())
        counted = max(0, self._scan - self.warmup)
        return EffectiveRate(
            rate=sum(self._held.values()) / seen if seen else float("nan"),
            rate_by_class={k: by_class_held[k] / v for k, v in sorted(by_class_seen.items())},
            false_per_scan=self._false / counted if counted else float("nan"),
            scans=counted,
            displaced_per_scan=self._displaced / counted if counted else float("nan"),
        )
