"""One tracking step over all track kinds.

The pipeline checks a scan once, then runs its trackers in two phases (see
:mod:`trackers.peers`): every *peer* (extended objects, formations, point patterns) proposes
what it would do with the scan, seeing the point tracks predicted to the scan's time; the
*point tracker* proposes its step on the detections no peer claimed, under what the peers
asked of it (detection probabilities, tracks taken over and handed back); only then does each
commit. A scan that says nothing of its coverage is given the area its sensor has been
seeing things in while several sensors report (:mod:`trackers.coverage`), so that a track out
of its view is not counted as missed. A rejected scan raises
:class:`~trackers.types.ScanRejected`, and a failing or ill-formed peer
:class:`~trackers.peers.PeerError`, before any tracker has changed.

The point tracker is chosen by ``association.method`` (:data:`POINT_TRACKERS`) or injected.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any, cast

import numpy as np

from trackers.clutter import MAX_SENSORS as MAX_MAPPED_SENSORS
from trackers.clutter import ClutterMap
from trackers.config import TrackerConfig
from trackers.coverage import CoverageLearner, LearnerSnapshot, polygon_arc
from trackers.extended.tracker import ExtendedTracker
from trackers.formation.tracker import FormationTracker
from trackers.individual import IndividualTracker
from trackers.pattern.tracker import PatternTracker
from trackers.peers import (
    NumbersTracks,
    PeerError,
    PeerProposal,
    PeerTracker,
    PersistentTracker,
    PointDirectives,
    PointProposal,
    PointTracker,
    PointTrackState,
    PointTrackView,
    StateCheckpoint,
    check_proposal,
    combine_directives,
)
from trackers.state import PipelineState, StateError, StateSection
from trackers.types import Scan, ScanRejected, StepResult, TrackSnapshot

__all__ = [
    "MAX_ABS_POSITION",
    "MAX_ABS_TIME",
    "MAX_VARIANCE",
    "POINT_TRACKERS",
    "PipelineCheckpoint",
    "TrackingPipeline",
    "check_scan",
    "make_point_tracker",
    "standard_peers",
]

#: Largest |x| or |y| a detection may have (m): far beyond any sensor of a local frame, and
#: small enough that squared distances and covariances stay finite in double precision.
MAX_ABS_POSITION = 1e9
#: Largest magnitude of a detection covariance entry (m²): a standard deviation of 10,000 km.
MAX_VARIANCE = 1e14
#: Largest magnitude of a scan's time (s): about 31,700 years from the epoch, so differences
#: of times keep a resolution of 0.1 ms.
MAX_ABS_TIME = 1e12


#: The point trackers by ``association.method``.
POINT_TRACKERS: dict[str, Callable[..., PointTracker]] = {"gnn": IndividualTracker}


def make_point_tracker(config: TrackerConfig, *, id_prefix: str = "") -> PointTracker:
    """The point tracker that ``config.association.method`` names; ``id_prefix`` before
    every new track's id."""
    return POINT_TRACKERS[config.association.method](config, id_prefix=id_prefix)


def standard_peers(config: TrackerConfig, *, id_prefix: str = "") -> tuple[PeerTracker, ...]:
    """One of each peer kind, in the order they see a scan: targets showing a configured
    point pattern (:mod:`trackers.pattern`; nothing without patterns), whose detections no
    other peer sees, then extended objects and groups (:mod:`trackers.extended`), then
    formations (:mod:`trackers.formation`), which see neither the detections nor the tracks
    the extended tracker took: a convoy of unresolved returns is never a formation."""
    return (
        PatternTracker(config, id_prefix=id_prefix),
        ExtendedTracker(config, id_prefix=id_prefix),
        FormationTracker(config, id_prefix=id_prefix),
    )


