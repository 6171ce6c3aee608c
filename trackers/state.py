"""The tracking pipeline's state as plain data, and as bytes that are safe to load.

A tracker that can be saved hands out a :class:`StateSection`: JSON values (numbers, strings,
lists, ``None``) and numeric arrays (bool, integer, float; never objects). Strings that live
in arrays (track ids, detection ids) are packed as UTF-8 bytes with their lengths
(:func:`pack_strings`), so every array is a plain number array. A
:class:`PipelineState` holds the point tracker's section, one section per peer kind, and the
pipeline's last processed time.

:func:`encode_state` writes a state as an uncompressed ``.npz`` (a zip of ``.npy`` arrays)
with a JSON ``header`` member: the format name and version, the sections' values, the
pipeline's time, and the caller's own ``meta`` (the service puts its report counter and the
wall-clock time of the save there). :func:`decode_state` reads it back without pickle: every
member must be one the header declares, each array's header is read and checked (a number
dtype, a size that fits its member) before the array is, and any defect raises
:class:`StateError` with a sentence saying what. Each tracker then checks its own section
(shapes, finite numbers, consistent lengths) with a :class:`SectionReader` before anything
changes.
"""

from __future__ import annotations

import io
import json
import math
import re
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "FORMAT",
    "VERSION",
    "PipelineState",
    "SectionReader",
    "StateError",
    "StateSection",
    "check_id_counter",
    "decode_state",
    "encode_state",
    "pack_strings",
    "positive_definite",
    "put_string_groups",
    "put_strings",
    "unpack_strings",
]

#: The name every state file carries in its header.
FORMAT = "open-tracker.pipeline-state"
#: The layout version this code writes and reads.
VERSION = 1

_NAME = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")
_NUMBER_KINDS = frozenset("biuf")
_HEADER = "header"
_NPY_HEADERS = {
    (1, 0): np.lib.format.read_array_header_1_0,
    (2, 0): np.lib.format.read_array_header_2_0,
}


class StateError(ValueError):
    """A saved state that cannot be used; the message says why. Nothing was changed."""


