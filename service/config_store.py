"""The configuration document (:mod:`service.config_tree`) as the service keeps it:
validated as a whole, saved atomically, and handed to the engine's worker for its next batch.

:class:`ConfigStore` holds the accepted document; ``PUT`` (:meth:`ConfigStore.replace`) and
``PATCH`` (:meth:`ConfigStore.patch`, a JSON merge patch) validate the whole result, write it
to the config file when one is set, and only then accept it. An invalid document raises
:class:`ConfigError` and changes nothing, not even the file. The worker takes what was
accepted with :meth:`ConfigStore.take_pending` before its next batch.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import orjson

from service.config_tree import (
    ConfigError,
    check_patch,
    config_document,
    validate_config_document,
)
from service.files import atomic_write
from service.schemas import IngestConfig
from trackers.config import TrackerConfig

__all__ = [
    "ConfigApplied",
    "ConfigStore",
    "config_changes",
    "load_config_file",
    "merge_patch",
    "save_config_file",
]

log = logging.getLogger("service.config")

_MISSING = object()


def _flatten(doc: Any, prefix: str, out: dict[str, Any]) -> None:
    if isinstance(doc, dict) and doc:
        for key, value in doc.items():
            _flatten(value, f"{prefix}.{key}" if prefix else str(key), out)
    else:
        out[prefix] = doc


def _shown(value: Any) -> str:
    if value is _MISSING:
        return "(none)"
    return orjson.dumps(value).decode() if not isinstance(value, str) else value


def config_changes(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """What differs between two configuration documents, one ``"section.field old -> new"``
    per changed leaf (a list is one value), in the new document's order."""
    before: dict[str, Any] = {}
    after: dict[str, Any] = {}
    _flatten(old, "", before)
    _flatten(new, "", after)
    out = []
    for name in [*after, *(n for n in before if n not in after)]:
        a, b = before.get(name, _MISSING), after.get(name, _MISSING)
        if a != b:
            out.append(f"{name} {_shown(a)} -> {_shown(b)}")
    return out


@dataclass(frozen=True)
class ConfigApplied:
    """What a PUT or PATCH did: the accepted document, what changed (``"motion.q_cv 0.5 ->
    1.0"`` each) and the file it was saved to (``None``: no config file)."""

    document: dict[str, Any]
    changes: tuple[str, ...]
    saved_to: Path | None

    def summary(self) -> str:
        """``"motion.q_cv 0.5 -> 1.0; saved to /path/config.json"``, as logged."""
        changed = "; ".join(self.changes) if self.changes else "nothing changed"
        saved = f"saved to {self.saved_to}" if self.saved_to is not None else "not saved"
        return f"{changed}; {saved}"


def merge_patch(base: Any, patch: Any) -> Any:
    """JSON merge patch (RFC 7386): objects merge recursively, ``null`` removes a field (so it
    takes its default), anything else replaces."""
    if not isinstance(patch, dict):
        return patch
    out = dict(base) if isinstance(base, dict) else {}
    for key, value in patch.items():
        if value is None:
            out.pop(key, None)
        else:
            out[key] = merge_patch(out.get(key), value)
    return out


def load_config_file(
    path: Path, ingest_defaults: IngestConfig
) -> tuple[TrackerConfig, IngestConfig] | None:
    """The configuration saved in ``path``, or ``None`` when the file does not exist.

    Raises :class:`ConfigError` when it exists but cannot be used."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise ConfigError(f"config file {path}: {exc.strerror or exc}") from None
    try:
        doc = orjson.loads(raw)
    except orjson.JSONDecodeError as exc:
        raise ConfigError(f"config file {path}: not JSON ({exc})") from None
    try:
        return validate_config_document(doc, ingest_defaults)
    except ConfigError as exc:
        raise ConfigError(f"config file {path}: {exc}") from None


def save_config_file(path: Path, doc: dict[str, Any]) -> None:
    """Write ``doc`` to ``path`` atomically (:func:`service.files.atomic_write`: a temporary
    file in the same folder, fsync'd, then renamed over the old one)."""
    data = orjson.dumps(doc, option=orjson.OPT_INDENT_2 | orjson.OPT_APPEND_NEWLINE)
    atomic_write(Path(path), data)


class ConfigStore:
    """The accepted configuration, and what the worker has yet to apply. Thread-safe."""

    def __init__(
        self,
        tracker: TrackerConfig,
        ingest: IngestConfig,
        *,
        ingest_defaults: IngestConfig,
        path: Path | None = None,
    ) -> None:
        self.ingest_defaults = ingest_defaults
        self.path = path
        self._tracker = tracker
        self._ingest = ingest
        self._lock = threading.Lock()
        self._pending: tuple[TrackerConfig, IngestConfig] | None = None

    @property
    def tracker(self) -> TrackerConfig:
        return self._tracker

    @property
    def ingest(self) -> IngestConfig:
        return self._ingest

    def document(self) -> dict[str, Any]:
        """The accepted document."""
        with self._lock:
            return config_document(self._tracker, self._ingest)

    def replace(self, doc: Any) -> dict[str, Any]:
        """Validate a whole document (missing fields take defaults), save it, and accept it.
        Raises :class:`ConfigError` (invalid) or ``OSError`` (not saved) and changes
        nothing."""
        return self.apply(doc).document

    def patch(self, patch: Any) -> dict[str, Any]:
        """Merge ``patch`` into the accepted document (JSON merge patch), then as
        :meth:`replace`."""
        return self.apply(patch, merge=True).document

    def apply(self, doc: Any, *, merge: bool = False) -> ConfigApplied:
        """:meth:`replace` (or :meth:`patch` with ``merge``), saying what changed and where
        it was saved; logs ``configuration applied: ...``."""
        if merge:
            check_patch(doc)
        with self._lock:
            current = config_document(self._tracker, self._ingest)
            new = self._accept(merge_patch(current, doc) if merge else doc)
        applied = ConfigApplied(new, tuple(config_changes(current, new)), self.path)
        log.info("configuration applied: %s", applied.summary())
        return applied

    def take_pending(self) -> tuple[TrackerConfig, IngestConfig] | None:
        """What was accepted since the last call (the latest only), or ``None``."""
        if self._pending is None:  # the common case, without the lock
            return None
        with self._lock:
            pending, self._pending = self._pending, None
        return pending

    def _accept(self, doc: Any) -> dict[str, Any]:
        tracker, ingest = validate_config_document(doc, self.ingest_defaults)
        out = config_document(tracker, ingest)
        if self.path is not None:
            try:
                save_config_file(self.path, out)
            except OSError as exc:
                raise OSError(f"could not save {self.path}: {exc}") from exc
        self._tracker = tracker
        self._ingest = ingest
        self._pending = (tracker, ingest)
        return out
