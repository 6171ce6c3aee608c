"""The peer interface: what trackers of other kinds may do in the individual tracker's step.

A *peer* is a tracker of objects that give many detections a scan or that hold several point
targets together: extended objects and groups (random matrices, paper 002), formations
(template matching, paper 003), bending targets (point patterns, papers 000 and 001). Each
scan, every peer sees the scan and the individual tracks predicted to the scan's time, and
*proposes* what it will do; only when every peer and the point tracker have proposed without
error does any of them *commit*. A failure anywhere changes nothing.

A peer's :class:`PeerProposal` may

- claim detections (``claimed``): a claimed detection is explained by the peer; it neither
  updates nor starts an individual track;
- change the detection probability of individual tracks, by id (``pd``, computed by the
  peer however its model says, e.g. paper 002 eq. 28-30 from its extent and resolution
  distance) or by geometry (``cells``: every track predicted inside the ellipse); where
  several requests reach one track the lowest probability holds;
- take over individual tracks (``take``): they leave the individual tracker at this scan,
  keeping their ids, and the peer updates and reports them from then on (a formation takes its
  members; an extended track absorbs the individual tracks that turn out to be one convoy);
- hand tracks back (``hand_back``): full states that the individual tracker adopts at this
  scan under their ids (a member leaving a formation, a convoy splitting);
- report its own tracks (``tracks``) and the ids it deleted (``deleted``).

What the first peers will call, written down before the interface was built:

- extended (random matrix): ``propose(scan, view)`` gates ``scan.z`` against each extent
  ellipse, partitions the gated detections by resolution distance, updates centroid and
  extent with the likeliest partition and claims it; sets ``pd`` of each track of ``view``
  whose predicted position ``view.x[:, :2]`` lies in its resolution cell; takes the ids of
  individual tracks that move with it; hands back :class:`PointTrackState` when it splits.
- formation (template matching): ``propose(scan, view)`` gates formation centres, matches the
  template to the detections, updates its members with the matched ones and claims them;
  takes over member tracks by id when it recognises a formation among ``view``'s confirmed
  tracks; hands a member back when it leaves.

The point tracker (GNN today, a track-oriented MHT later) sits behind :class:`PointTracker`:
it predicts its tracks for the peers, then proposes its step under the peers'
:class:`PointDirectives`, and commits.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from trackers.state import StateSection
from trackers.types import Scan, StepResult, TrackSnapshot

if TYPE_CHECKING:
    from trackers.association.gating import GatedPairs
    from trackers.config import TrackerConfig

__all__ = [
    "HeldDetections",
    "NumbersTracks",
    "PeerError",
    "PeerProposal",
    "PeerTracker",
    "PersistentTracker",
    "PointDirectives",
    "PointProposal",
    "PointTrackState",
    "PointTrackView",
    "PointTracker",
    "ResolutionCell",
    "SavesImmutableState",
    "StateCheckpoint",
    "check_proposal",
    "combine_directives",
]


class PeerError(RuntimeError):
    """A peer failed or proposed something impossible; the message names the peer."""

    def __init__(self, kind: str, detail: str) -> None:
        super().__init__(f"peer {kind!r}: {detail}")
        self.kind = kind
        self.detail = detail


def _read_only(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class ResolutionCell:
    """The ellipse ``(p − c)ᵀ M⁻¹ (p − c) ≤ 1`` inside which individual targets are detected
    with probability ``pd`` (often much lower than the sensor's: the peer's object masks them)."""

    center: np.ndarray
    matrix: np.ndarray
    pd: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _read_only(np.reshape(self.center, 2)))
        object.__setattr__(self, "matrix", _read_only(np.reshape(self.matrix, (2, 2))))

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask of the ``(n, 2)`` points inside the cell."""
        d = np.asarray(points, dtype=float).reshape(-1, 2) - self.center
        return np.einsum("ni,ij,nj->n", d, np.linalg.inv(self.matrix), d) <= 1.0


