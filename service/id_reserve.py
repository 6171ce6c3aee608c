"""Track ids that a restart does not give again, with or without a state file.

Each tracker numbers its tracks from a counter (``T1``, ``T2``, ... ``E1``, ``F1``, ``B1``).
Without a state file a restart would begin those counters at 1 again, and a consumer that
keys what it knows by track id would take the new ``T1`` for the old one. So the service
keeps, in ``<state_dir>/ids.json`` (``ids.<instance_id>.json`` for an instance of a
scale-out), a number for each counter that no id given so far has reached: a *reservation*.

- At start the counters move past the reservation (past the restored ones too, when a state
  file was restored), and a new reservation is written: each counter plus a block of
  :data:`ID_BLOCK` ids, or of the ids :data:`BLOCK_SECONDS` of the last rate numbers, when
  that is more (clutter can start tentative tracks by the hundred a second).
- After each batch or command that numbered a track, and before its report goes out, the
  counters are compared with the reservation; a counter that reached it writes a new one.
  So every id the service has published is below the reservation on disk, whenever it
  stops (a crash or kill -9 included).
- At a clean stop (SIGTERM, SIGINT) the reservation shrinks to the counters themselves: the
  next start goes on from the next id, with or without a state file.

A restart after a crash therefore skips at most a block of each counter (where a state file
saved before the crash would give again the ids numbered since its last save), and no
restart gives an id twice. The file is written atomically (:func:`service.files.atomic_write`)
and, while the service runs, held under an exclusive lock (``<file>.lock``): a second
service started on the same folder says so and runs without one. What goes wrong with the
file is logged and the service runs on: a write that fails is tried again (at most every
:data:`RETRY_SECONDS`); a file that cannot be read is left alone and no reservation is kept;
a file that is not one of these is replaced.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from service.files import atomic_write, remove_stale_temporaries
from trackers.pipeline import TrackingPipeline

try:  # POSIX; elsewhere the file is not locked
    import fcntl
except ImportError:  # pragma: no cover - not on the platforms the service ships for
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "BLOCK_SECONDS",
    "ID_BLOCK",
    "ID_FILE",
    "MAX_COUNTER",
    "IdReservation",
    "id_file",
]

log = logging.getLogger("service.ids")

#: The file's name in ``state_dir`` (one instance of a scale-out: ``ids.<instance_id>.json``).
ID_FILE = "ids.json"
#: New ids one reservation covers at least, per counter.
ID_BLOCK = 1000
#: ... or the ids numbered in this many seconds at the rate since the last reservation.
BLOCK_SECONDS = 30.0
#: Seconds between tries to write a reservation after one failed.
RETRY_SECONDS = 10.0
#: The largest counter the file holds (beyond, it is not a file this service wrote).
MAX_COUNTER = 2**53
#: A larger file is not one of these (a few counters take some 100 bytes).
MAX_FILE_BYTES = 65536
_VERSION = 1


def id_file(state_dir: Path, instance_id: str | None = None) -> Path:
    """Where the reservation of ``state_dir`` lives (``instance_id``: one of a scale-out)."""
    return Path(state_dir) / (ID_FILE if instance_id is None else f"ids.{instance_id}.json")


class IdReservation:
    """The reservation of a pipeline's id counters in ``path`` (module docstring);
    ``clock`` gives seconds (monotonic) for the block's rate and the retries."""

    def __init__(
        self,
        path: Path,
        block: int = ID_BLOCK,
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not 1 <= block <= MAX_COUNTER:
            raise ValueError(f"block must be in [1, {MAX_COUNTER}], got {block}")
        self.path = Path(path)
        self.block = int(block)
        self._clock = clock
        self._reserved: dict[str, int] = {}
        #: the counters and the time of the last reservation written (the rate's start)
        self._since: tuple[dict[str, int], float] | None = None
        self._on = False  # a reservation is kept (begun, the file ours and readable)
        self._failed_at: float | None = None  # the last write that failed, until one works
        self._lock_fd: int | None = None

    @property
    def reserved(self) -> dict[str, int]:
        """The reservation on disk: no id numbered at or above it has been given."""
        return dict(self._reserved)

    @property
    def active(self) -> bool:
        """Whether a reservation is kept (the file ours, readable, and written since a
        failure, if any)."""
        return self._on and self._failed_at is None

    def begin(self, pipeline: TrackingPipeline) -> None:
        """Move ``pipeline``'s counters past the saved reservation, then reserve the next
        block. Never raises for the file's sake (it logs)."""
        if not self._lock():
            return
        remove_stale_temporaries(self.path)  # what a crash during a write left
        saved = self._read()
        if saved is None:
            self._unlock()
            return
        if saved:
            before = pipeline.id_counters()
            pipeline.skip_ids(saved)
            moved = {kind: n for kind, n in pipeline.id_counters().items() if n != before.get(kind)}
            if moved:
                log.info(
                    "track ids go on past those given before the restart (%s): %s",
                    self.path,
                    ", ".join(f"{kind} from {n}" for kind, n in sorted(moved.items())),
                )
        self._on = True
        self._reserved = dict(saved)
        self._reserve(pipeline.id_counters())
        if self.active:
            log.info(
                "track ids: never given twice, across restarts too (reserved in %s)", self.path
            )

    def check(self, pipeline: TrackingPipeline) -> None:
        """After ids may have been given: a new reservation if a counter reached the one on
        disk (or the last write failed, and it is time to try again). Costs a few attribute
        reads when none did."""
        if not self._on:
            return
        if self._failed_at is not None:
            if self._clock() - self._failed_at >= RETRY_SECONDS:
                self._reserve(pipeline.id_counters())
            return
        counters = pipeline.id_counters()
        reserved = self._reserved
        for kind, n in counters.items():
            if n >= reserved.get(kind, 0):
                self._reserve(counters)
                return

    def end(self, pipeline: TrackingPipeline) -> None:
        """At a clean stop (nothing more will be numbered): the reservation shrinks to the
        counters themselves, so that the next start goes on from the next id, as a state
        file restores it, instead of skipping the rest of the block. Then the file's lock
        is released."""
        if self._on:
            self._reserve(pipeline.id_counters(), block=0)
            self._on = False
        self._unlock()

    def _block(self, counters: Mapping[str, int], now: float) -> dict[str, int]:
        """Each counter's block: :data:`ID_BLOCK` ids, or those of :data:`BLOCK_SECONDS` at
        the rate since the last reservation."""
        if self._since is None:
            return {kind: self.block for kind in counters}
        before, then = self._since
        span = max(now - then, 1.0)  # (a burst within a second is no rate to go on)
        return {
            kind: max(self.block, int(BLOCK_SECONDS * (n - before.get(kind, n)) / span))
            for kind, n in counters.items()
        }

    def _reserve(self, counters: Mapping[str, int], block: int | None = None) -> None:
        now = self._clock()
        add = self._block(counters, now) if block is None else dict.fromkeys(counters, block)
        # kinds not running now keep their saved numbers, for when they are switched on again
        reserved = {
            **self._reserved,
            **{kind: min(n + add[kind], MAX_COUNTER) for kind, n in counters.items()},
        }
        data = json.dumps({"version": _VERSION, "reserved": reserved}, sort_keys=True)
        try:
            atomic_write(self.path, data.encode())
        except OSError as exc:
            if self._failed_at is None:
                log.warning(
                    "cannot write the track id reservation %s (%s): tried again every %g s; "
                    "until it works, a restart after a crash may give again ids given now",
                    self.path,
                    exc,
                    RETRY_SECONDS,
                )
            self._failed_at = now
            return
        if self._failed_at is not None:
            log.info("the track id reservation %s is written again", self.path)
            self._failed_at = None
        self._reserved = reserved
        self._since = (dict(counters), now)

    def _lock(self) -> bool:
        """Hold ``<file>.lock`` for the run; False (logged) when another process holds it or
        it cannot be opened."""
        if fcntl is None:  # pragma: no cover
            return True
        lock_path = self.path.with_name(self.path.name + ".lock")
        try:
            lock_path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            log.warning(
                "cannot open %s (%s): no track id reservation is kept; after a restart, "
                "track ids may repeat those given now",
                lock_path,
                exc,
            )
            return False
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            log.warning(
                "another service holds the track id reservation %s (the same state folder): "
                "this one keeps none, and after a restart its track ids may repeat; give each "
                "service its own --state-dir",
                self.path,
            )
            return False
        self._lock_fd = fd
        return True

    def _unlock(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # (closing releases the flock)
            self._lock_fd = None

    def _read(self) -> dict[str, int] | None:
        """The saved reservation: {} when there is none or it is not one of these (logged;
        it is replaced), None when it cannot be read (logged; it is left alone)."""
        try:
            with open(self.path, "rb") as fh:
                raw = fh.read(MAX_FILE_BYTES + 1)
        except FileNotFoundError:
            return {}
        except OSError as exc:
            log.warning(
                "cannot read the track id reservation %s (%s): it is left as it is, and no "
                "reservation is kept (after a restart, track ids may repeat)",
                self.path,
                exc,
            )
            return None
        try:
            if len(raw) > MAX_FILE_BYTES:
                raise ValueError(f"larger than {MAX_FILE_BYTES} bytes")
            return _parse(json.loads(raw))
        except Exception as exc:  # ValueError, UnicodeDecodeError, RecursionError (deep nesting)
            log.warning(
                "the track id reservation %s is not usable (%s): it is replaced, and track "
                "ids may repeat some given before",
                self.path,
                f"{type(exc).__name__}: {exc}" if not isinstance(exc, ValueError) else exc,
            )
            return {}


def _parse(doc: Any) -> dict[str, int]:
    """The ``reserved`` numbers of a reservation file's document; ValueError saying why not."""
    if not isinstance(doc, dict) or doc.get("version") != _VERSION:
        raise ValueError(f"not a version {_VERSION} reservation")
    reserved = doc.get("reserved")
    if not isinstance(reserved, dict):
        raise ValueError("'reserved' must be an object")
    out: dict[str, int] = {}
    for kind, n in reserved.items():
        ok = isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_COUNTER
        if not (isinstance(kind, str) and ok):
            raise ValueError(f"{kind!r}: {n!r} is not a counter in [1, {MAX_COUNTER}]")
        out[kind] = n
    return out