def _view_without(view: PointTrackView, taken: set[str]) -> PointTrackView:
    """``view`` less the tracks ``taken``."""
    keep = np.array([tid not in taken for tid in view.ids], dtype=bool)
    idx = np.flatnonzero(keep)
    return PointTrackView(
        time=view.time,
        ids=tuple(view.ids[i] for i in idx.tolist()),
        x=np.take(view.x, idx, axis=0),
        P=np.take(view.P, idx, axis=0),
        score=view.score[idx],
        hits=view.hits[idx],
        confirmed=view.confirmed[idx],
        created=view.created[idx],
        updated=view.updated[idx],
    )


def check_scan(scan: Scan, last_time: float | None) -> None:
    """Raise :class:`ScanRejected` unless the scan's numbers are usable and in time order.

    Checks: finite time within ``±MAX_ABS_TIME`` not older than ``last_time``; finite
    positions with ``|x|, |y| ≤ MAX_ABS_POSITION``; symmetric positive definite covariances
    with entries ``≤ MAX_VARIANCE`` in magnitude; ``pd`` in (0, 1] and ``clutter_density``
    > 0 when given; a finite ``sensor_position`` (within ``±MAX_ABS_POSITION``) and
    ``sensor_velocity`` when given.
    """
    if not math.isfinite(scan.time):
        raise ScanRejected("invalid_scan", "time: not a finite number")
    if abs(scan.time) > MAX_ABS_TIME:
        raise ScanRejected("invalid_scan", f"time: beyond ±{MAX_ABS_TIME:g} s")
    if last_time is not None and scan.time < last_time:
        raise ScanRejected(
            "out_of_sequence",
            f"time {scan.time} is older than the last processed time {last_time}",
        )
    if scan.size:
        R = scan.R
        # NaN fails both comparisons too: then the checks below name the first bad detection.
        if not (np.abs(scan.z).max() <= MAX_ABS_POSITION and np.abs(R).max() <= MAX_VARIANCE):
            _check_magnitudes(scan.z, R)
        asym = np.abs(R[:, 0, 1] - R[:, 1, 0]) > 1e-9 * (1.0 + np.abs(R[:, 0, 1]))
        det = R[:, 0, 0] * R[:, 1, 1] - R[:, 0, 1] * R[:, 1, 0]
        bad = np.flatnonzero(asym | (R[:, 0, 0] <= 0) | (det <= 0))
        if bad.size:
            raise ScanRejected(
                "invalid_scan", f"detections[{bad[0]}].cov: not symmetric positive definite"
            )
    if scan.pd is not None and not (0 < scan.pd <= 1):
        raise ScanRejected("invalid_scan", f"pd: must be in (0, 1], got {scan.pd}")
    if scan.clutter_density is not None and not (
        math.isfinite(scan.clutter_density) and scan.clutter_density > 0
    ):
        raise ScanRejected("invalid_scan", "clutter_density: must be a finite number > 0")
    for name in ("sensor_position", "sensor_velocity"):
        value = getattr(scan, name)
        if value is not None and not np.isfinite(value).all():
            raise ScanRejected("invalid_scan", f"{name}: not finite")
    if scan.sensor_position is not None and np.abs(scan.sensor_position).max() > MAX_ABS_POSITION:
        raise ScanRejected("invalid_scan", f"sensor_position: beyond ±{MAX_ABS_POSITION:g} m")


def _check_magnitudes(z: np.ndarray, R: np.ndarray) -> None:
    """Raise :class:`ScanRejected` naming the first detection with a position or covariance
    entry that is not finite or too large."""
    bad = np.flatnonzero(~np.isfinite(z).all(axis=1))
    if bad.size:
        raise ScanRejected("invalid_scan", f"detections[{bad[0]}]: position not finite")
    bad = np.flatnonzero((np.abs(z) > MAX_ABS_POSITION).any(axis=1))
    if bad.size:
        raise ScanRejected(
            "invalid_scan",
            f"detections[{bad[0]}]: position beyond ±{MAX_ABS_POSITION:g} m",
        )
    bad = np.flatnonzero(~np.isfinite(R).all(axis=(1, 2)))
    if bad.size:
        raise ScanRejected("invalid_scan", f"detections[{bad[0]}].cov: not finite")
    bad = np.flatnonzero((np.abs(R) > MAX_VARIANCE).any(axis=(1, 2)))
    if bad.size:
        raise ScanRejected(
            "invalid_scan", f"detections[{bad[0]}].cov: an entry above {MAX_VARIANCE:g} m²"
        )