@dataclass(frozen=True)
class PointTrackState:
    """A point track's full state, as handed between trackers.

    ``x`` is ``[x, y, vx, vy, ω]`` (m, m/s, rad/s) with covariance ``P`` (5x5); ``score`` the
    track's log-likelihood ratio; ``time`` the instant of ``x``; ``instants`` the distinct
    times of its ``hits`` detections (``None``: as many as its hits).
    """

    id: str
    time: float
    x: np.ndarray
    P: np.ndarray
    score: float
    hits: int
    confirmed: bool
    created: float
    updated: float
    instants: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "x", _read_only(np.reshape(self.x, 5)))
        object.__setattr__(self, "P", _read_only(np.reshape(self.P, (5, 5))))


@dataclass(frozen=True, eq=False)
class PointTrackView:
    """The point tracker's live tracks predicted to ``time``, read-only: row ``i`` is track
    ``ids[i]``, ``x (N, 5)`` its predicted state ``[x, y, vx, vy, ω]`` and ``P (N, 5, 5)`` its
    covariance (moment-matched over the IMM modes); ``created`` and ``updated`` the times of
    its first and latest detection. ``gated``, when the point tracker gives it: for a scan,
    the pairs (rows of this view, rows of the scan) in the point tracker's own χ² gate on
    ``x``, ``P`` and the detections' covariances, and that gate's ``γ``; found once a scan
    and shared with the point tracker's update when the peers claim nothing (a view with
    tracks left out has none)."""

    time: float
    ids: tuple[str, ...]
    x: np.ndarray
    P: np.ndarray
    score: np.ndarray
    hits: np.ndarray
    confirmed: np.ndarray
    created: np.ndarray
    updated: np.ndarray
    gated: Callable[[Scan], tuple[GatedPairs, float]] | None = field(
        default=None, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        for name in ("x", "P", "score", "created", "updated"):
            object.__setattr__(self, name, _read_only(getattr(self, name)))
        for name, dtype in (("hits", np.int64), ("confirmed", bool)):
            a = np.array(getattr(self, name), dtype=dtype, copy=True)
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return len(self.ids)

    def index(self) -> dict[str, int]:
        """Row of each id."""
        return {tid: i for i, tid in enumerate(self.ids)}

    def state(self, i: int) -> PointTrackState:
        """Row ``i`` as a :class:`PointTrackState`."""
        return PointTrackState(
            id=self.ids[i],
            time=self.time,
            x=self.x[i],
            P=self.P[i],
            score=float(self.score[i]),
            hits=int(self.hits[i]),
            confirmed=bool(self.confirmed[i]),
            created=float(self.created[i]),
            updated=float(self.updated[i]),
        )


@dataclass(frozen=True, eq=False)
class PeerProposal:
    """What a peer proposes for one scan (see the module docstring). ``claimed`` is a boolean
    mask over the scan's detections; ``state`` is the peer's own new state, given back to its
    :meth:`PeerTracker.commit` unread by anyone else."""

    claimed: np.ndarray
    pd: Mapping[str, float] = field(default_factory=dict)
    cells: tuple[ResolutionCell, ...] = ()
    take: tuple[str, ...] = ()
    hand_back: tuple[PointTrackState, ...] = ()
    tracks: tuple[TrackSnapshot, ...] = ()
    deleted: tuple[str, ...] = ()
    state: Any = None


class PeerTracker(Protocol):
    """A tracker of another kind that takes part in every scan.

    ``propose`` must not change the peer (it may be called and its proposal dropped, when
    another tracker fails); ``commit`` makes the proposal the peer's state and must not fail.
    ``reconfigure`` receives the whole configuration tree; a peer reads its own section.
    """

    kind: str

    def propose(self, scan: Scan, view: PointTrackView) -> PeerProposal: ...

    def commit(self, proposal: PeerProposal) -> None: ...

    def snapshot(self) -> tuple[TrackSnapshot, ...]: ...

    def reconfigure(self, config: TrackerConfig) -> None: ...

    def reset(self) -> None:
        """Drop every track and what was learned, keeping the configuration and the id
        counter (:meth:`trackers.pipeline.TrackingPipeline.reset`)."""
        ...


class StateCheckpoint(Protocol):
    """A tracker's state as it was at one moment, turned into plain data later, on any
    thread (:mod:`trackers.state`)."""

    def export(self) -> StateSection: ...


@runtime_checkable
class PersistentTracker(Protocol):
    """Optional, for peers and point trackers: a tracker whose state survives a restart.

    ``checkpoint`` is called between scans and must cost next to nothing (hold the state's
    immutable parts; the work is in :meth:`StateCheckpoint.export`), and must stay valid
    however the tracker moves on. ``check_state`` reads a section that an export wrote and
    returns it checked (shapes, finite numbers, consistent lengths), raising
    :class:`~trackers.state.StateError` without changing anything; ``restore_state`` puts a
    checked state in place and must not fail, so that the pipeline restores all of its
    trackers or none. The configuration in force stays; a saved state made under another one
    is adapted to it or refused. A peer without these methods is not saved: it starts empty
    after a restart.
    """

    def checkpoint(self) -> StateCheckpoint: ...

    def check_state(self, section: StateSection) -> Any: ...

    def restore_state(self, checked: Any) -> None: ...


@runtime_checkable
class NumbersTracks(Protocol):
    """Optional, for peers and point trackers: a tracker that numbers its tracks' ids from a
    counter. ``skip_ids(first)`` makes it give no id numbered below ``first`` (a counter
    already past it stays): the service moves the counters past the ids a run before a
    restart gave, so that no id is given twice (:meth:`TrackingPipeline.skip_ids
    <trackers.pipeline.TrackingPipeline.skip_ids>`)."""

    @property
    def next_id(self) -> int: ...

    def skip_ids(self, first: int) -> None: ...


class SavesImmutableState:
    """The :class:`PersistentTracker` methods of a tracker whose whole state is one immutable
    object, ``self._state`` (so a checkpoint just holds it): the class names its checkpoint
    type, ``_checkpoint_type(state)`` with an ``export()``, and ``_read_state(section, state,
    id_prefix)``, which reads an exported section back under the configuration of ``state``
    (the one in force) and raises :class:`~trackers.state.StateError` saying why it cannot."""

    _state: Any
    id_prefix: str
    _checkpoint_type: Callable[[Any], StateCheckpoint]
    _read_state: Callable[[StateSection, Any, str], Any]

    def checkpoint(self) -> StateCheckpoint:
        """The committed state, to export later on any thread (free: it is immutable)."""
        return self._checkpoint_type(self._state)

    def export_state(self) -> StateSection:
        return self.checkpoint().export()

    def check_state(self, section: StateSection) -> Any:
        """A section that :meth:`export_state` wrote, read and checked under the
        configuration in force; :class:`~trackers.state.StateError` when it cannot be used."""
        return self._read_state(section, self._state, self.id_prefix)

    def restore_state(self, checked: Any) -> None:
        """Put a state that :meth:`check_state` returned in place of the current one."""
        if type(checked) is not type(self._state):
            raise TypeError("restore_state takes what check_state returned")
        self._state = checked

    def import_state(self, section: StateSection) -> None:
        self.restore_state(self.check_state(section))

    #: The fields of ``self._state`` that :meth:`reset` keeps (the configuration and the id
    #: counter); the others go back to their defaults.
    _kept_on_reset: tuple[str, ...] = ()

    @property
    def next_id(self) -> int:
        """The number of the next track's id (:class:`NumbersTracks`)."""
        return int(self._state.next_id)

    def skip_ids(self, first: int) -> None:
        """Give no id numbered below ``first`` from now on (:class:`NumbersTracks`)."""
        if int(first) > self._state.next_id:
            self._state = replace(self._state, next_id=int(first))

    def reset(self) -> None:
        """Drop every track and what was learned; the configuration and the id counter stay,
        so new ids go on from the last one given."""
        st = self._state
        self._state = type(st)(**{k: getattr(st, k) for k in self._kept_on_reset})


@dataclass(frozen=True)
class PointDirectives:
    """What the peers ask of the point tracker for one scan: the detection probability of
    named tracks (``pd``, the resolution cells' already folded in; the sensor's elsewhere),
    the ids the peers take over (``release``) and the tracks they hand back (``adopt``,
    as of the scan's time). ``hand_in``: tracks another tracker (an instance watching the
    next sector) hands over, each as of its own time: predicted to the scan and updated
    with it, or merged into a local track that follows the same target."""

    pd: Mapping[str, float] = field(default_factory=dict)
    release: frozenset[str] = frozenset()
    adopt: tuple[PointTrackState, ...] = ()
    hand_in: tuple[PointTrackState, ...] = ()


@dataclass(frozen=True, eq=False)
class HeldDetections:
    """Detections of a scan that tentative tracks hold back from the clutter map until their
    fate is known (:mod:`trackers.clutter`): ``rows`` of the point tracker's scan, the id of
    the track holding each (``holders``) and each detection's ``serials`` (unique across
    scans; a detection two tracks took comes twice, with one serial). ``earlier`` are the
    serials of detections of earlier scans that the map counted and now takes back to hold
    them too, for the tracks ``earlier_holders`` (one a serial): the first two of a track
    that took its third (:meth:`~trackers.clutter.ClutterMap.reclaim`)."""

    rows: np.ndarray
    holders: tuple[str, ...]
    serials: np.ndarray
    earlier: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    earlier_holders: tuple[str, ...] = ()
    #: the row of the point tracker's scan that each of them took now (its third), one a
    #: serial of ``earlier``
    earlier_thirds: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))

    @staticmethod
    def none() -> HeldDetections:
        return HeldDetections(np.zeros(0, dtype=np.intp), (), np.zeros(0, dtype=np.int64))


