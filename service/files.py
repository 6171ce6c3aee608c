"""Files the service writes (the configuration, the tracker's state): written atomically,
and what an interrupted write left behind removed at start.

:func:`atomic_write` writes a temporary file next to the target, named
``.{name}.{pid}-{random}.tmp``, fsyncs it, renames it over the target and fsyncs the folder:
a reader, or the service after a crash, finds the old file or the new one, never a part.
A process killed during the write (kill -9, power loss) leaves the temporary file;
:func:`remove_stale_temporaries` removes those at the next start.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import tempfile
import time
from pathlib import Path

__all__ = ["STALE_AFTER", "atomic_write", "remove_stale_temporaries", "temporaries_of"]

log = logging.getLogger("service.files")

#: A temporary file older than this (s) is stale even if the process that wrote it runs:
#: no write of the service takes this long.
STALE_AFTER = 600.0

_PID = re.compile(r"^(\d{1,10})-")


def _temporary_prefix(path: Path) -> str:
    return f".{path.name}."


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (module docstring). On any failure the old file
    is left as it was and no temporary file remains."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        prefix=f"{_temporary_prefix(path)}{os.getpid()}-", suffix=".tmp", dir=path.parent
    )
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_folder(path.parent)


def _fsync_folder(folder: Path) -> None:
    """Make the rename durable (where the platform allows opening a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        with contextlib.suppress(OSError):
            os.fsync(fd)
    finally:
        os.close(fd)


def temporaries_of(path: Path) -> list[Path]:
    """The temporary files of ``path`` in its folder (from :func:`atomic_write`, or from the
    earlier ``.{name}.{random}.tmp`` naming)."""
    path = Path(path)
    prefix = _temporary_prefix(path)
    try:
        entries = list(path.parent.iterdir())
    except OSError:
        return []
    return sorted(
        p
        for p in entries
        if p.name.startswith(prefix) and p.name.endswith(".tmp") and len(p.name) > len(prefix)
    )


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return pid > 0  # exists, owned by someone else
    return True


def _is_stale(tmp: Path, prefix: str, now: float) -> bool:
    """Left by a write that cannot finish: its process is gone (or is this one, restarted
    under the same pid, as in a container), its name carries no pid, or it is older than
    :data:`STALE_AFTER`."""
    match = _PID.match(tmp.name[len(prefix) :])
    if match is None:
        return True
    pid = int(match[1])
    if pid == os.getpid() or not _pid_alive(pid):
        return True
    try:
        return now - tmp.stat().st_mtime > STALE_AFTER
    except OSError:
        return False


def remove_stale_temporaries(path: Path) -> list[Path]:
    """Remove the temporary files that interrupted writes of ``path`` left (each logged);
    return them. Call at start, before this process writes ``path``."""
    path = Path(path)
    prefix = _temporary_prefix(path)
    now = time.time()
    removed = []
    for tmp in temporaries_of(path):
        if not _is_stale(tmp, prefix, now):
            continue
        try:
            size = tmp.stat().st_size
            tmp.unlink()
        except FileNotFoundError:
            continue
        except OSError as exc:
            log.warning("could not remove the stale temporary file %s: %s", tmp, exc)
            continue
        log.warning(
            "removed %s (%d bytes), left by an interrupted write of %s", tmp, size, path.name
        )
        removed.append(tmp)
    return removed
