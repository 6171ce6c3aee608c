"""The tracker's state file: tracks, ids and the report counter survive a restart.

The engine's worker takes a :class:`EngineCheckpoint` after every processed batch (a few
attribute reads: the trackers' states are immutable). :class:`StateStore` turns the latest
one into plain data and bytes (:mod:`trackers.state`) and writes it atomically
(:func:`service.files.atomic_write`), on its own thread every ``save_interval`` seconds and
once more when the engine stops, never on the worker's time. A periodic save is skipped when
no batch was processed since the last save (or the restore); the save at the stop is not, so
that the file says when the service stopped and ``max_age`` counts the time it was down, not
a quiet spell of the sensors before the stop (the tracks' wall-clock age since their last
batch is kept too, for the time-jump guard).

At start, :meth:`StateStore.restore_into` removes the temporary files interrupted saves left,
reads the file, refuses it when it is not a state file of this version, when it was saved
more than ``max_age`` seconds ago (wall clock), or when the trackers refuse its contents, and
otherwise puts it into the pipeline; every refusal is logged with its reason and the service
starts empty (the file is replaced at the next save).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from service import __version__
from service.files import atomic_write, remove_stale_temporaries
from trackers.pipeline import PipelineCheckpoint, TrackingPipeline
from trackers.state import PipelineState, StateError, decode_state, encode_state
from trackers.types import StepResult, TrackSnapshot

__all__ = ["EngineCheckpoint", "Restored", "SaveFigures", "StateStore", "restored_result"]

log = logging.getLogger("service.state")


@dataclass(frozen=True)
class EngineCheckpoint:
    """The engine after the batch of report ``seq`` (from ``sensor_id``), processed at
    ``processed_at`` (``time.monotonic()``)."""

    seq: int
    pipeline: PipelineCheckpoint
    sensor_id: str | None
    processed_at: float
    #: resets of the engine before it (a reset changes the state under the same ``seq``)
    resets: int = 0


@dataclass(frozen=True)
class Restored:
    """What a restore gives back to the engine besides the tracks: the report counter, the
    sensor of the last report, and the wall-clock seconds since its batch was processed."""

    seq: int
    sensor_id: str | None
    since_last_batch: float


@dataclass(frozen=True)
class SaveFigures:
    """One save: the report it holds, its size, and where its time went (ms)."""

    seq: int
    size: int
    export_ms: float
    encode_ms: float
    write_ms: float


def restored_result(pipeline: TrackingPipeline, sensor_id: str | None) -> StepResult | None:
    """The restored tracks as a step result (for the report readers see before the first
    batch after a restart); ``None`` when the pipeline has no time yet."""
    t = pipeline.last_time
    if t is None:
        return None
    tracks = pipeline.snapshot()
    confirmed = tuple(s for s in tracks if s.confirmed)

    def snapshot(confirmed_only: bool) -> tuple[TrackSnapshot, ...]:
        return confirmed if confirmed_only else tracks

    return StepResult(time=t, sensor_id=sensor_id or "", deleted=(), snapshot=snapshot)


class _NotUsed(Exception):
    """Why a saved state is not restored."""


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _warn_switched_off(pipeline: TrackingPipeline, state: PipelineState) -> None:
    """Say which restored tracks the configuration in force ends at the next batch: those
    of a track kind switched off (a state saved while ``--demo formation`` had formations
    on, restored without it), or point-pattern tracks with no pattern configured."""
    config = pipeline.config
    patterns = config.point_patterns
    # kind: (switched off, the section's count, what it counts, the setting that says so)
    ending = {
        "extended": (
            not config.extended.enabled,
            "n_tracks",
            "extended tracks",
            "extended.enabled",
        ),
        "formation": (
            not config.formation.enabled,
            "n_formations",
            "formations",
            "formation.enabled",
        ),
        "point_patterns": (
            not (patterns.enabled and patterns.patterns),
            "n_tracks",
            "point-pattern tracks",
            "point_patterns",
        ),
    }
    for kind, section in state.peers.items():
        off, key, what, setting = ending.get(kind, (False, "", "", ""))
        n = section.values.get(key)
        if off and isinstance(n, int) and n > 0:
            log.warning(
                "%d restored %s end at the next batch: %s is off in the configuration in force",
                n,
                what,
                setting,
            )


class StateStore:
    """The state file at ``path``: restored at start when younger than ``max_age`` seconds,
    saved every ``save_interval`` seconds (0: only when the engine stops)."""

    def __init__(
        self,
        path: Path,
        *,
        max_age: float,
        save_interval: float,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        self.path = Path(path)
        self.max_age = float(max_age)
        self.save_interval = float(save_interval)
        self._wall = wall_clock
        self._saved: tuple[int, int] | None = None  # (seq, resets) of the state on file
        self._save_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.last_save: SaveFigures | None = None

    # -- start ----------------------------------------------------------------------------

    def restore_into(self, pipeline: TrackingPipeline) -> Restored | None:
        """Remove stale temporary files, then load the file into ``pipeline``; ``None`` (and
        the reason logged) when there is nothing to restore or it cannot be used."""
        remove_stale_temporaries(self.path)
        try:
            return self._restore(pipeline)
        except _NotUsed as exc:
            log.warning(
                "the saved tracker state %s is not used: %s; starting with no tracks (the "
                "file is replaced at the next save)",
                self.path,
                exc,
            )
            return None

    def _restore(self, pipeline: TrackingPipeline) -> Restored | None:
        try:
            data = self.path.read_bytes()
        except FileNotFoundError:
            log.info("no saved tracker state at %s: starting with no tracks", self.path)
            return None
        except OSError as exc:
            raise _NotUsed(f"it cannot be read ({exc.strerror or exc})") from None
        try:
            state, meta = decode_state(data)
        except StateError as exc:
            raise _NotUsed(str(exc)) from None
        saved_at, seq = meta.get("saved_at"), meta.get("seq")
        since = meta.get("since_last_batch", 0.0)
        sensor_id = meta.get("sensor_id")
        if not (_number(saved_at) and _number(since) and since >= 0):
            raise _NotUsed("its header has no valid saved_at and since_last_batch")
        if not (isinstance(seq, int) and not isinstance(seq, bool) and seq >= 0):
            raise _NotUsed(f"its header has no valid seq ({seq!r})")
        if sensor_id is not None and not isinstance(sensor_id, str):
            raise _NotUsed("its header's sensor_id is not a string")
        age = self._wall() - float(saved_at)  # type: ignore[arg-type]
        if age > self.max_age:
            raise _NotUsed(
                f"it was saved {age:.1f} s ago, more than state_max_age = {self.max_age:g} s"
            )
        try:
            pipeline.import_state(state)
        except StateError as exc:
            raise _NotUsed(str(exc)) from None
        self._saved = (seq, 0)
        values = state.point.values
        kinds = Counter(t.kind for t in pipeline.snapshot())
        log.info(
            "tracker state restored from %s (saved %.1f s ago): %s tracks (%s), %s two-point "
            "candidates, last time %s, report seq %d, next id T%s",
            self.path,
            max(age, 0.0),
            sum(kinds.values()),
            ", ".join(f"{n} {kind}" for kind, n in sorted(kinds.items())) or "none",
            values.get("n_candidates"),
            state.last_time,
            seq,
            values.get("next_id"),
        )
        _warn_switched_off(pipeline, state)
        return Restored(seq=seq, sensor_id=sensor_id, since_last_batch=float(since) + max(age, 0.0))

    # -- saving ---------------------------------------------------------------------------

    def save(
        self, checkpoint: EngineCheckpoint | None, *, force: bool = False
    ) -> SaveFigures | None:
        """Write ``checkpoint`` unless it is ``None`` or, without ``force``, already saved (or
        restored). Raises ``OSError`` or :class:`~trackers.state.StateError` when it cannot;
        the old file is then left as it was."""
        with self._save_lock:
            if checkpoint is None:
                return None
            if not force and (checkpoint.seq, checkpoint.resets) == self._saved:
                return None
            t0 = time.perf_counter()
            state = checkpoint.pipeline.export()
            t1 = time.perf_counter()
            meta = {
                "saved_at": self._wall(),
                "seq": checkpoint.seq,
                "sensor_id": checkpoint.sensor_id,
                "since_last_batch": max(0.0, time.monotonic() - checkpoint.processed_at),
                "service_version": __version__,
            }
            data = encode_state(state, meta)
            t2 = time.perf_counter()
            atomic_write(self.path, data)
            t3 = time.perf_counter()
            self._saved = (checkpoint.seq, checkpoint.resets)
            figures = SaveFigures(
                seq=checkpoint.seq,
                size=len(data),
                export_ms=(t1 - t0) * 1e3,
                encode_ms=(t2 - t1) * 1e3,
                write_ms=(t3 - t2) * 1e3,
            )
            self.last_save = figures
        log.debug(
            "tracker state saved to %s: seq %d, %d bytes, export %.1f ms, encode %.1f ms, "
            "write %.1f ms",
            self.path,
            figures.seq,
            figures.size,
            figures.export_ms,
            figures.encode_ms,
            figures.write_ms,
        )
        return figures

    def save_logged(
        self, checkpoint: EngineCheckpoint | None, *, force: bool = False
    ) -> SaveFigures | None:
        """:meth:`save`, a failure logged instead of raised."""
        try:
            return self.save(checkpoint, force=force)
        except (OSError, StateError) as exc:
            log.warning("could not save the tracker state to %s: %s", self.path, exc)
        except Exception:  # a bug must not stop the saver or the engine's shutdown
            log.exception("could not save the tracker state to %s", self.path)
        return None

    def start(self, latest: Callable[[], EngineCheckpoint | None]) -> None:
        """Save ``latest()`` every ``save_interval`` seconds on a thread of its own."""
        if self._thread is not None or self.save_interval <= 0:
            return
        self._stop.clear()

        def run() -> None:
            while not self._stop.wait(self.save_interval):
                self.save_logged(latest())

        self._thread = threading.Thread(target=run, name="tracker-state-saver", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the periodic saves (a save under way finishes first)."""
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join()
        self._thread = None