@dataclass(frozen=True, eq=False)
class StateSection:
    """One tracker's state as plain data: ``values`` are JSON values, ``arrays`` number
    arrays (bool, integer or float) by name."""

    values: Mapping[str, Any] = field(default_factory=dict)
    arrays: Mapping[str, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class PipelineState:
    """The whole pipeline: its last processed time, the point tracker's kind and section,
    a section per peer kind, and ``learned``, a section per thing the pipeline learns of
    the sensors outside the trackers (``coverage``: the learned coverage boxes; values only,
    absent from files written before it was saved)."""

    last_time: float | None
    point_kind: str
    point: StateSection
    peers: Mapping[str, StateSection] = field(default_factory=dict)
    learned: Mapping[str, StateSection] = field(default_factory=dict)


# -- strings in arrays ----------------------------------------------------------------------


def pack_strings(items: Sequence[str | None]) -> tuple[np.ndarray, np.ndarray]:
    """``items`` as ``(utf8, lengths)``: their UTF-8 bytes end to end (uint8) and each one's
    byte length (int64), ``-1`` for ``None``."""
    encoded = [b"" if s is None else s.encode("utf-8") for s in items]
    lengths = np.fromiter(
        (-1 if s is None else len(e) for s, e in zip(items, encoded, strict=True)),
        dtype=np.int64,
        count=len(encoded),
    )
    return np.frombuffer(b"".join(encoded), dtype=np.uint8), lengths


def _bounds(sizes: np.ndarray) -> tuple[list[int], list[int]]:
    """Start and end of consecutive pieces of ``sizes``."""
    ends = np.cumsum(sizes)
    return (ends - sizes).tolist(), ends.tolist()


def unpack_strings(utf8: np.ndarray, lengths: np.ndarray, where: str) -> list[str | None]:
    """The strings :func:`pack_strings` packed; :class:`StateError` naming ``where`` when the
    lengths do not match the bytes or the bytes are not UTF-8."""
    if utf8.dtype != np.uint8 or utf8.ndim != 1:
        raise StateError(f"{where}: the string bytes must be a uint8 vector")
    if lengths.ndim != 1 or lengths.dtype.kind not in "iu" or (lengths < -1).any():
        raise StateError(f"{where}: string lengths must be a vector of integers >= -1")
    sizes = np.maximum(lengths, 0)
    if int(sizes.sum()) != utf8.size:
        raise StateError(
            f"{where}: the string lengths add up to {int(sizes.sum())} bytes, not {utf8.size}"
        )
    raw = utf8.tobytes()
    starts, ends = _bounds(sizes)
    try:
        return [
            None if n < 0 else raw[a:b].decode("utf-8")
            for a, b, n in zip(starts, ends, lengths.tolist(), strict=True)
        ]
    except UnicodeDecodeError as exc:
        raise StateError(f"{where}: a string is not UTF-8 ({exc.reason})") from None


def put_strings(arrays: dict[str, np.ndarray], name: str, items: Sequence[str | None]) -> None:
    """``items`` into ``arrays`` as ``name.utf8`` and ``name.len`` (:func:`pack_strings`), as
    :meth:`SectionReader.strings` reads them."""
    arrays[f"{name}.utf8"], arrays[f"{name}.len"] = pack_strings(items)


def put_string_groups(
    arrays: dict[str, np.ndarray], name: str, groups: Sequence[Sequence[str]]
) -> None:
    """Tuples of strings into ``arrays``: their strings end to end and each tuple's count
    (``name.count``), as :meth:`SectionReader.string_groups` reads them."""
    put_strings(arrays, name, [s for g in groups for s in g])
    arrays[f"{name}.count"] = np.array([len(g) for g in groups], dtype=np.int64)


def check_id_counter(
    ids: Sequence[str], next_id: int, prefix: str, letter: str, where: str
) -> None:
    """Raise :class:`StateError` (naming ``where``) when the id counter ``next_id`` would give
    again one of ``ids`` of the form ``{prefix}{letter}{n}``."""
    numbered = re.compile(rf"^{re.escape(letter)}[0-9]{{1,18}}$")
    own = [s.removeprefix(prefix) for s in ids if s.startswith(prefix)]
    top = max((int(s[len(letter) :]) for s in own if numbered.match(s)), default=0)
    if top >= next_id:
        raise StateError(
            f"{where}: next_id {next_id} would give again the id {prefix}{letter}{top}"
        )


def check_tracks(
    where: str,
    ids: Sequence[str],
    next_id: int,
    prefix: str,
    letter: str,
    *,
    created: np.ndarray,
    updated: np.ndarray,
    time: np.ndarray,
    score: np.ndarray,
    peak: np.ndarray,
) -> None:
    """The checks every saved table of tracks passes, :class:`StateError` naming ``where``:
    the ids unique and not empty, the id counter ahead of them (:func:`check_id_counter`),
    ``created <= updated <= time`` for each track (its own time: one started by hand may be
    ahead of the last scan) and its peak score not below its score."""
    if len(set(ids)) != len(ids) or not all(ids):
        raise StateError(f"{where}: track ids must be unique and not empty")
    check_id_counter(ids, next_id, prefix, letter, where)
    if (created > updated).any() or (updated > time).any():
        raise StateError(
            f"{where}: track times must satisfy created <= updated <= the track's time"
        )
    if (peak < score).any():
        raise StateError(f"{where}: a track's peak score is below its score")


# -- reading a section ----------------------------------------------------------------------


def positive_definite(M: np.ndarray) -> bool:
    """Whether every matrix of ``M (..., d, d)`` is symmetric (to 1e-6 of its largest entry)
    and positive definite (it has a Cholesky factor)."""
    M = np.asarray(M, dtype=float)
    if M.size == 0:
        return True
    scale = np.abs(M).max(axis=(-2, -1), keepdims=True)
    if (np.abs(M - np.swapaxes(M, -1, -2)) > 1e-6 * scale).any():
        return False
    try:
        np.linalg.cholesky(0.5 * (M + np.swapaxes(M, -1, -2)))
    except np.linalg.LinAlgError:
        return False
    return True


class SectionReader:
    """Reads one section and checks every value as it goes; each failure is a
    :class:`StateError` naming ``where`` and the field. :meth:`finish` refuses any array that
    was not read (a file of another layout)."""

    def __init__(self, section: StateSection, where: str) -> None:
        self.values = section.values
        self.arrays = dict(section.arrays)
        self.where = where

    def _value(self, name: str) -> Any:
        if name not in self.values:
            raise StateError(f"{self.where}.{name}: missing")
        return self.values[name]

    def integer(self, name: str, *, ge: int) -> int:
        v = self._value(name)
        if not (isinstance(v, int) and not isinstance(v, bool) and v >= ge):
            raise StateError(f"{self.where}.{name}: must be an integer >= {ge}, got {v!r}")
        return v

    def time(self, name: str) -> float | None:
        v = self._value(name)
        if v is None:
            return None
        if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)):
            raise StateError(f"{self.where}.{name}: must be a finite number or null, got {v!r}")
        return float(v)

    def names(self, name: str) -> tuple[str, ...]:
        v = self._value(name)
        if not (isinstance(v, list) and v and all(isinstance(s, str) and s for s in v)):
            raise StateError(f"{self.where}.{name}: must be a non-empty list of names")
        if len(set(v)) != len(v):
            raise StateError(f"{self.where}.{name}: a name appears twice")
        return tuple(v)

    def _array(self, name: str, kinds: str, shape: tuple[int, ...]) -> np.ndarray:
        a = self.arrays.pop(name, None)
        if a is None:
            raise StateError(f"{self.where}.{name}: missing")
        if a.dtype.kind not in kinds:
            raise StateError(f"{self.where}.{name}: wrong type {a.dtype}")
        if a.shape != shape:
            raise StateError(f"{self.where}.{name}: shape {a.shape}, expected {shape}")
        return a

    def floats(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """A float64 array of ``shape``, every entry finite."""
        a = self._array(name, "f", shape).astype(np.float64, copy=False)
        if not np.isfinite(a).all():
            raise StateError(f"{self.where}.{name}: holds a number that is not finite")
        return a

    def integers(self, name: str, shape: tuple[int, ...], *, ge: int) -> np.ndarray:
        a = self._array(name, "iu", shape).astype(np.int64, copy=False)
        if a.size and int(a.min()) < ge:
            raise StateError(f"{self.where}.{name}: holds a number below {ge}")
        return a

    def has(self, name: str) -> bool:
        """Whether the section holds an array ``name`` (not read yet): for fields that files
        written by earlier versions lack."""
        return name in self.arrays

    def booleans(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        return self._array(name, "b", shape)

    def strings(self, name: str, n: int, *, optional: bool = False) -> list[str | None]:
        """``n`` strings packed under ``name.utf8`` and ``name.len`` (``None`` allowed only
        when ``optional``)."""
        utf8 = self._array(f"{name}.utf8", "u", (self._size(f"{name}.utf8"),))
        lengths = self._array(f"{name}.len", "iu", (n,))
        out = unpack_strings(utf8, lengths, f"{self.where}.{name}")
        if not optional and any(s is None for s in out):
            raise StateError(f"{self.where}.{name}: a string is missing")
        return out

    def string_groups(self, name: str, n: int) -> list[tuple[str, ...]]:
        """``n`` tuples of strings: the strings packed under ``name`` and the count of each
        tuple's strings under ``name.count``."""
        counts = self.integers(f"{name}.count", (n,), ge=0)
        flat = [s for s in self.strings(name, int(counts.sum())) if s is not None]
        starts, ends = _bounds(counts)
        return [tuple(flat[a:b]) for a, b in zip(starts, ends, strict=True)]

    def length(self, name: str) -> int:
        """The length of the 1-D array ``name`` not read yet (−1: none such)."""
        return self._size(name)

    def _size(self, name: str) -> int:
        a = self.arrays.get(name)
        return -1 if a is None or a.ndim != 1 else int(a.shape[0])

    def finish(self) -> None:
        if self.arrays:
            raise StateError(f"{self.where}: unexpected array(s) {sorted(self.arrays)}")


# -- bytes ----------------------------------------------------------------------------------


def _json_safe(value: Any, where: str) -> Any:
    try:
        return json.loads(json.dumps(value, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise StateError(f"{where}: not plain JSON values ({exc})") from None


def encode_state(state: PipelineState, meta: Mapping[str, Any] | None = None) -> bytes:
    """``state`` (and the caller's JSON ``meta``) as the bytes of an ``.npz`` file."""
    members: dict[str, np.ndarray] = {}
    peers: dict[str, Any] = {}
    sections = [("point", state.point)] + [(f"peer/{k}", s) for k, s in state.peers.items()]
    for prefix, section in sections:
        for name, a in section.arrays.items():
            a = np.asarray(a)
            if not _NAME.match(name) or a.dtype.kind not in _NUMBER_KINDS:
                raise StateError(f"{prefix}.{name}: not a named number array ({a.dtype})")
            members[f"{prefix}/{name}"] = a
    for kind, section in state.peers.items():
        if not _NAME.match(kind):
            raise StateError(f"peer kind {kind!r}: not a valid name")
        peers[kind] = {"values": dict(section.values)}
    learned: dict[str, Any] = {}
    for name, section in state.learned.items():
        if not _NAME.match(name) or section.arrays:
            raise StateError(f"learned {name!r}: a valid name, with values only")
        learned[name] = {"values": dict(section.values)}
    header = {
        "format": FORMAT,
        "version": VERSION,
        "last_time": state.last_time,
        "point": {"kind": state.point_kind, "values": dict(state.point.values)},
        "peers": peers,
        "learned": learned,
        "meta": dict(meta or {}),
    }
    text = json.dumps(_json_safe(header, "header"), allow_nan=False, separators=(",", ":"))
    members[_HEADER] = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    buf = io.BytesIO()
    np.savez(buf, **members)  # type: ignore[arg-type]
    return buf.getvalue()


def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo) -> np.ndarray:
    """One ``.npy`` member, its header checked before its data is read."""
    name = info.filename
    if info.compress_type != zipfile.ZIP_STORED:
        raise StateError(f"member {name!r} is compressed; state files are stored")
    with zf.open(info) as fh:
        try:
            version = np.lib.format.read_magic(fh)
            read_header = _NPY_HEADERS.get(version)
            if read_header is not None:
                shape, _, dtype = read_header(fh)
        except ValueError as exc:
            raise StateError(f"member {name!r}: not an array ({exc})") from None
        if read_header is None:
            raise StateError(f"member {name!r}: .npy version {version}")
        if dtype.kind not in _NUMBER_KINDS or dtype.hasobject:
            raise StateError(f"member {name!r}: {dtype} is not a number type")
        if math.prod(shape) * dtype.itemsize > info.file_size:
            raise StateError(f"member {name!r}: its shape {shape} does not fit its size")
    with zf.open(info) as fh:
        try:
            return np.lib.format.read_array(fh, allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise StateError(f"member {name!r}: unreadable ({exc})") from None


def _section_values(obj: Any, where: str) -> dict[str, Any]:
    if not isinstance(obj, dict) or not isinstance(obj.get("values"), dict):
        raise StateError(f"header.{where}: must be an object with an object 'values'")
    return dict(obj["values"])


def decode_state(data: bytes) -> tuple[PipelineState, dict[str, Any]]:
    """The state and ``meta`` that :func:`encode_state` wrote. Raises :class:`StateError`
    for anything else: not a zip, no header, another format or version, a member the header
    does not declare, an array that is not a number array."""
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
        infos = zf.infolist()
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise StateError(f"not a state file (not an .npz archive: {exc})") from None
    with zf:
        by_name: dict[str, zipfile.ZipInfo] = {}
        for info in infos:
            if not info.filename.endswith(".npy") or info.filename in by_name:
                raise StateError(f"not a state file (member {info.filename!r})")
            by_name[info.filename.removesuffix(".npy")] = info
        if _HEADER not in by_name:
            raise StateError("not a state file (no header)")
        try:
            raw = _read_member(zf, by_name.pop(_HEADER))
            header = json.loads(raw.tobytes().decode("utf-8"))
        except (zipfile.BadZipFile, UnicodeDecodeError, ValueError) as exc:
            if isinstance(exc, StateError):
                raise
            raise StateError(f"not a state file (unreadable header: {exc})") from None
        if not isinstance(header, dict) or header.get("format") != FORMAT:
            raise StateError("not a state file of this tracker (another format)")
        if header.get("version") != VERSION:
            raise StateError(
                f"state file version {header.get('version')!r}; this version reads {VERSION}"
            )
        last_time = header.get("last_time")
        if last_time is not None and not (
            isinstance(last_time, int | float)
            and not isinstance(last_time, bool)
            and math.isfinite(last_time)
        ):
            raise StateError(f"header.last_time: must be a finite number or null: {last_time!r}")
        point = header.get("point")
        point_values = _section_values(point, "point")
        kind = point.get("kind") if isinstance(point, dict) else None
        if not isinstance(kind, str):
            raise StateError("header.point.kind: must be a string")
        peers_header = header.get("peers")
        if not isinstance(peers_header, dict) or not all(_NAME.match(k) for k in peers_header):
            raise StateError("header.peers: must be an object keyed by peer kind")
        learned_header = header.get("learned", {})  # (absent from older files)
        if not isinstance(learned_header, dict) or not all(_NAME.match(k) for k in learned_header):
            raise StateError("header.learned: must be an object keyed by name")
        meta = header.get("meta")
        if not isinstance(meta, dict):
            raise StateError("header.meta: must be an object")
        point_arrays: dict[str, np.ndarray] = {}
        peer_arrays: dict[str, dict[str, np.ndarray]] = {k: {} for k in peers_header}
        try:
            for name, info in by_name.items():
                parts = name.split("/")
                if len(parts) == 2 and parts[0] == "point" and _NAME.match(parts[1]):
                    point_arrays[parts[1]] = _read_member(zf, info)
                elif len(parts) == 3 and parts[0] == "peer" and parts[1] in peer_arrays:
                    if not _NAME.match(parts[2]):
                        raise StateError(f"not a state file (member {info.filename!r})")
                    peer_arrays[parts[1]][parts[2]] = _read_member(zf, info)
                else:
                    raise StateError(f"not a state file (member {info.filename!r})")
        except zipfile.BadZipFile as exc:
            raise StateError(f"a damaged state file ({exc})") from None
    state = PipelineState(
        last_time=None if last_time is None else float(last_time),
        point_kind=kind,
        point=StateSection(point_values, point_arrays),
        peers={
            k: StateSection(_section_values(v, f"peers.{k}"), peer_arrays[k])
            for k, v in peers_header.items()
        },
        learned={
            k: StateSection(_section_values(v, f"learned.{k}"), {})
            for k, v in learned_header.items()
        },
    )
    return state, meta