@dataclass(frozen=True, eq=False)
class PointProposal:
    """A point tracker's proposed step: ``result`` is what the step returns once committed,
    ``released`` the states of the tracks the peers took; ``state`` is private to the tracker.
    ``clutter``, when the tracker says, marks the scan's detections that no confirmed track
    took or had in its gate and no track of three or more detections took (what the
    pipeline's clutter map counts); ``held`` are those of the last kind that tentative tracks
    took (and earlier ones of theirs), and ``accepted`` and ``rejected`` the ids of the
    tracks whose held detections are now known to be a target's (or another reading's of
    one) or false alarms."""

    result: StepResult
    released: tuple[PointTrackState, ...]
    state: Any
    clutter: np.ndarray | None = None
    held: HeldDetections = field(default_factory=HeldDetections.none)
    accepted: tuple[str, ...] = ()
    rejected: tuple[str, ...] = ()
    #: the serial number the tracker gave the scan's first detection (its others follow in
    #: order; −1: it numbers none), what ``held`` and the map know detections by
    first_serial: int = -1


class PointTracker(Protocol):
    """The tracker of individual point targets inside the pipeline (GNN today; a
    track-oriented MHT later), interchangeable by configuration."""

    kind: str

    @property
    def config(self) -> TrackerConfig: ...

    def reconfigure(self, config: TrackerConfig) -> None: ...

    def predicted(self, time: float) -> PointTrackView: ...

    def propose(self, scan: Scan, directives: PointDirectives = ...) -> PointProposal: ...

    def commit(self, proposal: PointProposal) -> None: ...

    def snapshot(self, confirmed_only: bool = False) -> tuple[TrackSnapshot, ...]: ...

    def reset(self) -> None:
        """Drop every track and what was learned, keeping the configuration and the id
        counters."""
        ...


