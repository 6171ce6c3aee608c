"""Track ids that a restart does not give again, with or without a state file.

Each tracker numbers its tracks from a counter (``T1``, ``T2``, ... ``E1``, ``F1``, ``B1``).
Without a state file a restart would begin those counters at 1 again, and a consumer that
keys what it knows by track id would take the new ``T1`` for the old one. So the service
keeps, in ``<state_dir>/ids.json`` (``ids.<instance_id>.json`` for an instance of a
scale-out), a number for each counter that no id given so far has reached: a *reservation*.

- At start the counters move past the reservation (past the restored ones too, when a state
  file was restored), and a new reservation ``counter + block`` is written.
- At a clean stop (SIGTERM, SIGINT) the reservation shrinks to the counters themselves: the
  next start goes on from the next id, with or without a state file.
- After each batch or command that numbered a track, and before its report goes out, the
  counters are compared with the reservation; a counter that reached it writes a new one.
  So every id the service has published is below the reservation on disk, whenever it
  stops (a crash or kill -9 included), and one write covers ``block`` new ids.

A restart after a crash therefore skips at most ``block`` numbers of each counter (where a
state file saved before the crash would give again the ids numbered since its last save), and
no restart gives an id twice.
The file is written atomically (:func:`service.files.atomic_write`). A folder that cannot be
written, or a file that cannot be read, is logged once, and the service goes on (its ids may
then repeat those of a run before a restart, as the log says).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from service.files import atomic_write, remove_stale_temporaries
from trackers.pipeline import TrackingPipeline

__all__ = ["ID_BLOCK", "ID_FILE", "IdReservation", "id_file"]

log = logging.getLogger("service.ids")

#: The file's name in ``state_dir`` (one instance of a scale-out: ``ids.<instance_id>.json``).
ID_FILE = "ids.json"
#: New ids one reservation covers, per counter: a restart skips at most this many numbers.
ID_BLOCK = 1000
#: The largest counter the file may hold (beyond, it is not a file this service wrote).
MAX_COUNTER = 2**53
_VERSION = 1


def id_file(state_dir: Path, instance_id: str | None = None) -> Path:
    """Where the reservation of ``state_dir`` lives (``instance_id``: one of a scale-out)."""
    return Path(state_dir) / (ID_FILE if instance_id is None else f"ids.{instance_id}.json")


class IdReservation:
    """The reservation of a pipeline's id counters in ``path`` (module docstring)."""

    def __init__(self, path: Path, block: int = ID_BLOCK) -> None:
        if not 1 <= block <= MAX_COUNTER:
            raise ValueError(f"block must be in [1, {MAX_COUNTER}], got {block}")
        self.path = Path(path)
        self.block = int(block)
        self._reserved: dict[str, int] = {}
        self._writable = True

    @property
    def reserved(self) -> dict[str, int]:
        """The reservation on disk: no id numbered at or above it has been given."""
        return dict(self._reserved)

    def begin(self, pipeline: TrackingPipeline) -> None:
        """Move ``pipeline``'s counters past the saved reservation, then reserve the next
        block. Never raises for the file's sake (it logs)."""
        remove_stale_temporaries(self.path)  # what a crash during a write left
        saved = self._read()
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
        self._reserve(pipeline.id_counters(), saved)

    def check(self, pipeline: TrackingPipeline) -> None:
        """After ids may have been given: a new reservation if a counter reached the one on
        disk. Costs a few attribute reads when none did."""
        if not self._writable:
            return
        counters = pipeline.id_counters()
        reserved = self._reserved
        for kind, n in counters.items():
            if n >= reserved.get(kind, 0):
                self._reserve(counters, reserved)
                return

    def end(self, pipeline: TrackingPipeline) -> None:
        """At a clean stop (nothing more will be numbered): the reservation shrinks to the
        counters themselves, so that the next start goes on from the next id, as a state
        file restores it, instead of skipping the rest of the block."""
        if self._writable:
            self._reserve(pipeline.id_counters(), self._reserved, block=0)

    def _reserve(
        self, counters: Mapping[str, int], keep: Mapping[str, int], block: int | None = None
    ) -> None:
        # kinds not running now keep their saved numbers, for when they are switched on again
        add = self.block if block is None else block
        reserved = {**keep, **{kind: n + add for kind, n in counters.items()}}
        data = json.dumps({"version": _VERSION, "reserved": reserved}, sort_keys=True)
        try:
            atomic_write(self.path, data.encode())
        except OSError as exc:
            self._writable = False
            log.warning(
                "cannot write the track id reservation %s (%s): after a restart, track ids "
                "may repeat those given now",
                self.path,
                exc,
            )
            return
        self._reserved = reserved

    def _read(self) -> dict[str, int]:
        """The saved reservation ({} when there is none, or it cannot be used: logged)."""
        try:
            raw = self.path.read_bytes()
        except FileNotFoundError:
            return {}
        except OSError as exc:
            log.warning("cannot read the track id reservation %s (%s)", self.path, exc)
            return {}
        try:
            return _parse(json.loads(raw))
        except (ValueError, UnicodeDecodeError) as exc:
            log.warning(
                "the track id reservation %s is not usable (%s): it is replaced, and track "
                "ids may repeat some given before",
                self.path,
                exc,
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