class PipelineCheckpoint:
    """The pipeline's state at one moment (:meth:`TrackingPipeline.checkpoint`), turned into
    plain data by :meth:`export`, later and on any thread."""

    def __init__(
        self,
        last_time: float | None,
        point_kind: str,
        point: StateCheckpoint,
        peers: tuple[tuple[str, StateCheckpoint], ...],
        coverage: LearnerSnapshot = (),
    ) -> None:
        self.last_time = last_time
        self.point_kind = point_kind
        self._point = point
        self._peers = peers
        self._coverage = coverage

    def export(self) -> PipelineState:
        return PipelineState(
            last_time=self.last_time,
            point_kind=self.point_kind,
            point=self._point.export(),
            peers={kind: cp.export() for kind, cp in self._peers},
            learned={"coverage": StateSection(CoverageLearner.export(self._coverage), {})},
        )


#: A stated disc (``max_range`` about the sensor) is the one the sensor's clutter map was
#: started under while its range is within this fraction of that one's ...
DISC_RANGE_CHANGE = 0.01
#: ... and its centre within this fraction of that range of that one's.
DISC_SHIFT = 0.25


def _remember(table: dict[str, Any], sensor_id: str, value: Any) -> None:
    """``table[sensor_id] = value``, the most recently heard sensor last, keeping the
    :data:`MAX_MAPPED_SENSORS` most recently heard."""
    table.pop(sensor_id, None)
    table[sensor_id] = value
    while len(table) > MAX_MAPPED_SENSORS:
        table.pop(next(iter(table)))