def check_proposal(kind: str, proposal: object, scan: Scan, view: PointTrackView) -> None:
    """Raise :class:`PeerError` naming ``kind`` unless ``proposal`` is a :class:`PeerProposal`
    whose ``claimed`` mask fits the scan, whose ``pd`` names live tracks with probabilities in
    (0, 1], whose ``take`` names live tracks once each, and whose ``hand_back`` states are
    finite with fresh ids."""
    if not isinstance(proposal, PeerProposal):
        raise PeerError(kind, f"propose returned {type(proposal).__name__}, not a PeerProposal")
    claimed = np.asarray(proposal.claimed)
    if claimed.dtype != bool or claimed.shape != (scan.size,):
        raise PeerError(
            kind,
            f"claimed must be a boolean mask of {scan.size} detections, "
            f"got {claimed.dtype} of shape {claimed.shape}",
        )
    live = set(view.ids)
    for tid, p in proposal.pd.items():
        if tid not in live:
            raise PeerError(kind, f"pd names track {tid!r}, which is not a live point track")
        if not (isinstance(p, int | float) and 0 < p <= 1):
            raise PeerError(kind, f"pd of track {tid!r} must be in (0, 1], got {p!r}")
    for cell in proposal.cells:
        if not (0 < cell.pd <= 1) or not np.isfinite(cell.center).all():
            raise PeerError(kind, "a resolution cell needs a finite centre and pd in (0, 1]")
        M = cell.matrix
        if not (np.isfinite(M).all() and M[0, 0] > 0 and np.linalg.det(M) > 0):
            raise PeerError(kind, "a resolution cell's matrix must be positive definite")
    if len(set(proposal.take)) != len(proposal.take):
        raise PeerError(kind, "take names a track twice")
    for tid in proposal.take:
        if tid not in live:
            raise PeerError(kind, f"take names track {tid!r}, which is not a live point track")
    seen: set[str] = set()
    for st in proposal.hand_back:
        if not isinstance(st, PointTrackState):
            raise PeerError(kind, "hand_back holds something other than a PointTrackState")
        if st.id in live or st.id in seen:
            raise PeerError(kind, f"hand_back id {st.id!r} is already a live point track")
        seen.add(st.id)
        if not (np.isfinite(st.x).all() and np.isfinite(st.P).all() and math.isfinite(st.score)):
            raise PeerError(kind, f"hand_back track {st.id!r} has a non-finite state or score")
        P = st.P
        if not np.allclose(P, P.T) or np.linalg.eigvalsh(P).min() <= 0:
            raise PeerError(
                kind, f"hand_back track {st.id!r}: P is not symmetric positive definite"
            )
        if abs(st.time - scan.time) > 1e-9:
            raise PeerError(kind, f"hand_back track {st.id!r} is at {st.time}, not the scan's time")