class TrackingPipeline:
    """Peers and the point tracker; one ``process`` call per scan, in time order."""

    def __init__(
        self,
        config: TrackerConfig | None = None,
        peers: Sequence[PeerTracker] = (),
        point_tracker: PointTracker | None = None,
    ) -> None:
        config = config or TrackerConfig()
        self.point: PointTracker = point_tracker or make_point_tracker(config)
        self.peers: tuple[PeerTracker, ...] = tuple(peers)
        kinds = [p.kind for p in self.peers]
        if len(set(kinds)) != len(kinds):
            raise ValueError(f"two peers of one kind: {kinds}")
        self._last_time: float | None = None
        self._hand_in: dict[str, PointTrackState] = {}
        self._hand_over: set[str] = set()
        # Where each sensor looks, for scans that do not say (not saved: relearned in a few
        # scans after a restart).
        self._coverage = CoverageLearner()
        # The false-alarm density of each sensor's areas, for scans that state none (not
        # saved either: it starts again from track_management.clutter_density), and the
        # disc each sensor's last mapped batch stated (max_range about its position, or None).
        self._clutter = ClutterMap()
        self._discs: dict[str, tuple[float, float, float] | None] = {}
        # The coverage polygon each sensor's last batch stated and the one its map was last
        # taught under (None: none; not saved either: _same_view).
        self._polygons: dict[str, tuple[np.ndarray | None, np.ndarray | None]] = {}

    @classmethod
    def all_kinds(
        cls, config: TrackerConfig | None = None, *, id_prefix: str = ""
    ) -> TrackingPipeline:
        """A pipeline with every track kind the trackers have: the point tracker and the
        peers of :func:`standard_peers` (each switched on and off by its configuration
        section). The service runs this one. ``id_prefix`` goes before every new track's id
        (an instance's qualifier when several instances share the work)."""
        config = config or TrackerConfig()
        return cls(
            config,
            peers=standard_peers(config, id_prefix=id_prefix),
            point_tracker=make_point_tracker(config, id_prefix=id_prefix),
        )

    @property
    def individual(self) -> PointTracker:
        """The point tracker (the individual-target tracks)."""
        return self.point

    @property
    def config(self) -> TrackerConfig:
        return self.point.config

    @property
    def last_time(self) -> float | None:
        """Time of the last processed scan, or ``None`` before the first."""
        return self._last_time

    def reconfigure(self, config: TrackerConfig) -> None:
        """Use ``config`` from the next scan on, in every tracker; tracks and ids are kept."""
        self.point.reconfigure(config)
        for peer in self.peers:
            peer.reconfigure(config)

    def reset(self) -> None:
        """Start again: every tracker drops its tracks and what it learned, the hand-overs
        waiting are dropped, the learned coverage and clutter map too, and the last processed
        time is forgotten (scans of any time are taken again). The configuration and the id
        counters stay: new ids go on from the last one given."""
        for tracker in (self.point, *self.peers):
            tracker.reset()
        self._last_time = None
        self._hand_in.clear()
        self._hand_over.clear()
        self._coverage = CoverageLearner()
        self._clutter = ClutterMap()
        self._discs = {}
        self._polygons = {}

    # -- hand-over between trackers of neighbouring sectors ---------------------------------

    def hand_in(self, states: Sequence[PointTrackState]) -> None:
        """Take over these individual tracks (from another instance) at the next scan: each
        is predicted from its own time to the scan's and updated with it under its own id,
        or gives its id to a local track that follows the same target
        (:attr:`PointDirectives.hand_in`). A later state for the same id replaces one still
        waiting; an id handed over from here and back again is kept."""
        for st in states:
            self._hand_in[st.id] = st
            self._hand_over.discard(st.id)

    def hand_over(self, ids: Sequence[str]) -> None:
        """Drop these individual tracks at the next scan: another instance has taken them
        over (they are not reported as deleted)."""
        self._hand_over.update(ids)

    def point_states(self, ids: Sequence[str]) -> tuple[PointTrackState, ...]:
        """The live individual tracks ``ids`` (unknown ids skipped) as hand-over records at
        the last processed time."""
        if self._last_time is None or not ids:
            return ()
        view = self.point.predicted(self._last_time)
        index = view.index()
        return tuple(view.state(index[tid]) for tid in ids if tid in index)

    def _with_hand_over(self, directives: PointDirectives) -> PointDirectives:
        if not (self._hand_in or self._hand_over):
            return directives
        return replace(
            directives,
            release=directives.release | self._hand_over,
            hand_in=tuple(self._hand_in.values()),
        )

    def _same_view(self, scan: Scan) -> bool:
        """Whether ``scan`` states no coverage polygon, or the one its sensor's previous batch
        stated (a fixed field of view rather than a sector). A polygon other than the one
        the sensor's map was last taught under (a camera pointed elsewhere) makes the map
        start afresh. Every batch is remembered (the :data:`MAX_MAPPED_SENSORS` most recently
        heard sensors; not saved). A radar that reports one sector in several batches, each
        stating it, would teach the map as if each looked everywhere."""
        cov = scan.coverage
        polygon = None if cov is None or cov.polygon is None else cov.polygon
        sid = scan.sensor_id
        last, taught = self._polygons.get(sid, (None, None))
        if polygon is not None and taught is not None and not np.array_equal(polygon, taught):
            self._clutter.forget(sid)
            taught = None
        same = polygon is None or (last is not None and np.array_equal(polygon, last))
        _remember(self._polygons, sid, (polygon, polygon if same else taught))
        return same

    def _map_disc(self, scan: Scan) -> bool:
        """Whether the disc the batch states (``max_range`` about its position; none) is the
        one its sensor's clutter map was started under (or the first), within
        :data:`DISC_RANGE_CHANGE` of its range and :data:`DISC_SHIFT` of its range from its
        centre: if not, the map starts afresh under this disc, and learns from the next batch
        that states about the same. A platform moving a little at every batch (a ship's
        radar, 25 m a turn) keeps its map until it has gone a quarter of its range; before
        2026-11-27 its map started afresh at every batch and never learned."""
        cov = scan.coverage
        disc = (
            None
            if cov is None or cov.centre is None or cov.max_range is None
            else (*cov.centre.tolist(), float(cov.max_range))
        )
        anchor = self._discs.get(scan.sensor_id, disc)
        same = anchor == disc
        if not same and anchor is not None and disc is not None:
            x0, y0, r0 = anchor
            x, y, r = disc
            same = (
                abs(r - r0) <= DISC_RANGE_CHANGE * r0
                and math.hypot(x - x0, y - y0) <= DISC_SHIFT * r0
            )
        _remember(self._discs, scan.sensor_id, anchor if same else disc)
        if not same:
            self._clutter.forget(scan.sensor_id)
        return same

    def _committed(self, scan: Scan, point: PointProposal, rows: np.ndarray, mapped: bool) -> None:
        """After every tracker has taken ``scan``: its time is the last, the hand-overs are
        done, and its detections say where its sensor looks and, when the scan was ``mapped``
        (scored with the clutter map), those of ``rows`` (the point tracker's, the peers'
        claims left out) that the point tracker marks as ``clutter``, how dense its false
        alarms are."""
        self._last_time = scan.time
        self._hand_in.clear()
        self._hand_over.clear()
        self._coverage.learn(scan.sensor_id, scan.time, scan.z, scan.R, scan.sensor_position)
        # A batch teaches the map as a look at every cell when it states no polygon, or the
        # one its sensor's previous batch stated (a camera's fixed field of view: cells
        # outside it never see a detection), and holds a detection (not a heartbeat). A
        # sector of a revolution (a polygon other than the previous batch's, about the
        # sensor's position, or the detections of a sensor that streams sectors without
        # saying so) is gathered with the rest of its sweep, which teaches the map once;
        # other polygons (a camera panning) teach nothing. A range alone (``max_range``) is
        # a whole revolution: its cells beyond the range never see a detection, and are never
        # looked at either while the disc stays about where it is; when it moves far or
        # changes, the sensor's map starts afresh (:meth:`_map_disc`).
        whole = self._same_view(scan)
        arc = None
        swept = False  # (an arc of detections: the sweep passed from the last one's to it)
        position = scan.sensor_position
        if position is not None:
            cov = scan.coverage
            if cov is not None and cov.polygon is not None:
                arc = None if whole else polygon_arc(cov.polygon, position)
            elif self._coverage.sweeping(scan.sensor_id):
                whole = False
                arc = self._coverage.last_arc(scan.sensor_id)  # this batch's, just learned
                swept = True
        sector = arc is not None
        held = point.held
        seen = False  # the scan's detections were counted as seen (or gathered with a sweep)
        if mapped and (sector or (whole and scan.size)) and self._map_disc(scan):
            seen = True
            mask = point.clutter
            picked = (
                np.arange(rows.size) if mask is None else np.flatnonzero(np.asarray(mask, bool))
            )
            clutter = rows.take(picked)
            serials = None if point.first_serial < 0 else point.first_serial + picked
            if arc is not None:
                self._clutter.learn_sector(
                    scan.sensor_id,
                    *arc,
                    scan.z.take(clutter, axis=0),
                    scan.R,
                    swept=swept,
                    serials=serials,
                    z_seen=scan.z,
                )
            else:
                self._clutter.learn(
                    scan.sensor_id, scan.z.take(clutter, axis=0), scan.R, serials, scan.z
                )
            if held.rows.size:
                z = scan.z.take(rows.take(held.rows), axis=0)
                self._clutter.hold(scan.sensor_id, z, held.holders, held.serials)
        if held.earlier.size:  # (counted at scans of their own, perhaps of other sensors)
            thirds = scan.z.take(rows.take(held.earlier_thirds), axis=0)
            self._clutter.reclaim(
                held.earlier,
                held.earlier_holders,
                (scan.sensor_id, thirds, arc is not None) if seen else None,
            )
        if point.accepted or point.rejected:
            self._clutter.settle(point.accepted, point.rejected)

    def process(self, scan: Scan) -> StepResult:
        """Run one scan through every tracker. Raise ``ScanRejected`` for an unusable scan and
        ``PeerError`` for a failing peer; either way no tracker changes."""
        check_scan(scan, self._last_time)
        given = scan
        learned: dict[str, Any] = {}
        stated = scan.coverage
        if stated is None:
            coverage = self._coverage.coverage(
                scan.sensor_id, scan.time, scan.z, scan.R, scan.sensor_position
            )
            if coverage is not None:
                learned["coverage"] = coverage
        elif stated.polygon is None and not stated.nowhere:
            # a range alone, from a radar that streams sectors: the sector within it
            sector = self._coverage.sector(scan.sensor_id, scan.z, scan.R, scan.sensor_position)
            if sector is not None:
                learned["coverage"] = (
                    sector
                    if sector.nowhere
                    else replace(sector, centre=stated.centre, max_range=stated.max_range)
                )
        tm = self.point.config.track_management
        mapped = scan.clutter_density is None and tm.clutter_map
        if mapped:
            learned["clutter_map"], learned["clutter_scene"] = self._clutter.read(
                scan.sensor_id, scan.z, tm.clutter_density
            )
            learned["clutter_around"] = functools.partial(
                self._clutter.around, scan.sensor_id, prior=tm.clutter_density
            )
        if learned:
            scan = replace(scan, **learned)
        if not self.peers:
            proposal = self.point.propose(scan, self._with_hand_over(PointDirectives()))
            self.point.commit(proposal)
            self._committed(given, proposal, np.arange(scan.size), mapped)
            return proposal.result
        view = self.point.predicted(scan.time)
        # The peers see the scan one after another, each without the detections claimed
        # and the tracks taken by those before it.
        proposals: list[PeerProposal] = []
        claimed = np.zeros(scan.size, dtype=bool)
        peer_scan, peer_view = scan, view
        free = np.arange(scan.size)
        for peer in self.peers:
            try:
                prop = peer.propose(peer_scan, peer_view)
            except ScanRejected:
                raise
            except Exception as exc:
                raise PeerError(peer.kind, f"{type(exc).__name__}: {exc}") from exc
            check_proposal(peer.kind, prop, peer_scan, peer_view)
            proposals.append(prop)
            if prop.claimed.any():
                claimed[free[prop.claimed]] = True
                free = np.flatnonzero(~claimed)
                peer_scan = scan.subset(~claimed)
            if prop.take:
                peer_view = _view_without(peer_view, set(prop.take))
        kinds = tuple(p.kind for p in self.peers)
        directives = self._with_hand_over(combine_directives(kinds, tuple(proposals), view))
        # (the scan itself when the peers claimed nothing: the view's gate pairs are its own)
        point = self.point.propose(scan.subset(~claimed) if claimed.any() else scan, directives)
        # Commit: every tracker has proposed without error.
        for peer, prop in zip(self.peers, proposals, strict=True):
            peer.commit(prop)
        self.point.commit(point)
        self._committed(given, point, free, mapped)
        peer_all = tuple(t for prop in proposals for t in prop.tracks)
        peer_confirmed = tuple(t for t in peer_all if t.confirmed)
        deleted = tuple(d for prop in proposals for d in prop.deleted)
        result = point.result
        return StepResult(
            time=scan.time,
            sensor_id=scan.sensor_id,
            deleted=deleted + result.deleted,
            snapshot=lambda confirmed_only: (
                (peer_confirmed if confirmed_only else peer_all) + result.snapshot(confirmed_only)
            ),
            range_rates=result.range_rates,
        )

    # -- saving and restoring --------------------------------------------------------------

    def checkpoint(self) -> PipelineCheckpoint:
        """The state between scans, to export later (:class:`PipelineCheckpoint`): it costs a
        few attribute reads, since every tracker's state is immutable. Peers that cannot be
        saved (:class:`~trackers.peers.PersistentTracker`) are left out. Raises
        :class:`~trackers.state.StateError` when the point tracker cannot be saved."""
        point = self.point
        take = getattr(point, "checkpoint", None)  # cheaper than an isinstance on a Protocol
        if take is None:
            raise StateError(f"the point tracker {point.kind!r} cannot save its state")
        peers = tuple(
            (peer.kind, peer.checkpoint())
            for peer in self.peers
            if isinstance(peer, PersistentTracker)
        )
        return PipelineCheckpoint(
            self._last_time, point.kind, take(), peers, self._coverage.snapshot()
        )

    def export_state(self) -> PipelineState:
        """The state as plain data (:mod:`trackers.state`)."""
        return self.checkpoint().export()

    def import_state(self, state: PipelineState) -> None:
        """Go on from a saved state: every tracker checks its section, then all restore, so a
        bad section (:class:`~trackers.state.StateError`, saying why) changes nothing. The
        configuration in force stays; the last processed time comes back, so scans older
        than the saved ones stay out of sequence. A peer the file has no section for keeps
        its state (empty at start-up); a section for a peer kind this pipeline does not run
        is refused."""
        point = self.point
        if state.point_kind != point.kind:
            raise StateError(
                f"the saved point tracker is {state.point_kind!r}; this one is {point.kind!r}"
            )
        if not isinstance(point, PersistentTracker):
            raise StateError(f"the point tracker {point.kind!r} cannot restore a state")
        last = state.last_time
        if last is not None and not math.isfinite(last):
            raise StateError(f"last_time: not a finite number: {last!r}")
        point_time = state.point.values.get("time")
        if isinstance(point_time, int | float) and (last is None or not point_time <= last):
            raise StateError(f"the point tracker's time {point_time!r} is after {last!r}")
        coverage = None
        for name, section in state.learned.items():
            if name != "coverage":
                raise StateError(f"the saved state holds learned {name!r}, unknown here")
            try:
                coverage = CoverageLearner.restored(dict(section.values))
            except ValueError as exc:
                raise StateError(str(exc)) from None
        peers = {p.kind: p for p in self.peers}
        checked: list[tuple[PersistentTracker, Any]] = [(point, point.check_state(state.point))]
        for kind, section in state.peers.items():
            peer = peers.get(kind)
            if not isinstance(peer, PersistentTracker):
                raise StateError(f"the saved state holds peer {kind!r}, which is not running")
            checked.append((peer, peer.check_state(section)))
        for tracker, value in checked:
            tracker.restore_state(value)
        self._last_time = last
        if coverage is not None:  # (a file without it: the boxes are learned again)
            self._coverage = coverage
        # the detections tentative tracks held back belong to tracks and serial numbers of
        # the state left: the restored tracker gives those numbers and ids again
        self._clutter.forget_held()

    # -- id counters -----------------------------------------------------------------------

    def id_counters(self) -> dict[str, int]:
        """The number of the next id of each tracker that numbers its tracks
        (:class:`~trackers.peers.NumbersTracks`), by its kind."""
        return {tracker.kind: tracker.next_id for tracker in self._numbering()}

    def skip_ids(self, counters: Mapping[str, int]) -> None:
        """Make each tracker whose kind ``counters`` names give no id numbered below its
        number (ids given before a restart; a counter already past it stays). Kinds that
        this pipeline does not run, or whose tracker gives no numbered ids, are ignored."""
        for tracker in self._numbering():
            first = counters.get(tracker.kind)
            if first is not None:
                tracker.skip_ids(first)

    def _numbering(self) -> list[NumbersTracks]:
        """The trackers that number their tracks (:class:`~trackers.peers.NumbersTracks`).
        By ``getattr``: an isinstance on a Protocol costs some 10 µs a tracker, and
        :meth:`id_counters` runs at every batch."""
        return [
            cast(NumbersTracks, tracker)
            for tracker in (self.point, *self.peers)
            if getattr(tracker, "skip_ids", None) is not None
        ]

    def snapshot(self) -> tuple[TrackSnapshot, ...]:
        """Every live track of every kind, as of the last processed scan."""
        out: list[TrackSnapshot] = []
        for peer in self.peers:
            out.extend(peer.snapshot())
        out.extend(self.point.snapshot())
        return tuple(out)