def combine_directives(
    kinds: tuple[str, ...], proposals: tuple[PeerProposal, ...], view: PointTrackView
) -> PointDirectives:
    """The point tracker's directives from every peer's (checked) proposal: cells and per-track
    probabilities with the lowest holding where they meet; a track taken or an id handed back
    by two peers is an error naming the second."""
    pd: dict[str, float] = {}
    cells: list[ResolutionCell] = []
    taken: dict[str, str] = {}
    adopt: list[PointTrackState] = []
    handed: dict[str, str] = {}
    for kind, prop in zip(kinds, proposals, strict=True):
        for tid, p in prop.pd.items():
            pd[tid] = min(pd.get(tid, 1.0), float(p))
        cells.extend(prop.cells)
        for tid in prop.take:
            if tid in taken:
                raise PeerError(kind, f"track {tid!r} is already taken by peer {taken[tid]!r}")
            taken[tid] = kind
        for st in prop.hand_back:
            if st.id in handed:
                raise PeerError(kind, f"id {st.id!r} is also handed back by peer {handed[st.id]!r}")
            handed[st.id] = kind
            adopt.append(st)
    if cells and len(view):
        xy = view.x[:, :2]
        for cell in cells:
            for i in np.flatnonzero(cell.contains(xy)).tolist():
                tid = view.ids[i]
                pd[tid] = min(pd.get(tid, 1.0), cell.pd)
    return PointDirectives(pd=pd, release=frozenset(taken), adopt=tuple(adopt))
