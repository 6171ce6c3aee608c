"""The individual-target tracker: IMM filters, gating, GNN, LLR scores, sequential test.

All tracks live in one structure of arrays (:class:`TrackArrays`), so each step is a handful
of numpy operations over every track and candidate pair at once. A step builds new arrays and
swaps them in at its end: an exception part-way leaves the tracker as it was.

One step, for a scan at time t with detections z_j (covariances R_j):

1. IMM prediction of every track to t (mixing, mode-matched prediction);
2. detection probability per track: the sensor's P_D, or a resolution cell's (hybridization);
3. gating of all track-detection pairs (k-d tree pre-gate, chi-square gate);
4. GNN over independent clusters, maximising the summed score gain: confirmed tracks first,
   then tentative tracks over the detections left;
5. IMM update of assigned tracks; hit or miss score increments;
6. initiation from the detections neither assigned nor in a confirmed track's gate ("free"):
   by default (``two_point``, :mod:`trackers.initiation`) the candidates of earlier scans
   pair with them, and with those a tentative track took when the pair scores higher, each
   pair kept starting a tentative track; each free detection becomes a candidate. With
   ``single_point`` each free detection starts a tentative track scored
   L(1) = max(ln(λ_nt/λ_fa), ln κ) (:func:`trackers.scoring.initial_score`);
7. confirmation and deletion by the sequential test (a track is confirmed once it holds
   detections of three instants at the earliest, :data:`MIN_CONFIRM_INSTANTS`), the
   drop-from-peak and coasting rules.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np

from trackers.association.gating import (
    GatedPairs,
    expected_false_alarms,
    gate,
    max_eigenvalue_2x2,
)
from trackers.association.gnn import gnn_assign
from trackers.association.manoeuvre import (
    MAX_AGILE_SEARCH_TURN,
    ManoeuvreMatch,
    manoeuvre_search,
    reaches_beyond,
)
from trackers.association.spatial import pairs_within
from trackers.config import InitiationConfig, MeasurementConfig, TrackerConfig
from trackers.coverage import Coverage, disc_fraction, same_area, visible_fraction
from trackers.detection_rate import (
    LOOK_MIN_HITS,
    MAX_SENSORS,
    MIN_MISSES,
    DetectionRates,
    SensorRate,
    coast_revisits,
)
from trackers.filters.imm import (
    imm_combine,
    imm_predict,
    imm_range_rate_update,
    imm_update,
    transition_matrix,
)
from trackers.initiation import (
    MIN_PAIR_INTERVAL,
    Candidates,
    next_hit_allowance,
    pair_candidates,
)
from trackers.models.measurement import H_POSITION, MIN_RANGE, range_rate_innovation
from trackers.models.motion import STATE_DIM, agile_turn_rate, along_track_block, build_models
from trackers.peers import (
    HeldDetections,
    PointDirectives,
    PointProposal,
    PointTrackState,
    PointTrackView,
)
from trackers.rows import RowArrays, sort_within_groups
from trackers.scoring import (
    hit_increment,
    initial_score,
    initial_score_each,
    miss_increment,
    new_target_odds_density,
    sequential_test,
)
from trackers.state import (
    SectionReader,
    StateError,
    StateSection,
    check_id_counter,
    put_string_groups,
    put_strings,
)
from trackers.types import Scan, StepResult, TrackSnapshot

__all__ = ["Checkpoint", "IndividualTracker", "TrackArrays"]

KIND = "individual"


#: The sequential test confirms a tentative track once it holds detections of this many
#: instants at the earliest, whatever its score (tracks handed in by peers keep their status):
#: the velocity of two instants has been tested by a third. Several sensors' detections of
#: one instant (radars reporting together) tell where the target is, not how it moves.
MIN_CONFIRM_INSTANTS = 3

#: A confirmed track with detections of this many instants may coast for m* − ½ revisits of
#: its sensor, however short ``max_coast_time`` (:mod:`trackers.detection_rate`): a GMTI revisiting
#: every 10 s misses a vehicle twice in a row now and then (1 % a scan at P_D 0.9), and
#: ``max_coast_time`` 10 s deleted it at the second miss.
COAST_MIN_INSTANTS = 5

#: ``ln(1 − 0.9)``: a fast sensor's miss of a hidden target costs at least its share of this
#: (``track_management.miss_correlation_time``): a target hidden behind a pillar is missed
#: however likely the camera is to detect it when in sight, so a camera of low P_D does not
#: let its tracks coast longer than one of P_D 0.9 (2 s at τ 0.3 s).
_HIDDEN_MISS = float(miss_increment(0.9))

#: A scan looks at a track when at least this share of its predicted position's distribution
#: lies in the scan's coverage (:func:`_visible`; ``TrackArrays.looked``).
LOOK_SHARE = 0.5

#: A confirmed track out of view that no scan has looked at for this many of its revisits,
#: and that lies in no sensor's field of regard (:class:`_Regard`), has left every sensor's
#: view (:func:`_left_view`): it is deleted, and no young track continues it
#: (:func:`_relinked`). A track in view is deleted after its third miss in a row or so; out
#: of view, it waited for the coasting limit (a car 270 m past a road radar's coverage at
#: 10 Hz, whose id the next car to enter there took).
LOOK_CYCLES = 4.0

#: A sensor's field of regard is the union of the areas its last this many scans looked at
#: (one entry while they look at the same area: a camera's footprint, a road radar's stated
#: coverage; two turns of a radar that reports 16 sectors a turn).
REGARD_SCANS = 32

#: A track lies in a sensor's field of regard when at least this share of its predicted
#: position's distribution lies in one of the areas of it.
REGARD_SHARE = 0.1

#: A sensor's field of regard is forgotten once it has been silent for the longer of
#: ``track_management.max_coast_time`` and this many of its mean intervals between scans;
#: no track is taken for gone until the tracker has run that long since it started, was reset
#: or restored (fields of regard are not saved).
REGARD_INTERVALS = 4.0

#: The highest serial number a state file may give the next detection (``TrackArrays.took``:
#: ten million detections a second for ten thousand years stay below it).
MAX_SERIAL = 2**62


@dataclass(frozen=True, eq=False)
class TrackArrays(RowArrays):
    """Every individual track, one row each.

    x (N, M, 5), P (N, M, 5, 5), mu (N, M): the IMM mode-conditioned estimates and mode
    probabilities; x_comb (N, 5) and P_comb (N, 5, 5) their moment-matched combination.
    ``hits`` counts a track's detections, ``instants`` the distinct times of them (several
    sensors' batches of one instant count once: a detection less than
    :data:`~trackers.initiation.MIN_PAIR_INTERVAL` after the track's previous one adds
    none); ``took`` is the serial number of the last detection it took (the tracker numbers
    every detection it is given, batch after batch; −1: none), what tells its siblings
    (:func:`_siblings_sharing`), ``first`` that of its first detection (−1: unknown; what
    the clutter map takes back at its third, :meth:`~trackers.clutter.ClutterMap.reclaim`).
    ``origin`` numbers the detection a track started from: tracks of one origin are rival
    hypotheses of one target's start, of which only the likeliest is kept once each has
    been tested against a scan. ``looked`` is the last time a scan looked at the track (had
    its predicted position in view at least :data:`LOOK_SHARE`, or updated it).
    """

    ids: np.ndarray
    x: np.ndarray
    P: np.ndarray
    mu: np.ndarray
    x_comb: np.ndarray
    P_comb: np.ndarray
    score: np.ndarray
    peak: np.ndarray
    confirmed: np.ndarray
    hits: np.ndarray
    instants: np.ndarray
    created: np.ndarray
    updated: np.ndarray
    detection_ids: np.ndarray
    origin: np.ndarray
    took: np.ndarray
    first: np.ndarray
    looked: np.ndarray

    @staticmethod
    def empty(n_modes: int) -> TrackArrays:
        n = STATE_DIM
        return TrackArrays(
            ids=np.zeros(0, dtype=object),
            x=np.zeros((0, n_modes, n)),
            P=np.zeros((0, n_modes, n, n)),
            mu=np.zeros((0, n_modes)),
            x_comb=np.zeros((0, n)),
            P_comb=np.zeros((0, n, n)),
            score=np.zeros(0),
            peak=np.zeros(0),
            confirmed=np.zeros(0, dtype=bool),
            hits=np.zeros(0, dtype=np.int64),
            instants=np.zeros(0, dtype=np.int64),
            created=np.zeros(0),
            updated=np.zeros(0),
            detection_ids=np.zeros(0, dtype=object),
            took=np.zeros(0, dtype=np.int64),
            first=np.zeros(0, dtype=np.int64),
            origin=np.zeros(0, dtype=np.int64),
            looked=np.zeros(0),
        )

    @property
    def n_modes(self) -> int:
        return int(self.mu.shape[1])


def _objects(items: Sequence[object]) -> np.ndarray:
    """A 1-D object array holding ``items`` as they are (tuples stay tuples)."""
    return np.fromiter(items, dtype=object, count=len(items))


@dataclass(frozen=True, eq=False)
class _Prediction:
    """Every track predicted to ``time`` under ``config``: the IMM mode-matched predictions
    ``x_pred``, ``P_pred`` with mode probabilities ``c_bar``, and their combination ``xc``,
    ``Pc``. Computed once a scan, for the peers' view and the tracker's own update."""

    base: int
    time: float
    dt: float
    config: TrackerConfig
    models: tuple
    tracks: TrackArrays
    x_pred: np.ndarray
    P_pred: np.ndarray
    c_bar: np.ndarray
    xc: np.ndarray
    Pc: np.ndarray

    def take(self, keep: np.ndarray) -> _Prediction:
        return replace(
            self,
            tracks=self.tracks.take(keep),
            x_pred=self.x_pred[keep],
            P_pred=self.P_pred[keep],
            c_bar=self.c_bar[keep],
            xc=self.xc[keep],
            Pc=self.Pc[keep],
        )

    def gated(self, scan: Scan, gamma: float) -> GatedPairs:
        """Every track's pairs with ``scan``'s detections in its χ² gate ``γ``
        (:func:`~trackers.association.gating.gate` on ``xc``, ``Pc``), found once for a scan
        and a ``γ``: the peers' view and the tracker's own update share them."""
        cached = self.__dict__.get("_gated")
        if cached is not None and cached[0] is scan and cached[1] == gamma:
            return cached[2]
        pairs = gate(self.xc[:, :2], self.Pc[:, :2, :2], scan.z, scan.R, gamma)
        object.__setattr__(self, "_gated", (scan, gamma, pairs))
        return pairs


@dataclass(frozen=True, eq=False)
class _State:
    """Everything a step changes, swapped in whole by ``commit``."""

    config: TrackerConfig
    models: tuple
    tracks: TrackArrays
    candidates: Candidates
    time: float | None
    next_id: int
    next_origin: int
    #: the serial number of the next batch's first detection (``TrackArrays.took``)
    next_serial: int = 0
    #: each sensor's detection probability as its tracks show it (not saved: relearned)
    rates: DetectionRates = field(default_factory=DetectionRates)
    #: each sensor's field of regard (not saved: relearned), and the time of the first scan
    #: since the tracker started, was reset or restored
    regard: Mapping[str, _Regard] = field(default_factory=lambda: MappingProxyType({}))
    since: float | None = None


@dataclass(frozen=True)
class _Regard:
    """Where one sensor has been looking: the areas of its last :data:`REGARD_SCANS` scans,
    a run of scans of one area as one entry (``None``: everywhere), and when it was last
    heard."""

    time: float
    areas: tuple[Coverage | None, ...]


def _regarded(
    regard: Mapping[str, _Regard],
    scan: Scan,
    rates: DetectionRates,
    max_coast: float,
) -> Mapping[str, _Regard]:
    """The fields of regard with ``scan``'s area added to its sensor's; those of sensors
    silent for longer than :data:`REGARD_INTERVALS` of their intervals (at least
    ``max_coast``; of ``max_coast`` while a sensor's interval is unknown: a 12 s radar heard
    once is not forgotten before its second scan) dropped, and no more than the detection
    rates' :data:`MAX_SENSORS` kept (the least recently heard goes first)."""
    t = float(scan.time)
    out: dict[str, _Regard] = {}
    for sensor, r in regard.items():
        if sensor != scan.sensor_id and t - r.time <= max(
            max_coast, REGARD_INTERVALS * (rates.interval(sensor) or max_coast)
        ):
            out[sensor] = r
    old = regard.get(scan.sensor_id)
    areas = () if old is None else old.areas
    if not areas or not same_area(areas[-1], scan.coverage):
        areas = (*areas, scan.coverage)[-REGARD_SCANS:]
        sizes = [0 if a is None or a.polygon is None else len(a.polygon) for a in areas]
        while len(areas) > 1 and sum(sizes) > REGARD_VERTICES:
            areas, sizes = areas[1:], sizes[1:]
    out[scan.sensor_id] = _Regard(t, areas)  # the most recently heard last
    while len(out) > MAX_SENSORS:
        del out[next(iter(out))]
    return MappingProxyType(out)


#: A sensor's field of regard keeps its newest areas up to this many polygon vertices in all
#: (at least one area: a stated polygon has at most 1024), so that 256 sensors stating large
#: polygons that change at every batch hold some 16 MB, not 130.
REGARD_VERTICES = 4096


class _Counters:
    """The id and origin counters of one proposed step (the tracker's own move on commit),
    and the serial number of the step's first detection."""

    def __init__(
        self, next_id: int, next_origin: int, id_prefix: str = "", serial: int = 0
    ) -> None:
        self.next_id = next_id
        self.next_origin = next_origin
        self.id_prefix = id_prefix
        self.serial = serial

    def ids(self, n: int) -> np.ndarray:
        p = self.id_prefix
        out = _objects([f"{p}T{i}" for i in range(self.next_id, self.next_id + n)])
        self.next_id += n
        return out

    def origins(self, n: int) -> np.ndarray:
        out = np.arange(self.next_origin, self.next_origin + n, dtype=np.int64)
        self.next_origin += n
        return out


class IndividualTracker:
    """Tracks of individual point targets (GNN association); scans in time order.

    A step is ``propose`` then ``commit`` (:class:`trackers.peers.PointTracker`): a proposal
    is computed from the tracker's state without changing it, so that the pipeline can drop
    it when a peer fails. ``step`` does both.
    """

    kind = KIND

    def __init__(self, config: TrackerConfig | None = None, *, id_prefix: str = "") -> None:
        """``id_prefix`` goes before every new track's id (``{id_prefix}T12``): an instance's
        qualifier when several share the work."""
        config = config or TrackerConfig()
        self.id_prefix = id_prefix
        models = build_models(config.motion)
        self._state = _State(
            config=config,
            models=models,
            tracks=_frozen(TrackArrays.empty(len(models))),
            candidates=Candidates.empty(),
            time=None,
            next_id=1,
            next_origin=0,
        )
        self._pending: TrackerConfig | None = None
        self._version = 0
        self._prediction: _Prediction | None = None

    # -- configuration -------------------------------------------------------------------

    @property
    def config(self) -> TrackerConfig:
        """The configuration in force (or to be in force from the next scan)."""
        return self._pending or self._state.config

    @property
    def time(self) -> float | None:
        """Time of the last committed scan, or ``None`` before the first."""
        return self._state.time

    def reconfigure(self, config: TrackerConfig) -> None:
        """Use ``config`` from the next scan on. Tracks, scores and ids are kept; when the
        set of motion models changes, each track restarts its modes from its combined
        estimate with the configured initial mode probabilities."""
        self._pending = config
        self._prediction = None

    def _configured(self) -> tuple[TrackerConfig, tuple, TrackArrays]:
        st = self._state
        if self._pending is None:
            return st.config, st.models, st.tracks
        config = self._pending
        models = build_models(config.motion)
        tracks = st.tracks
        if config.motion.models != st.config.motion.models:
            tracks = _remoded(tracks, config)
        return config, models, tracks

    # -- the step ------------------------------------------------------------------------

    def _predict(self, time: float) -> _Prediction:
        """Every track predicted to ``time`` (cached for the state and time)."""
        cached = self._prediction
        if cached is not None and cached.base == self._version and cached.time == time:
            return cached
        last = self._state.time
        if last is not None and time < last:
            raise ValueError(f"time {time} is older than the last processed time {last}")
        config, models, tracks = self._configured()
        dt = 0.0 if last is None else time - last
        if len(tracks):
            Pi = transition_matrix(config.motion.sojourn_times, dt)
            # an agile turn's prior is per revisit of the track (as its detections show it at
            # the configured P_D), not per batch of any sensor
            agile = any(getattr(model, "agile", False) for model in models)
            revisit = _revisit(tracks, config.track_management.pd) if agile else None
            x_pred, P_pred, c_bar = imm_predict(
                models, tracks.x, tracks.P, tracks.mu, Pi, dt, revisit
            )
            xc, Pc = imm_combine(x_pred, P_pred, c_bar)
        else:
            x_pred, P_pred, c_bar = tracks.x, tracks.P, tracks.mu
            xc, Pc = tracks.x_comb, tracks.P_comb
        pred = _Prediction(
            self._version, time, dt, config, models, tracks, x_pred, P_pred, c_bar, xc, Pc
        )
        self._prediction = pred
        return pred

    def detection_probability(self, sensor_id: str) -> float:
        """``sensor_id``'s detection probability as its established tracks showed it
        (:mod:`trackers.detection_rate`; the configured ``pd`` for a sensor not heard yet). It
        sets how long a track may coast on that sensor's scans that state no ``pd``."""
        return self._state.rates.estimate(sensor_id, self.config.track_management.pd)

    def predicted(self, time: float) -> PointTrackView:
        """The live tracks predicted to ``time`` (no earlier than the last scan), read-only."""
        pred = self._predict(float(time))
        tr = pred.tracks
        return PointTrackView(
            time=float(time),
            ids=tuple(tr.ids.tolist()),
            x=pred.xc,
            P=pred.Pc,
            score=tr.score,
            hits=tr.hits,
            confirmed=tr.confirmed,
            created=tr.created,
            updated=tr.updated,
            gated=lambda scan: (
                pred.gated(scan, pred.config.gating.threshold),
                pred.config.gating.threshold,
            ),
        )

    def step(self, scan: Scan, directives: PointDirectives | None = None) -> StepResult:
        """Process one scan (already checked by the pipeline): propose, then commit."""
        proposal = self.propose(scan, directives)
        self.commit(proposal)
        return proposal.result

    def commit(self, proposal: PointProposal) -> None:
        """Make ``proposal`` the tracker's state; refused when the tracker has moved on since
        it was proposed."""
        base, state = proposal.state
        if base != self._version:
            raise ValueError("a stale proposal: the tracker has committed another step since")
        self._state = state
        self._pending = None
        self._version += 1
        self._prediction = None

    def reset(self) -> None:
        """Drop every track, the two-point candidates and the learned detection
        probabilities, and forget the last time; the configuration and the id counters stay
        (new ids go on from the last one given)."""
        st = self._state
        self._state = _State(
            config=st.config,
            models=st.models,
            tracks=_frozen(TrackArrays.empty(len(st.models))),
            candidates=Candidates.empty(),
            time=None,
            next_id=st.next_id,
            next_origin=st.next_origin,
            next_serial=st.next_serial,
        )
        self._version += 1
        self._prediction = None

    @property
    def next_id(self) -> int:
        """The number of the next track's id (``T{next_id}``)."""
        return self._state.next_id

    def skip_ids(self, first: int) -> None:
        """Give no id numbered below ``first`` from now on (ids a run before a restart gave:
        :class:`~trackers.peers.NumbersTracks`); a counter already past it stays."""
        if int(first) > self._state.next_id:
            self._state = replace(self._state, next_id=int(first))
            self._version += 1
            self._prediction = None

    def propose(self, scan: Scan, directives: PointDirectives | None = None) -> PointProposal:
        """The step for ``scan`` under the peers' ``directives``, without changing the tracker."""
        directives = directives or PointDirectives()
        t = float(scan.time)
        pred = self._predict(t)
        config, models = pred.config, pred.models
        tm = config.track_management
        pd_sensor = tm.pd if scan.pd is None else float(scan.pd)
        lam_fa = _clutter_densities(scan, tm.clutter_density)
        rates = self._state.rates
        pd_coast = rates.estimate(scan.sensor_id, tm.pd) if scan.pd is None else pd_sensor
        reach = coast_revisits(pd_coast, tm.p_true_delete)
        longer = reach > MIN_MISSES - 0.5  # a sensor that misses more than P_D 0.9 does
        serial = self._state.next_serial  # this batch's detection j is number serial + j
        interval = rates.interval(scan.sensor_id)  # the sensor's mean interval between batches
        regard = _regarded(self._state.regard, scan, rates, tm.max_coast_time)
        since = t if self._state.since is None else self._state.since
        counters = _Counters(self._state.next_id, self._state.next_origin, self.id_prefix, serial)

        released: tuple[PointTrackState, ...] = ()
        if directives.release:
            ids = pred.tracks.ids
            out = np.isin(ids, np.array(sorted(directives.release), dtype=object))
            released = tuple(_state_of(pred, i, t) for i in np.flatnonzero(out).tolist())
            pred = pred.take(~out)

        renamed: tuple[str, ...] = ()
        if directives.hand_in:
            pred, renamed = _handed_in(pred, directives.hand_in, counters)

        tracks = pred.tracks
        claims = np.full(scan.size, -np.inf)
        masked = np.zeros(0)  # each old track's P_D / the sensor's, below 1 inside a peer's cell
        rivals = np.zeros(0, dtype=bool)  # tentative tracks that lost to a rival of their origin
        losers = winners = np.zeros(0, dtype=np.intp)  # siblings not the likeliest, and it
        seen: np.ndarray | None = None  # old tracks in the scan's view (None: all)
        visible: np.ndarray | None = None  # the share of each one's position in view
        range_rates = (0, 0)
        established = np.zeros(scan.size, dtype=bool)
        held = HeldDetections.none()
        looks = detected = 0
        gated = (np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp))
        if len(tracks):
            pd = np.full(len(tracks), pd_sensor)
            if directives.pd:
                for i, tid in enumerate(tracks.ids.tolist()):
                    p = directives.pd.get(tid)
                    if p is not None:
                        pd[i] = p
            masked = np.minimum(pd / pd_sensor, 1.0)
            visible = _visible(pred, scan)
            seen = None if visible is None else visible > 0.0
            # The manoeuvre search reaches as far as a track may coast at P_D 0.9 (a target
            # missed more often is looked for in its gate only: the search's reach grows as
            # τ², and a track lost for long found clutter with it and flew off).
            searching = None
            if longer:
                searching = (t - pred.tracks.updated) * _coast_rate(
                    pred.tracks,
                    tm.max_coast_time,
                    pd_coast,
                    MIN_MISSES - 0.5,
                    interval,
                ) <= tm.max_coast_time
            tracks, claims, range_rates, established, gated, held = self._update_existing(
                pred, scan, pd, lam_fa, visible, searching, serial, masked >= 1.0, interval
            )
            look = _looks(pred.tracks, visible, masked, t, pd_coast)
            looks = int(np.count_nonzero(look))
            detected = int(np.count_nonzero(look & (tracks.updated == t)))
            # Rivals are dropped with the deleted tracks below; those out of view wait for a
            # scan that looks at them. A sibling that is not the likeliest of its siblings
            # (_siblings_sharing) took its detection from the likelier one: among the rivals
            # of its own origin it ranks last, so it prunes none of them and any of them
            # prunes it.
            losers, winners = _sibling_losers(tracks, serial)
            rivals = ~_best_of_each_origin(tracks, losers)
            if seen is not None:
                rivals &= seen
            # A batch of the instant a track last took a detection at (another radar
            # reporting with the first) does not test its velocity: no rival loses by it.
            rivals &= pred.tracks.updated <= t - MIN_PAIR_INTERVAL

        if config.initiation.method == "two_point":
            born, candidates = self._initiate_two_point(
                scan, claims, config, pd_sensor, lam_fa, counters, tracks
            )
        else:
            born = self._initiate(scan, claims == -np.inf, config, lam_fa, counters)
            candidates = Candidates.empty()
        # The tracks born at this scan are neither tested nor deleted (2 detections, and
        # the scan that starts a track never deletes it): they join the others at the end,
        # after the tracks kept. Tracks handed back by peers (``adopt``) are tested with the
        # old ones, never deleted at this scan either, and go after the births.
        n_old = len(tracks)
        if directives.adopt:
            tracks = tracks.concat(_adopted(directives.adopt, config, counters))

        # A track whose detection probability a peer lowered (a vehicle inside a convoy's
        # resolution cell) is expected to go undetected for longer: its coasting time counts
        # at the rate P_D / P_D,sensor while it is there. A track of a slow sensor may coast
        # for m* − ½ of its revisits, m* from the sensor's detection probability,
        # stated or learned (:mod:`trackers.detection_rate`). The lower rate counts.
        # Past MIN_MISSES, only a track whose gate is clear of clutter coasts on. A track out
        # of this sensor's view is held to the most lenient of the sensors' limits.
        revisits: float | np.ndarray = reach
        idle = np.zeros(0, dtype=np.intp) if seen is None else np.flatnonzero(~seen)
        revisit = np.zeros(0)
        lost = None  # the tracks that have left every sensor's view
        if idle.size:
            # (a young track's revisit too: P_D Δ̄, not T_s)
            revisit = _revisit_time(tracks, pd_coast, interval, min_instants=0)[idle]
            gone = _left_view(pred, idle, revisit, t, regard, since, tm.max_coast_time)
            if gone.any():
                lost = np.zeros(n_old, dtype=bool)
                lost[idle[gone]] = True
                idle, revisit = idle[~gone], revisit[~gone]
        if n_old and (longer or idle.size):
            revisits = np.full(len(tracks), reach)
            if longer:
                lam_gated = _gated_densities(n_old, gated, lam_fa)
                crowded = _crowded_gates(pred.Pc, scan, lam_fa, lam_gated, config.gating.threshold)
                revisits[:n_old][crowded] = MIN_MISSES - 0.5
            if idle.size:
                revisits[idle] = coast_revisits(rates.lowest(tm.pd), tm.p_true_delete)
        rate = _coast_rate(tracks, tm.max_coast_time, pd_coast, revisits, interval)
        if masked.size and (masked < 1.0).any():
            rate[: masked.size] = np.minimum(rate[: masked.size], masked)
        coast = (t - tracks.updated) * rate
        status = sequential_test(tracks.score, tracks.peak, tracks.confirmed, coast, tm)
        delete = status.delete
        # A track estimated faster than any target it may hold has lost it: it runs on
        # through clutter (_runaway).
        delete |= _runaway(tracks, config.initiation.max_speed)
        delete[n_old:] = False  # a track is never deleted in the scan that starts or adopts it
        if idle.size:
            # out of view: their scores stand, and coasting ends them only a revisit past
            # the limit, so that a sensor looks at them again first (a radar reporting its
            # turn sector by sector looks at a track once a turn, not at each batch)
            late = t - tracks.updated[idle] - revisit
            delete[idle] &= late * rate[idle] > tm.max_coast_time
        tested = delete.copy()  # deleted by the sequential test
        if idle.size:
            tested[idle] = False  # coasted out of view: no verdict on its detections
        if lost is not None:
            delete[:n_old] |= lost  # left every sensor's view: a target's, gone
            tested[:n_old] &= ~lost
        delete[:n_old] |= rivals  # tentative, so not among the deleted ids
        # Two detections say that a target is there, not how it moves: a pair whose slow and
        # fast readings both fit (200 m in 1 s under 40 m noise) may hold the wrong one, and
        # confirmed, would be lost at the next detection and coast on as a second track.
        newly = status.confirmed & ~tracks.confirmed & (tracks.instants >= MIN_CONFIRM_INSTANTS)
        newly[losers] = False  # not the likeliest reading of its start: not confirmed now
        # A track with detections of 3 instants or more on a target whose confirmed track
        # lost it (it sped up, braked, turned out of the gate) is that track again, confirmed
        # or not yet (a score of 0 or more: no less likely a target than not): the old id goes
        # on with it. Tracks handed back by peers at this scan (rows from n_old on) are left alone.
        young = ~tracks.confirmed & (tracks.instants >= MIN_CONFIRM_INSTANTS) & ~delete
        young &= newly | (tracks.score >= 0.0)
        young[n_old:] = False
        young[losers] = False
        tracked = newly & ~delete  # the winners that go on as a confirmed track
        if young.any():
            before = delete.copy()
            tracks, young, delete = _relinked(
                tracks, young, delete, t, config, n_old, _typical(lam_fa), lost
            )
            tracked |= delete & ~before  # merged into the confirmed track they continue
            newly &= ~delete
        if losers.size:  # the likeliest sibling is tracked: the others were its other readings
            delete[losers[tracked[winners]]] = True
        deleted_ids = renamed + tuple(tracks.ids[delete & tracks.confirmed].tolist())
        # The fates of the tracks that held detections back from the clutter map: no target
        # (the test deleted a tentative track), or a target's or another reading's (confirmed
        # now, merged into a confirmed track, a rival or sibling that lost).
        accepted = tuple(tracks.ids[(newly & ~delete) | (delete & ~tested)].tolist())
        rejected = tuple(tracks.ids[tested & ~tracks.confirmed].tolist())
        tracks = _frozen(
            _kept(tracks, ~delete, confirmed=newly | tracks.confirmed, born=born, n_old=n_old)
        )

        state = _State(
            config=config,
            models=models,
            tracks=tracks,
            candidates=candidates,
            time=t,
            next_id=counters.next_id,
            next_origin=counters.next_origin,
            next_serial=serial + scan.size,
            rates=rates.learned(scan.sensor_id, t, looks, detected),
            regard=regard,
            since=since,
        )
        names = tuple(m.name for m in models)
        result = StepResult(
            time=t,
            sensor_id=scan.sensor_id,
            deleted=deleted_ids,
            snapshot=lambda confirmed_only: _snapshots(
                tracks, names, t, confirmed_only=confirmed_only
            ),
            range_rates=range_rates,
        )
        return PointProposal(
            result=result,
            released=released,
            state=(self._version, state),
            clutter=(claims < np.inf) & ~established,
            held=held,
            accepted=accepted,
            rejected=rejected,
            first_serial=serial,
        )

    def _update_existing(
        self,
        pred: _Prediction,
        scan: Scan,
        pd: np.ndarray,
        lam_fa: float | np.ndarray,
        visible: np.ndarray | None,
        searching: np.ndarray | None,
        serial: int,
        free: np.ndarray | None = None,
        interval: float = 0.0,
    ) -> tuple[
        TrackArrays,
        np.ndarray,
        tuple[int, int],
        np.ndarray,
        tuple[np.ndarray, np.ndarray],
        HeldDetections,
    ]:
        """The tracks updated with this scan (``pd`` the detection probability of each), and
        each detection's *claim* (``lam_fa`` the false-alarm density, one or one a detection):
        ``+inf`` where a confirmed track took it or has it in its
        gate, the updated score of the tentative track that took it, ``−inf`` where it is
        free. A track that takes no detection was missed with probability ``P_D f``, ``f`` the
        share of its predicted position in the scan's coverage (``visible``; ``None``: all of
        it): out of view (``f`` = 0) it keeps its score, not missed, only not looked at. Last, the
        number of range-rates of the detections confirmed tracks took, and of those used
        (inside their gate), the detections taken by tracks of at least
        :data:`ESTABLISHED_HITS` detections (whatever their instants: a target's, not
        clutter), the gated pairs (track and detection indices), and those of the taken
        detections that tentative tracks of that many detections hold back from the clutter
        map (:class:`~trackers.peers.HeldDetections`). ``interval`` is the sensor's mean
        interval between batches (0: not known yet), for the share of a miss a fast sensor's
        look costs (``track_management.miss_correlation_time``)."""
        config, tracks = pred.config, pred.tracks
        x_pred, P_pred, c_bar = pred.x_pred, pred.P_pred, pred.c_bar
        pairs = pred.gated(scan, config.gating.threshold)
        ti, dj = pairs.track, pairs.detection
        # The mode-matched update of every gated pair gives its likelihood g_ij for the
        # association gain, and the posterior of the pairs the assignment keeps.
        P_pairs = P_pred[ti]
        if ti.size and config.motion.q_ct_along > 0.0 and pred.dt > 0.0:
            _along_where_calm(pred, scan, ti, dj, P_pairs, lam_fa, free)
        xu, Pu, muu, loglik = imm_update(
            x_pred[ti], P_pairs, c_bar[ti], scan.z[dj], scan.R[dj], H_POSITION
        )
        xu, Pu, muu, loglik, rr = _with_range_rates(xu, Pu, muu, loglik, scan, dj, config)
        hit = hit_increment(pd[ti], loglik, _at(lam_fa, dj))
        gain = hit - miss_increment(pd[ti])
        # Confirmed tracks choose first; tentative tracks share what they leave. A young track
        # with a wide velocity gate would otherwise take a confirmed target's detections.
        first = tracks.confirmed[ti]
        sel = np.flatnonzero(first)[
            gnn_assign(ti[first], dj[first], gain[first], len(tracks), scan.size)
        ]
        taken = np.zeros(scan.size, dtype=bool)
        taken[dj[sel]] = True
        # A confirmed track with nothing in its gate looks again, within the reach of a
        # manoeuvre since its last update, among the detections no confirmed track gates.
        seen = None if visible is None else visible > 0.0
        found = _manoeuvre_found(pred, scan, ti[sel], dj[first], pd, lam_fa, seen, searching)
        if found is not None:
            taken[found.detection] = True
            zero = np.zeros(found.track.size)
            fx, fP, fmu, extra, _ = _with_range_rates(
                found.x, found.P, found.mu, zero, scan, found.detection, config
            )
            found = replace(found, x=fx, P=fP, mu=fmu, hit=found.hit + extra)
        second = np.flatnonzero(~first & ~taken[dj])
        chosen = second[gnn_assign(ti[second], dj[second], gain[second], len(tracks), scan.size)]
        sel = np.concatenate([sel, chosen, _siblings_sharing(tracks, ti, dj, gain, second, chosen)])
        at, ad = ti[sel], dj[sel]
        # The range-rates of the confirmed tracks' detections: how many came, how many fit.
        range_rates = (0, 0)
        if scan.range_rate is not None and at.size:
            kept = rr[sel][tracks.confirmed[at]]
            range_rates = (
                int(np.count_nonzero(kept != _NO_RANGE_RATE)),
                int(np.count_nonzero(kept == _RANGE_RATE_USED)),
            )

        x, P, mu = x_pred.copy(), P_pred.copy(), c_bar.copy()
        missed = miss_increment(pd if visible is None else pd * visible)
        tm = config.track_management
        if 0.0 < interval < tm.miss_correlation_time:
            # A sensor that looks more often than τ does not miss a target independently at
            # each look (a pillar hides a walker from a camera for a second or two): a track
            # that has shown a target, its score a full drop above confirmation, pays the
            # share Δ/τ of a miss, Δ the longer of the time since its last look and the
            # sensor's interval (known from its third batch: until then, in full). A hidden
            # target is missed whatever the sensor's P_D: the share is of a miss at P_D 0.9
            # at least (a camera of P_D 0.5 kept a track 6.4 s, 2 s now), never more than
            # the miss itself.
            shown = tracks.confirmed & (
                tracks.peak >= tm.confirm_threshold + tm.delete_drop_from_peak
            )
            since = np.maximum(scan.time - tracks.looked, interval)
            share = np.minimum(since / tm.miss_correlation_time, 1.0)
            hidden = np.maximum(missed, share * np.minimum(missed, _HIDDEN_MISS))
            missed = np.where(shown, hidden, missed)
        score = tracks.score + missed
        xu, Pu, muu, hit = xu[sel], Pu[sel], muu[sel], hit[sel]
        if found is not None:
            at, ad = np.concatenate([at, found.track]), np.concatenate([ad, found.detection])
            xu, Pu, muu, hit = (
                np.concatenate(pair)
                for pair in ((xu, found.x), (Pu, found.P), (muu, found.mu), (hit, found.hit))
            )
        hits = tracks.hits.copy()
        instants = tracks.instants.copy()
        updated = tracks.updated.copy()
        det_ids = _objects([()] * len(tracks))
        took = tracks.took.copy()
        took[at] = serial + ad
        if at.size:
            x[at], P[at], mu[at] = xu, Pu, muu
            score[at] = tracks.score[at] + hit
            hits[at] += 1
            instants[at] += tracks.updated[at] <= scan.time - MIN_PAIR_INTERVAL
            updated[at] = scan.time
            det_ids[at] = scan.detection_id_groups.take(ad)
        x_comb, P_comb = imm_combine(x, P, mu)
        # A detection in a confirmed track's gate belongs to that target's neighbourhood: when
        # the track did not take it, it is far likelier clutter or a second detection of the
        # same target than a new one, and starting a track on it would make a duplicate.
        claims = np.full(scan.size, -np.inf)
        np.maximum.at(claims, ad, score[at])  # (siblings share a detection: the best)
        # Detections that tracks of three or more detections took: a target's, whatever the
        # track's status (a group of young targets is not clutter).
        established = np.zeros(scan.size, dtype=bool)
        established[ad[hits[at] >= ESTABLISHED_HITS]] = True
        claims[dj[tracks.confirmed[ti]]] = np.inf  # a confirmed track's detections included
        if found is not None:
            claims[found.detection] = np.inf
        # Of those, what the map would count but for the tentative track that took it: held
        # back until the test decides on that track (none in a confirmed track's gate).
        hold = np.flatnonzero(
            (hits[at] >= ESTABLISHED_HITS) & ~tracks.confirmed[at] & (claims[ad] < np.inf)
        )
        # A track that took its third detection now is a target's whatever its status: its
        # first two, which the map counted when it had fewer, are taken back to be held too.
        assert ESTABLISHED_HITS == 3  # (a track knows the serials of its first and last only)
        took_third = (hits[at] == ESTABLISHED_HITS) & (tracks.hits[at] == ESTABLISHED_HITS - 1)
        took_third &= ~tracks.confirmed[at]
        held = HeldDetections(
            rows=ad[hold], holders=tuple(tracks.ids[at[hold]].tolist()), serials=serial + ad[hold]
        )
        if took_third.any():  # (at few scans: the arrays are built only then)
            third = at[took_third]
            held = replace(
                held,
                earlier=np.stack([tracks.first[third], tracks.took[third]], axis=1).ravel(),
                earlier_holders=tuple(np.repeat(tracks.ids[third], 2).tolist()),
                earlier_thirds=np.repeat(ad[took_third], 2),
            )
        new = replace(
            tracks,
            x=x,
            P=P,
            mu=mu,
            x_comb=x_comb,
            P_comb=P_comb,
            score=score,
            peak=np.maximum(tracks.peak, score),
            hits=hits,
            instants=instants,
            updated=updated,
            detection_ids=det_ids,
            took=took,
            looked=(
                np.full(len(tracks), scan.time)
                if visible is None
                else np.where(
                    (visible >= LOOK_SHARE) | (updated == scan.time), scan.time, tracks.looked
                )
            ),
        )
        return new, claims, range_rates, established, (ti, dj), held

    def _initiate_two_point(
        self,
        scan: Scan,
        claims: np.ndarray,
        config: TrackerConfig,
        pd: float,
        lam_fa: float | np.ndarray,
        counters: _Counters,
        tracks: TrackArrays,
    ) -> tuple[TrackArrays, Candidates]:
        """Velocity-gated two-point initiation (:mod:`trackers.initiation`).

        The candidates of earlier scans pair with this scan's detections that no confirmed
        track claims (see :meth:`_update_existing`); each pair kept starts a tentative track
        holding two detections. A pair on a detection that a tentative track took must score
        higher than that track: the target's own start is then not lost to a weaker track
        that crossed its path, and the two compete for the next detection. A pair must score
        above the deletion threshold, or, at its candidate's first scan (opened at the scan
        before), above it less the increment a third detection is expected to bring
        (:func:`~trackers.initiation.next_hit_allowance`): a fast target at a long revisit
        then starts, and is kept or dropped at its third scan. Every free detection becomes a
        candidate. A candidate out of the scan's view (with the reach of ``max_speed``) is
        not missed by it. Returns the new tracks and the candidates to keep."""
        init, tm = config.initiation, config.track_management
        t = float(scan.time)
        cand = self._state.candidates
        cand = cand.take(t - cand.time <= init.candidate_max_age)
        looked = _candidates_visible(cand, scan, config)
        two = pair_candidates(
            cand,
            scan.z,
            scan.R,
            claims < np.inf,
            t,
            max_speed=init.max_speed,
            velocity_std=init.velocity_std,
            slow_fraction=init.slow_target_fraction,
            q=config.motion.q_cv,
            gamma=config.gating.threshold,
            max_pairs=init.max_pairs_per_candidate,
            pd=pd,
            clutter_density=lam_fa,
            min_score=tm.delete_threshold,
            group_fraction=init.group_fraction,
            group_velocity_std=init.group_velocity_std,
            rivals=claims,
            allowance=next_hit_allowance(
                cand,
                cand.offered == 0,
                scan.z,
                claims < np.inf,
                t,
                pd=pd,
                clutter_density=_typical(lam_fa),
                max_speed=init.max_speed,
                slow_fraction=init.slow_target_fraction,
                floor=tm.delete_threshold,
            ),
        )
        born = _new_tracks(
            config,
            scan,
            counters,
            two.detection,
            two.x,
            two.P,
            score=two.score,
            hits=2,
            created=cand.time[two.candidate],
            origin=cand.origin[two.candidate],
            first=cand.serial[two.candidate],
        )
        # The candidates go on as their missed branches while their score stays above T_d
        # (missed with probability P_D times the share of their target's reach in view);
        # every free detection of this scan opens a new one.
        missed = t - cand.time >= MIN_PAIR_INTERVAL  # at the same instant: not missed
        if looked is not None:
            missed &= looked > 0.0  # nor out of view
        increment = miss_increment(pd if looked is None else pd * looked)
        score = np.where(missed, cand.score + increment, cand.score)
        offered = cand.offered + missed
        keep = np.flatnonzero(score > tm.delete_threshold)
        idx = np.flatnonzero(claims == -np.inf)
        n = idx.size
        fresh_ids = _objects([scan.detection_ids[j] for j in idx.tolist()])
        z_new = scan.z.take(idx, axis=0)
        candidates = Candidates(
            z=np.concatenate([cand.z.take(keep, axis=0), z_new]),
            R=np.concatenate([cand.R.take(keep, axis=0), scan.R.take(idx, axis=0)]),
            time=np.concatenate([cand.time.take(keep), np.full(n, t)]),
            score=np.concatenate(
                [score.take(keep), _initial_scores(tm.new_target_density, lam_fa, idx)]
            ),
            detection_ids=np.concatenate([cand.detection_ids.take(keep), fresh_ids]),
            origin=np.concatenate([cand.origin.take(keep), counters.origins(n)]),
            group_velocity=np.concatenate(
                [cand.group_velocity.take(keep, axis=0), _group_velocities(z_new, tracks, init)]
            ),
            offered=np.concatenate([offered.take(keep), np.zeros(n, dtype=np.int64)]),
            serial=np.concatenate([cand.serial.take(keep), counters.serial + idx]),
        )
        return born, candidates

    def _initiate(
        self,
        scan: Scan,
        free: np.ndarray,
        config: TrackerConfig,
        lam_fa: float | np.ndarray,
        counters: _Counters,
    ) -> TrackArrays:
        """A tentative track at each free detection: position z with covariance R, zero
        velocity and turn rate with the configured standard deviations."""
        idx = np.flatnonzero(free)
        n = idx.size
        x = np.zeros((n, 4))
        x[:, :2] = scan.z[idx]
        P = np.zeros((n, 4, 4))
        P[:, :2, :2] = scan.R[idx]
        P[:, 2, 2] = P[:, 3, 3] = config.initiation.velocity_std**2
        L1 = _initial_scores(config.track_management.new_target_density, lam_fa, idx)
        return _new_tracks(
            config,
            scan,
            counters,
            idx,
            x,
            P,
            score=L1,
            hits=1,
            created=np.full(n, float(scan.time)),
            origin=counters.origins(n),
        )

    # -- output --------------------------------------------------------------------------

    @property
    def tracks(self) -> TrackArrays:
        """The live tracks as arrays (read-only by convention)."""
        return self._state.tracks

    @property
    def candidates(self) -> Candidates:
        """The two-point candidates waiting for a second detection (read-only by convention)."""
        return self._state.candidates

    def snapshot(self, confirmed_only: bool = False) -> tuple[TrackSnapshot, ...]:
        """Every live track (or only the confirmed ones) as immutable snapshots."""
        st = self._state
        names = tuple(m.name for m in st.models)
        t = st.time if st.time is not None else 0.0
        return _snapshots(st.tracks, names, t, confirmed_only=confirmed_only)

    # -- saving and restoring (trackers.peers.PersistentTracker) -----------------------------

    def checkpoint(self) -> Checkpoint:
        """The committed state, to export later on any thread (free: it is immutable)."""
        return Checkpoint(self._state)

    def export_state(self) -> StateSection:
        """The committed state as plain data (:class:`Checkpoint`)."""
        return self.checkpoint().export()

    def check_state(self, section: StateSection) -> object:
        """A section that :meth:`export_state` wrote, read and checked, ready for
        :meth:`restore_state`; :class:`~trackers.state.StateError` when it cannot be used.

        The configuration in force stays. Tracks saved under other motion models restart
        their modes from their combined estimates, as :meth:`reconfigure` does."""
        return _import(section, self.config, self.id_prefix)

    def restore_state(self, checked: object) -> None:
        """Put a state that :meth:`check_state` returned in place of the current one."""
        if not isinstance(checked, _State):
            raise TypeError("restore_state takes what check_state returned")
        self._state = checked
        self._pending = None
        self._version += 1
        self._prediction = None

    def import_state(self, section: StateSection) -> None:
        """:meth:`check_state`, then :meth:`restore_state`: the tracker goes on from the
        saved tracks, candidates, time and id counters, or is left as it was."""
        self.restore_state(self.check_state(section))


@dataclass(frozen=True, eq=False)
class Checkpoint:
    """An :class:`IndividualTracker`'s committed state at one moment."""

    state: _State

    def export(self) -> StateSection:
        """Plain data: the time, the id and origin counters, the motion models' names,
        every field of the tracks and the two-point candidates as arrays (ids and detection
        ids as packed UTF-8), and each sensor's learned detection rate and interval between
        batches (:mod:`trackers.detection_rate`)."""
        st = self.state
        tr, cand = st.tracks, st.candidates
        groups = tr.detection_ids.tolist()
        arrays: dict[str, np.ndarray] = {}
        put_strings(arrays, "tracks.ids", tr.ids.tolist())
        put_string_groups(arrays, "tracks.detection_ids", groups)
        for name in _TRACK_NUMBERS:
            arrays[f"tracks.{name}"] = getattr(tr, name)
        for name in _CANDIDATE_NUMBERS:
            arrays[f"candidates.{name}"] = getattr(cand, name)
        put_strings(arrays, "candidates.detection_ids", cand.detection_ids.tolist())
        grouped = np.isfinite(cand.group_velocity).all(axis=1)
        arrays["candidates.grouped"] = grouped
        arrays["candidates.group_velocity"] = np.where(grouped[:, None], cand.group_velocity, 0.0)
        arrays["candidates.offered"] = cand.offered
        # each sensor's learned P_D and interval between batches (since 2026-11-28; an
        # interval not known yet is written as 0)
        rates = st.rates.sensors
        put_strings(arrays, "rates.sensors", list(rates))
        arrays["rates.values"] = np.array(
            [
                [r.time, r.looks, r.detected, 0.0 if math.isnan(r.interval) else r.interval]
                for r in rates.values()
            ],
            dtype=float,
        ).reshape(-1, 4)
        values = {
            "time": st.time,
            "next_id": st.next_id,
            "next_origin": st.next_origin,
            "next_serial": st.next_serial,
            "models": list(st.config.motion.models),
            "n_tracks": len(tr),
            "n_candidates": len(cand),
            "n_rates": len(rates),
        }
        return StateSection(values, arrays)


_TRACK_NUMBERS = (
    "x",
    "P",
    "mu",
    "x_comb",
    "P_comb",
    "score",
    "peak",
    "confirmed",
    "hits",
    "instants",
    "created",
    "updated",
    "origin",
    "took",
    "first",
    "looked",
)
_CANDIDATE_NUMBERS = ("z", "R", "time", "score", "origin", "serial")


def _read_group_velocities(r: SectionReader, k: int) -> np.ndarray:
    """The candidates' group velocities (NaN where none): none at all in a file written
    before candidates had them."""
    out = np.full((k, 2), np.nan)
    if r.has("candidates.grouped"):
        grouped = r.booleans("candidates.grouped", (k,))
        v = r.floats("candidates.group_velocity", (k, 2))
        out[grouped] = v[grouped]
    return out


def _covariances_ok(P: np.ndarray) -> bool:
    """Every matrix of ``P (..., d, d)`` has a positive diagonal and is symmetric to within
    1e-6 of its largest entry."""
    if P.size == 0:
        return True
    diag = np.diagonal(P, axis1=-2, axis2=-1)
    scale = np.abs(P).max(axis=(-2, -1), keepdims=True)
    asym = np.abs(P - np.swapaxes(P, -1, -2))
    return bool((diag > 0).all() and (asym <= 1e-6 * scale).all())


def _import(section: StateSection, config: TrackerConfig, id_prefix: str = "") -> _State:
    """The :class:`_State` of a section that :meth:`Checkpoint.export` wrote, checked, under
    ``config``; :class:`StateError` naming the field when it cannot be used."""
    r = SectionReader(section, "point")
    t = r.time("time")
    next_id = r.integer("next_id", ge=1)
    next_origin = r.integer("next_origin", ge=0)
    next_serial = r.integer("next_serial", ge=0) if "next_serial" in r.values else 0
    if next_serial > MAX_SERIAL:
        raise StateError(f"point.next_serial: above {MAX_SERIAL}, got {next_serial}")
    saved_models = r.names("models")
    n = r.integer("n_tracks", ge=0)
    k = r.integer("n_candidates", ge=0)
    M, D = len(saved_models), STATE_DIM
    ids = r.strings("tracks.ids", n)
    hits = r.integers("tracks.hits", (n,), ge=0)
    took = r.integers("tracks.took", (n,), ge=-1) if r.has("tracks.took") else None
    if took is None or "next_serial" not in r.values:  # a file from before siblings
        took = np.full(n, -1, dtype=np.int64)
    # a file from before the clutter map took a track's first detections back: unknown
    first = r.integers("tracks.first", (n,), ge=-1) if r.has("tracks.first") else None
    if first is None or "next_serial" not in r.values:
        first = np.full(n, -1, dtype=np.int64)
    updated = r.floats("tracks.updated", (n,))
    tracks = TrackArrays(
        ids=_objects(ids),
        x=r.floats("tracks.x", (n, M, D)),
        P=r.floats("tracks.P", (n, M, D, D)),
        mu=r.floats("tracks.mu", (n, M)),
        x_comb=r.floats("tracks.x_comb", (n, D)),
        P_comb=r.floats("tracks.P_comb", (n, D, D)),
        score=r.floats("tracks.score", (n,)),
        peak=r.floats("tracks.peak", (n,)),
        confirmed=r.booleans("tracks.confirmed", (n,)),
        hits=hits,
        instants=(
            r.integers("tracks.instants", (n,), ge=0)
            if r.has("tracks.instants")
            else hits.copy()  # a file from before instants were counted
        ),
        created=r.floats("tracks.created", (n,)),
        updated=updated,
        detection_ids=_objects(r.string_groups("tracks.detection_ids", n)),
        origin=r.integers("tracks.origin", (n,), ge=0),
        took=took,
        first=first,
        # a file from before: looked at when last updated
        looked=r.floats("tracks.looked", (n,)) if r.has("tracks.looked") else updated.copy(),
    )
    candidates = Candidates(
        z=r.floats("candidates.z", (k, 2)),
        R=r.floats("candidates.R", (k, 2, 2)),
        time=r.floats("candidates.time", (k,)),
        score=r.floats("candidates.score", (k,)),
        detection_ids=_objects(r.strings("candidates.detection_ids", k, optional=True)),
        origin=r.integers("candidates.origin", (k,), ge=0),
        group_velocity=_read_group_velocities(r, k),
        offered=(
            r.integers("candidates.offered", (k,), ge=0)
            if r.has("candidates.offered")
            else np.zeros(k, dtype=np.int64)  # a file from before coverage
        ),
        serial=(
            r.integers("candidates.serial", (k,), ge=-1)
            if r.has("candidates.serial")
            else np.full(k, -1, dtype=np.int64)  # a file from before: unknown
        ),
    )
    if "next_serial" not in r.values:  # (serials of a tracker that numbered none)
        candidates = replace(candidates, serial=np.full(k, -1, dtype=np.int64))
    rates = _read_rates(r, t)
    r.finish()

    def bad(detail: str) -> StateError:
        return StateError(f"point: {detail}")

    if len(set(ids)) != n or not all(ids):
        raise bad("track ids must be unique and not empty")
    check_id_counter(ids, next_id, id_prefix, "T", "point")
    origins = np.concatenate([tracks.origin, candidates.origin])
    if origins.size and int(origins.max()) >= next_origin:
        raise bad(f"next_origin {next_origin} is not above every origin ({int(origins.max())})")
    if (n or k) and t is None:
        raise bad("tracks or candidates without the time of the last scan")
    if n:
        assert t is not None
        if (tracks.created > tracks.updated).any() or (tracks.updated > t).any():
            raise bad("track times must satisfy created <= updated <= time")
        mu = tracks.mu
        if (mu < 0).any() or (mu > 1).any() or (np.abs(mu.sum(axis=1) - 1.0) > 1e-6).any():
            raise bad("mode probabilities must be in [0, 1] and sum to 1")
        if (tracks.peak < tracks.score).any():
            raise bad("a track's peak score is below its score")
        if (tracks.took >= next_serial).any() or (tracks.first >= next_serial).any():
            raise bad(f"next_serial {next_serial} is not above every detection a track took")
        if (tracks.instants > tracks.hits).any() or (
            tracks.instants < np.minimum(tracks.hits, 1)
        ).any():
            raise bad("a track's instants must be from 1 to its hits (0 with none)")
        if not (_covariances_ok(tracks.P) and _covariances_ok(tracks.P_comb)):
            raise bad("a track covariance is not symmetric with a positive diagonal")
    if k:
        assert t is not None
        if (candidates.time > t).any():
            raise bad("a candidate is later than the last scan")
        if (candidates.serial >= next_serial).any():
            raise bad(f"next_serial {next_serial} is not above every candidate's detection")
        R = candidates.R
        if not _covariances_ok(R) or (R[:, 0, 0] * R[:, 1, 1] - R[:, 0, 1] ** 2 <= 0).any():
            raise bad("a candidate covariance is not symmetric positive definite")
    if saved_models != config.motion.models:
        tracks = _remoded(tracks, config)
    return _State(
        config=config,
        models=build_models(config.motion),
        tracks=_frozen(tracks),
        candidates=candidates,
        time=t,
        next_id=next_id,
        next_origin=next_origin,
        next_serial=next_serial,
        rates=rates,
    )


def _read_rates(r: SectionReader, t: float | None) -> DetectionRates:
    """The sensors' learned detection rates that :meth:`Checkpoint.export` wrote (none in a
    file from before 2026-11-28: learned afresh), checked."""
    if "n_rates" not in r.values:
        return DetectionRates()
    m = r.integer("n_rates", ge=0)
    if m > MAX_SENSORS:
        raise StateError(f"point.n_rates: at most {MAX_SENSORS}, got {m}")
    names = r.strings("rates.sensors", m)
    values = r.floats("rates.values", (m, 4))
    if len(set(names)) != m:
        raise StateError("point.rates.sensors: a sensor appears twice")
    heard, looks, detected, interval = values.T
    if (looks < 0).any() or (detected < 0).any() or (detected > looks * (1 + 1e-9)).any():
        raise StateError("point.rates.values: looks and detections must be 0 <= detected <= looks")
    if (interval < 0).any() or (t is not None and (heard > t).any()):
        raise StateError("point.rates.values: an interval below 0 or a time after the state's")
    return DetectionRates(
        MappingProxyType(
            {
                str(name): SensorRate(
                    float(h), float(lo), float(d), float(iv) if iv > 0 else math.nan
                )
                for name, h, lo, d, iv in zip(names, heard, looks, detected, interval, strict=True)
            }
        )
    )


def _along_where_calm(
    pred: _Prediction,
    scan: Scan,
    ti: np.ndarray,
    dj: np.ndarray,
    P_pairs: np.ndarray,
    lam_fa: float | np.ndarray,
    free: np.ndarray | None,
) -> None:
    """Add ``motion.q_ct_along`` over the time since the track's last detection
    (:func:`~trackers.models.motion.along_track_noise`) to the coordinated-turn mode of the
    gated pairs' predicted covariances ``P_pairs (K, M, 5, 5)`` (pairs ``ti``, ``dj``), in
    place, where the track may take a change of speed from its detection: a confirmed track
    (a tentative one's velocity is still the initiation's guess) with that detection alone in
    its gate, the gate expecting fewer than :data:`GATE_CLUTTER` false alarms
    (:func:`_crowded_gates`), outside every peer's resolution cell (``free``; None: no cell).
    The turn mode is the manoeuvre mode: it holds a target that speeds up or slows down along
    its path as well as one that turns. Where a detection in the gate may as well be clutter
    or a neighbour's, a track free to change its speed follows it: in a patch of clutter the
    map has not learned, false tracks lived on; beside a convoy, a vehicle's track taken by a
    member's detection slowed to the convoy's speed."""
    tracks, motion = pred.tracks, pred.config.motion
    if "ct" not in motion.models:
        return
    lone = np.bincount(ti, minlength=len(tracks)) == 1
    lone &= tracks.confirmed
    if free is not None:
        lone &= free
    k = np.flatnonzero(lone[ti])  # the pair of each such track
    if k.size == 0:
        return
    rows, dets = ti[k], dj[k]
    # the gate of each with the detection's own R (_crowded_gates has the scan's median R)
    S = pred.Pc[rows, :2, :2] + scan.R[dets]
    det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] ** 2
    calm = ~_expects_clutter(_at(lam_fa, dets), det, pred.config.gating.threshold)
    if not calm.all():
        k, rows = k[calm], rows[calm]
        if k.size == 0:
            return
    j = motion.models.index("ct")
    # over τ, the time since the track's last detection: a track that coasted gets the
    # noise of its whole coast, not of the last interval
    tau = pred.time - tracks.updated[rows]
    P_pairs[k, j, 0:4, 0:4] += along_track_block(pred.x_pred[rows, j, 2:4], motion.q_ct_along, tau)


def _remoded(tracks: TrackArrays, config: TrackerConfig) -> TrackArrays:
    """``tracks`` under the motion models of ``config``: each restarts every mode from its
    combined estimate, with the configured initial mode probabilities."""
    M = len(config.motion.models)
    mu0 = np.asarray(config.motion.initial_mode_probabilities)
    return replace(
        tracks,
        x=np.repeat(tracks.x_comb[:, None, :], M, axis=1),
        P=np.repeat(tracks.P_comb[:, None, :, :], M, axis=1),
        mu=np.tile(mu0, (len(tracks), 1)),
    )


def _rows_of(values: Sequence[float], n: int) -> np.ndarray:
    """An (n, len(values)) array whose every row is ``values``."""
    out = np.empty((n, len(values)))
    out[:] = values
    return out


def _new_tracks(
    config: TrackerConfig,
    scan: Scan,
    counters: _Counters,
    detections: np.ndarray,
    x: np.ndarray,
    P: np.ndarray,
    *,
    score: np.ndarray,
    hits: int,
    created: np.ndarray,
    origin: np.ndarray,
    first: np.ndarray | None = None,
) -> TrackArrays:
    """Tentative tracks at this scan from states ``x (n, 4)`` over ``[x, y, vx, vy]``
    with covariances ``P (n, 4, 4)``, each mode starting from that state with turn rate 0
    of std ``turn_rate_std``; ``detections`` index the scan's detections they hold (the
    last of them; ``first`` the serials of their first, when that is another)."""
    M = len(config.motion.models)
    n = detections.size
    if n == 0:
        return TrackArrays.empty(M)
    x0 = np.zeros((n, STATE_DIM))
    x0[:, :4] = x
    P0 = np.zeros((n, STATE_DIM, STATE_DIM))
    P0[:, :4, :4] = P
    P0[:, 4, 4] = config.initiation.turn_rate_std**2
    ids = counters.ids(n)
    det_ids = scan.detection_id_groups.take(detections)
    return TrackArrays(
        ids=ids,
        x=np.repeat(x0[:, None, :], M, axis=1),
        P=np.repeat(P0[:, None, :, :], M, axis=1),
        mu=_rows_of(config.motion.initial_mode_probabilities, n),
        x_comb=x0,
        P_comb=P0,
        score=np.asarray(score, dtype=float),
        peak=np.array(score, dtype=float),
        confirmed=np.zeros(n, dtype=bool),
        hits=np.full(n, hits, dtype=np.int64),
        instants=np.full(n, hits, dtype=np.int64),  # a pair's detections: two instants
        created=np.asarray(created, dtype=float),
        updated=np.full(n, float(scan.time)),
        detection_ids=det_ids,
        origin=np.asarray(origin, dtype=np.int64),
        took=(took := counters.serial + np.asarray(detections, dtype=np.int64)),
        first=took.copy() if first is None else np.asarray(first, dtype=np.int64),
        looked=np.full(n, float(scan.time)),
    )


def _kept(
    tracks: TrackArrays,
    keep: np.ndarray,
    *,
    confirmed: np.ndarray,
    born: TrackArrays,
    n_old: int,
) -> TrackArrays:
    """The rows ``keep`` (a mask) of ``tracks`` with the status ``confirmed`` (one a track of
    ``tracks``), the tracks ``born`` after its first ``n_old`` rows: one pass over the fields
    instead of a ``concat``, a ``replace`` and a ``take``."""
    index = np.flatnonzero(keep)
    cut = int(np.searchsorted(index, n_old))
    head, tail = index[:cut], index[cut:]
    whole = cut == n_old  # none of the first n_old rows goes
    columns = {}
    for k in TrackArrays.__dataclass_fields__:
        v = confirmed if k == "confirmed" else getattr(tracks, k)
        parts = [v[:n_old] if whole else v.take(head, axis=0), getattr(born, k)]
        if tail.size:
            parts.append(v.take(tail, axis=0))
        columns[k] = np.concatenate(parts)
    return TrackArrays(**columns)


def _frozen(tracks: TrackArrays) -> TrackArrays:
    """``tracks`` with every array read-only: what the tracker keeps between scans cannot be
    changed through anything it hands out."""
    for k in TrackArrays.__dataclass_fields__:
        getattr(tracks, k).flags.writeable = False
    return tracks


def _state_of(pred: _Prediction, i: int, t: float) -> PointTrackState:
    """Track ``i`` of a prediction as a hand-over record (its combined estimate at ``t``)."""
    tr = pred.tracks
    return PointTrackState(
        id=str(tr.ids[i]),
        time=t,
        x=pred.xc[i],
        P=pred.Pc[i],
        score=float(tr.score[i]),
        hits=int(tr.hits[i]),
        confirmed=bool(tr.confirmed[i]),
        created=float(tr.created[i]),
        updated=float(tr.updated[i]),
        instants=int(tr.instants[i]),
    )


def _adopted(
    states: Sequence[PointTrackState], config: TrackerConfig, counters: _Counters
) -> TrackArrays:
    """Tracks handed back by a peer, under their own ids: every IMM mode starts from the
    handed state with the configured initial mode probabilities; each is its own origin."""
    n, M = len(states), len(config.motion.models)
    x = np.array([st.x for st in states], dtype=float).reshape(n, STATE_DIM)
    P = np.array([st.P for st in states], dtype=float).reshape(n, STATE_DIM, STATE_DIM)
    score = np.array([st.score for st in states], dtype=float)
    return TrackArrays(
        ids=_objects([st.id for st in states]),
        x=np.repeat(x[:, None, :], M, axis=1),
        P=np.repeat(P[:, None, :, :], M, axis=1),
        mu=_rows_of(config.motion.initial_mode_probabilities, n),
        x_comb=x,
        P_comb=P,
        score=score,
        peak=score.copy(),
        confirmed=np.array([st.confirmed for st in states], dtype=bool),
        hits=np.array([st.hits for st in states], dtype=np.int64),
        instants=np.array([_instants(st) for st in states], dtype=np.int64),
        created=np.array([st.created for st in states], dtype=float),
        updated=np.array([st.updated for st in states], dtype=float),
        detection_ids=_objects([()] * n),
        origin=counters.origins(n),
        took=np.full(n, -1, dtype=np.int64),
        first=np.full(n, -1, dtype=np.int64),
        looked=np.array([st.time for st in states], dtype=float),  # the peer's view of it
    )


def _instants(st: PointTrackState) -> int:
    """A handed state's instants: as many as its hits where it does not say (a peer's)."""
    return int(st.hits if st.instants is None else min(max(st.instants, 1), st.hits))


#: χ²(4) at 0.999: a handed-over track and a local one closer than this in position and
#: velocity (their covariances summed) are one target.
HAND_IN_GATE = 18.47


def _handed_in(
    pred: _Prediction, states: Sequence[PointTrackState], counters: _Counters
) -> tuple[_Prediction, tuple[str, ...]]:
    """``pred`` with the tracks another instance handed over (their ids kept), each
    predicted from its own time to ``pred.time`` by the IMM (from the handed estimate in
    every mode, with the configured initial mode probabilities; a state newer than the scan
    is taken as it is), so that the scan updates them like the others.

    A handed track that a local one already follows (Mahalanobis distance over position and
    velocity, ``d² = Δᵀ (P_h + P_l)⁻¹ Δ < HAND_IN_GATE``) is not added: the nearest such
    local track takes its id, its first time, its hits (added) and the higher score and is
    confirmed. A state whose id is live here already is ignored. Returns the new prediction
    and the confirmed local ids that were renamed (gone from the reports under their old
    ids)."""
    t, config, models = pred.time, pred.config, pred.models
    live = set(pred.tracks.ids.tolist())
    fresh = [st for st in states if st.id not in live]
    if not fresh:
        return pred, ()
    born = _adopted(fresh, config, counters)
    n = len(fresh)
    x_pred, P_pred = born.x.copy(), born.P.copy()
    c_bar = born.mu.copy()
    for i, st in enumerate(fresh):
        dt = max(0.0, t - st.time)
        if dt > 0:
            Pi = transition_matrix(config.motion.sojourn_times, dt)
            xs, Ps, cs = imm_predict(
                models, born.x[i : i + 1], born.P[i : i + 1], born.mu[i : i + 1], Pi, dt
            )
            x_pred[i], P_pred[i], c_bar[i] = xs[0], Ps[0], cs[0]
    xc, Pc = imm_combine(x_pred, P_pred, c_bar)

    tracks = pred.tracks
    ids = tracks.ids.copy()
    created, score, hits = tracks.created.copy(), tracks.score.copy(), tracks.hits.copy()
    instants = tracks.instants.copy()
    peak, confirmed = tracks.peak.copy(), tracks.confirmed.copy()
    renamed: list[str] = []
    add = np.ones(n, dtype=bool)
    free = np.ones(len(tracks), dtype=bool)
    for i, st in enumerate(fresh):
        if not free.any():
            break
        d = pred.xc[:, :4] - xc[i, :4]
        S = pred.Pc[:, :4, :4] + Pc[i, :4, :4]
        d2 = np.einsum("ni,ni->n", d, np.linalg.solve(S, d[..., None])[..., 0])
        d2[~free] = np.inf
        k = int(np.argmin(d2))
        if d2[k] >= HAND_IN_GATE:
            continue
        if confirmed[k]:
            renamed.append(str(ids[k]))
        ids[k] = st.id
        created[k] = min(created[k], st.created)
        hits[k] += st.hits  # both instances' detections, over the time since created
        instants[k] = max(instants[k], _instants(st))  # the same target at the same times
        score[k] = max(score[k], st.score)
        peak[k] = max(peak[k], score[k])
        confirmed[k] = True
        free[k] = False
        add[i] = False
    tracks = replace(
        tracks,
        ids=ids,
        created=created,
        hits=hits,
        instants=instants,
        score=score,
        peak=peak,
        confirmed=confirmed,
    )
    keep = np.flatnonzero(add)
    born = born.take(keep)
    merged = replace(
        pred,
        tracks=tracks.concat(born),
        x_pred=np.concatenate([pred.x_pred, x_pred[keep]]),
        P_pred=np.concatenate([pred.P_pred, P_pred[keep]]),
        c_bar=np.concatenate([pred.c_bar, c_bar[keep]]),
        xc=np.concatenate([pred.xc, xc[keep]]),
        Pc=np.concatenate([pred.Pc, Pc[keep]]),
    )
    return merged, tuple(renamed)


def _manoeuvre_found(
    pred: _Prediction,
    scan: Scan,
    assigned: np.ndarray,
    gated: np.ndarray,
    pd: np.ndarray,
    lam_fa: float | np.ndarray,
    seen: np.ndarray | None,
    searching: np.ndarray | None,
) -> ManoeuvreMatch | None:
    """:func:`manoeuvre_search` for the confirmed tracks in view (``seen``) and
    ``searching`` (``None``: all), not in ``assigned``, over the detections not in ``gated``
    (those in a confirmed track's gate), its indices turned into the scan's tracks and
    detections."""
    config, tracks = pred.config, pred.tracks
    lost = tracks.confirmed.copy() if searching is None else tracks.confirmed & searching
    if seen is not None:
        lost &= seen
    lost[assigned] = False
    lost = np.flatnonzero(lost)
    if lost.size == 0:
        return None
    gating = config.gating
    a_max, omega_max = gating.manoeuvre_acceleration, gating.manoeuvre_turn_rate
    tau = scan.time - tracks.updated[lost]
    # Most lost tracks' manoeuvres stay within their gates: the search's arrays are taken
    # for the others only.
    agile = config.motion.agile_acceleration
    wide = reaches_beyond(
        pred.xc[lost],
        pred.Pc[lost],
        tau,
        a_max,
        omega_max,
        gating.manoeuvre_speed_change,
        agile=agile,
    )
    lost, tau = lost[wide], tau[wide]
    free = np.ones(scan.size, dtype=bool)
    free[gated] = False
    free = np.flatnonzero(free)
    if lost.size == 0 or free.size == 0:
        return None
    found = manoeuvre_search(
        pred.x_pred[lost],
        pred.P_pred[lost],
        pred.c_bar[lost],
        pred.xc[lost],
        pred.Pc[lost],
        tau,
        scan.z[free],
        scan.R[free],
        pd[lost],
        _at(lam_fa, free),
        a_max=a_max,
        omega_max=omega_max,
        straight_sojourn=config.motion.sojourn_times[0],
        gamma=config.gating.threshold,
        max_speed=config.initiation.max_speed,
        a_speed=gating.manoeuvre_speed_change,
        quiet=GATE_CLUTTER,
        agile=agile,
    )
    if found is None:
        return None
    return replace(found, track=lost[found.track], detection=free[found.detection])


#: A track holding this many detections is taken to be a target's: the clutter map does not
#: count the detections it takes, tentative or not.
ESTABLISHED_HITS = 3


def _clutter_densities(scan: Scan, configured: float) -> float | np.ndarray:
    """λ_fa: the density the batch states, else the clutter map's at each detection
    (:mod:`trackers.clutter`), else the configured one."""
    if scan.clutter_density is not None:
        return float(scan.clutter_density)
    if scan.clutter_map is not None:
        return scan.clutter_map
    return configured


def _at(lam: float | np.ndarray, rows: np.ndarray) -> float | np.ndarray:
    """λ_fa of the detections ``rows``: the one number, or theirs."""
    return lam if isinstance(lam, float) else np.take(lam, rows)


def _typical(lam: float | np.ndarray) -> float:
    """One λ_fa for a scan: the one number, or the median of the detections'."""
    if isinstance(lam, float):
        return lam
    return float(np.median(lam)) if lam.size else 1.0


def _initial_scores(
    new_target_density: float, lam: float | np.ndarray, rows: np.ndarray
) -> np.ndarray:
    """``L(1) = max(ln(λ_nt / λ_fa), ln κ)`` (:func:`trackers.scoring.initial_score`) of new
    candidates or tracks at the detections ``rows``."""
    if isinstance(lam, float):
        return np.full(rows.size, initial_score(new_target_density, lam))
    return initial_score_each(new_target_density, np.take(lam, rows))


def _candidates_visible(cand: Candidates, scan: Scan, config: TrackerConfig) -> np.ndarray | None:
    """The share of each candidate's target's possible positions in the scan's view, under
    the two-point prior (:mod:`trackers.initiation`) after ``Δt`` since its detection: with
    weight ``w`` (``slow_target_fraction``) a slow target,
    ``N(z_c, R_c + (σ_v² Δt² + q Δt³/3) I)`` (:func:`~trackers.coverage.visible_fraction`),
    else one anywhere within ``v_max Δt`` plus its gate (:func:`~trackers.coverage.disc_fraction`):

        f = w f_slow + (1 − w) f_fast.

    ``None`` (all of it) when the scan covers everything. A radar's candidate 100 m outside a
    camera's square is not missed by the camera's scans ten times a second (it was, when any
    reach into the view counted as a look, and the radar started no track there)."""
    if scan.coverage is None:
        return None
    init = config.initiation
    dt = np.maximum(float(scan.time) - cand.time, 0.0)
    spread = init.velocity_std**2 * dt**2 + config.motion.q_cv * dt**3 / 3.0
    slow = visible_fraction(scan.coverage, cand.z, cand.R + spread[:, None, None] * np.eye(2))
    reach = np.sqrt(config.gating.threshold * max_eigenvalue_2x2(cand.R)) + init.max_speed * dt
    fast = disc_fraction(scan.coverage, cand.z, reach)
    w = init.slow_target_fraction
    return w * slow + (1.0 - w) * fast


def _visible(pred: _Prediction, scan: Scan) -> np.ndarray | None:
    """The share of each predicted track's position distribution ``N(x̂, P̂)`` in the scan's
    coverage (:func:`~trackers.coverage.visible_fraction`); ``None`` (all) when the scan
    covers everything. A scan misses a track with probability ``P_D`` times it."""
    if scan.coverage is None:
        return None
    return visible_fraction(scan.coverage, pred.xc[:, :2], pred.Pc[:, :2, :2])


def _with_range_rates(
    x: np.ndarray,
    P: np.ndarray,
    mu: np.ndarray,
    loglik: np.ndarray,
    scan: Scan,
    det: np.ndarray,
    config: TrackerConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pairs' posteriors updated again with their detections' range-rates, where the
    scan has them and a sensor position (:func:`trackers.filters.imm.imm_range_rate_update`;
    seen from a moving sensor when the scan gives its velocity ``v_s``), and their
    log-likelihoods grown by the range-rate's likelihood ratio against a false alarm's,
    ``ln Λ − ln p_fa(ṙ)`` (:func:`_false_range_rate_log_density`: surface clutter near zero
    Doppler, and the rest uniform within ``±v_max``, ``v_max = initiation.max_speed + |v_s|``).

    A range-rate outside its gate in every mode (``ν_j²/S_j > γ₁``, one degree of freedom,
    ``gating.gate_probability``) is not used: the pair keeps its position-only update, so a
    sensor whose Doppler is aliased or of the wrong sign loses nothing against one that sends
    none. One inside the gate of some mode updates every mode, and the mode probabilities
    with it (a turn's onset shows first in the range-rate). Nor is one used where the track is
    within :data:`~trackers.models.measurement.MIN_RANGE` of the sensor. The last array says
    of each pair: :data:`_NO_RANGE_RATE`, :data:`_RANGE_RATE_REFUSED` (outside its gate) or
    :data:`_RANGE_RATE_USED`."""
    status = np.full(det.size, _NO_RANGE_RATE, dtype=np.int8)
    if scan.range_rate is None or scan.sensor_position is None or det.size == 0:
        return x, P, mu, loglik, status
    rdot = np.take(scan.range_rate, det)
    have = np.flatnonzero(np.isfinite(rdot))
    if have.size == 0:
        return x, P, mu, loglik, status
    sensor = np.asarray(scan.sensor_position, dtype=float)
    v_s = scan.sensor_velocity
    variance = config.measurement.range_rate_std**2
    K, M, n = x[have].shape
    xm = x[have].reshape(K * M, n)
    nu, S = range_rate_innovation(
        xm, P[have].reshape(K * M, n, n), np.repeat(rdot[have], M), sensor, variance, v_s
    )
    inside = (nu * nu <= config.gating.threshold_1d * S).reshape(K, M).any(axis=1)
    far = (np.hypot(xm[:, 0] - sensor[0], xm[:, 1] - sensor[1]) >= MIN_RANGE).reshape(K, M)
    status[have[far.all(axis=1) & ~inside]] = _RANGE_RATE_REFUSED
    have = have[inside & far.all(axis=1)]
    if have.size == 0:
        return x, P, mu, loglik, status
    status[have] = _RANGE_RATE_USED
    x, P, mu, loglik = x.copy(), P.copy(), mu.copy(), loglik.copy()
    xh, Ph, muh, dll = imm_range_rate_update(
        x[have], P[have], mu[have], rdot[have], sensor, variance, v_s
    )
    x[have], P[have], mu[have] = xh, Ph, muh
    v_max = config.initiation.max_speed + (0.0 if v_s is None else math.hypot(*v_s))
    loglik[have] -= _false_range_rate_log_density(
        rdot[have], scan.z[det[have]], sensor, v_s, v_max, config.measurement
    )
    loglik[have] += dll
    return x, P, mu, loglik, status


#: The share of false alarms that are surface clutter near zero Doppler (vegetation, sea,
#: ground seen through the sidelobes) in the range-rate's false-alarm density
#: (:func:`_false_range_rate_log_density`); the rest are spread evenly.
SURFACE_CLUTTER_SHARE = 0.1


def _false_range_rate_log_density(
    rdot: np.ndarray,
    z: np.ndarray,
    sensor: np.ndarray,
    v_s: tuple[float, float] | None,
    v_max: float,
    measurement: MeasurementConfig,
) -> np.ndarray:
    """``ln p_fa(ṙ)`` of range-rates ``ṙ`` of false alarms at ``z (K, 2)``: a mixture of
    surface clutter, still on the ground, and false alarms spread evenly within ``±v_max``::

        p_fa(ṙ) = w N(ṙ + u·v_s; 0, σ_c²) + (1 − w) / (2 v_max),

    ``w`` = :data:`SURFACE_CLUTTER_SHARE`, ``σ_c`` = ``measurement.clutter_range_rate_std``
    (0: the even part alone), ``u`` the unit vector from the sensor to ``z`` and ``v_s`` its
    velocity (the ground's range-rate seen from a moving sensor is ``−u·v_s``). A track that
    crosses the beam, its range-rate near zero, gains little (about 0.6 a hit, 4 before) from
    a range-rate that wind-blown trees give as well (a newcomer's ground radar: 4.8 false
    tracks a scan in a 2 km² patch of vegetation with range-rates, 0.02 without them); one
    moving along the beam gains as before."""
    uniform = 1.0 / (2.0 * v_max)
    sigma = measurement.clutter_range_rate_std
    if sigma <= 0.0:
        return np.full(rdot.shape, math.log(uniform))
    ground = np.asarray(rdot, dtype=float).copy()
    if v_s is not None:
        d = z - sensor
        r = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        ground += (d[:, 0] * v_s[0] + d[:, 1] * v_s[1]) / r
    w = SURFACE_CLUTTER_SHARE
    surface = np.exp(-0.5 * (ground / sigma) ** 2) / (math.sqrt(2.0 * math.pi) * sigma)
    return np.log(w * surface + (1.0 - w) * uniform)


#: What became of a pair's range-rate (:func:`_with_range_rates`).
_NO_RANGE_RATE, _RANGE_RATE_REFUSED, _RANGE_RATE_USED = 0, 1, 2


def _group_velocities(z: np.ndarray, tracks: TrackArrays, init: InitiationConfig) -> np.ndarray:
    """For each detection ``z (n, 2)`` that opens a candidate, the velocity of the nearest
    confirmed track within ``init.group_radius`` that is at least ``init.group_min_speed``
    fast (and no faster than ``init.max_speed``), ``(n, 2)``; NaN where there is none (or
    ``init.group_fraction`` is 0)."""
    out = np.full((z.shape[0], 2), np.nan)
    if init.group_fraction <= 0.0 or z.shape[0] == 0 or len(tracks) == 0:
        return out
    v = tracks.x_comb[:, 2:4]
    speed = np.hypot(v[:, 0], v[:, 1])
    rows = np.flatnonzero(
        tracks.confirmed & (speed >= init.group_min_speed) & (speed <= init.max_speed)
    )
    if rows.size == 0:
        return out
    p = np.take(tracks.x_comb[:, :2], rows, axis=0)
    j, k = pairs_within(z, np.full(z.shape[0], init.group_radius), p)
    if j.size == 0:
        return out
    d2 = np.sum((np.take(p, k, axis=0) - np.take(z, j, axis=0)) ** 2, axis=1)
    order, rank = sort_within_groups(j, -d2)  # by detection, nearest first
    nearest = order[rank == 0]
    out[j[nearest]] = np.take(v, np.take(rows, k[nearest]), axis=0)
    return out


def _mean_gap(tracks: TrackArrays) -> np.ndarray:
    """``Δ̄ = (t_updated − t_created) / (n − 1)``: each track's mean interval between its
    detections, ``n`` the instants of them (three radars reporting together update a track
    once a revisit)."""
    return (tracks.updated - tracks.created) / np.maximum(tracks.instants - 1, 1)


def _revisit(tracks: TrackArrays, pd: float) -> np.ndarray:
    """``T̂ = P_D Δ̄``: each track's sensor revisit as the track saw it (its mean interval
    between detections :func:`_mean_gap`, of which a fraction ``P_D`` are detected)."""
    return pd * _mean_gap(tracks)


def _coast_rate(
    tracks: TrackArrays,
    max_coast: float,
    pd: float,
    revisits: float | np.ndarray,
    sensor_interval: float = 0.0,
) -> np.ndarray:
    """The rate at which each track's coasting time counts against ``max_coast``:

        min(1, T_coast / (revisits · T̂)),

    ``T̂`` its sensor's revisit: as the track saw it (its mean interval between detections
    ``Δ̄`` of :func:`_mean_gap`, of which a fraction ``P_D`` are detected; for confirmed
    tracks with detections of at least :data:`COAST_MIN_INSTANTS` instants, as a false
    track's few hits say little of a revisit), and, for every confirmed track, at least the mean
    interval ``T_s`` between the scan's sensor's batches (0 while unknown) up to ``Δ̄``:

        T̂ = max(P_D Δ̄, min(T_s, Δ̄)).

    The track's own reading alone falls short of the revisit when the track happened to be
    detected more often than ``P_D``: at a 10 s revisit and ``P_D`` 0.85, 3.1 revisits, a
    track seen 16 times in a row was deleted at its third miss (30 s, beyond 3.1 · 8.5 s).
    ``Δ̄`` bounds ``T_s``: a track that three unsynchronized 10 s radars update every 3.3 s
    does not coast 2.5 · 10 s. The rate is 1 for the other tracks; it is below 1 only where
    ``revisits`` revisits take longer than ``max_coast`` (a revisit over 4 s with the
    defaults and ``P_D`` 0.9, ``revisits`` 2.5), and then lets a track coast through that
    many revisits."""
    reach = np.where(tracks.confirmed, revisits * _revisit_time(tracks, pd, sensor_interval), 0.0)
    return np.minimum(1.0, max_coast / np.maximum(reach, max_coast))


def _left_view(
    pred: _Prediction,
    idle: np.ndarray,
    revisit: np.ndarray,
    t: float,
    regard: Mapping[str, _Regard],
    since: float,
    max_coast: float,
) -> np.ndarray:
    """Of the tracks ``idle`` (indices of the predicted tracks out of this scan's view;
    ``revisit`` their :func:`_revisit_time`), a mask of those that have left every sensor's
    view: confirmed (young ones too), looked at by no scan for :data:`LOOK_CYCLES` of their
    revisits (read alike for every track, ``max(P_D Δ̄, min(T_s, Δ̄))``), and in
    no sensor's field of regard (``regard``: less than :data:`REGARD_SHARE` of the predicted
    position in each area its last scans looked at). None while the fields of regard are
    younger than ``max_coast`` (the tracker started, was reset or restored at ``since``). A
    car past the end of a road radar's stated coverage is gone; a track in another sector of
    a rotating radar that reports its turn by sectors, in the view of a slower radar only or
    of a sensor that paused is not."""
    tracks = pred.tracks
    out = tracks.confirmed[idle] & (t - tracks.looked[idle] > LOOK_CYCLES * revisit)
    if not out.any() or t - since < max_coast:
        return np.zeros(idle.size, dtype=bool)
    at = idle[out]
    xy, P = pred.xc[at, :2], pred.Pc[at, :2, :2]
    seen = np.zeros(at.size, dtype=bool)
    for r in regard.values():
        for area in r.areas:
            if area is None:
                return np.zeros(idle.size, dtype=bool)  # a sensor that looks everywhere
            seen |= visible_fraction(area, xy, P) >= REGARD_SHARE
    out[out] = ~seen
    return out


def _revisit_time(
    tracks: TrackArrays,
    pd: float,
    sensor_interval: float = 0.0,
    min_instants: int = COAST_MIN_INSTANTS,
) -> np.ndarray:
    """``T̂ = max(P_D Δ̄, min(T_s, Δ̄))``, each track's sensor revisit as :func:`_coast_rate`
    reads it (``P_D Δ̄`` only for tracks with detections of ``min_instants`` instants or
    more)."""
    gap = _mean_gap(tracks)
    own = np.where(tracks.instants >= min_instants, pd * gap, 0.0)
    return np.maximum(own, np.minimum(sensor_interval, gap))


#: A track coasts past MIN_MISSES − ½ revisits only while fewer false alarms than this are
#: expected in its gate (:mod:`trackers.detection_rate`).
GATE_CLUTTER = 0.1


def _gated_densities(
    n: int, gated: tuple[np.ndarray, np.ndarray], lam_fa: float | np.ndarray
) -> np.ndarray:
    """Each of the ``n`` tracks' highest false-alarm density among the detections in its
    gate (``gated``: the track and detection index of each gated pair; NaN: none in it)."""
    ti, dj = gated
    lam_gated = np.full(n, np.nan)
    if ti.size:
        lam_gated[:] = -np.inf
        np.maximum.at(lam_gated, ti, np.broadcast_to(_at(lam_fa, dj), ti.shape))
        lam_gated[np.isneginf(lam_gated)] = np.nan
    return lam_gated


def _crowded_gates(
    Pc: np.ndarray,
    scan: Scan,
    lam_fa: float | np.ndarray,
    lam_gated: np.ndarray,
    gamma: float,
) -> np.ndarray:
    """Mask of the tracks whose gate expects at least :data:`GATE_CLUTTER` false alarms:

        λ V ≥ GATE_CLUTTER,   V = π γ √det(P_pos + R̄),

    with ``P_pos`` a track's predicted position covariance and ``R̄`` the scan's median
    detection covariance; ``λ`` the highest false-alarm density among the detections in the
    track's gate (``lam_gated``), else the scan's (its median where the clutter map gives one
    per detection). A scan with no detection leaves every gate clear: there is nothing in it
    to take."""
    if scan.size == 0:
        return np.zeros(Pc.shape[0], dtype=bool)
    scene = float(np.median(lam_fa)) if isinstance(lam_fa, np.ndarray) else float(lam_fa)
    lam = np.where(np.isnan(lam_gated), scene, lam_gated)
    S = Pc[:, :2, :2] + np.median(scan.R, axis=0)
    return _expects_clutter(lam, S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] ** 2, gamma)


def _expects_clutter(lam: float | np.ndarray, det: np.ndarray, gamma: float) -> np.ndarray:
    """Whether gates ``mᵀ S⁻¹ m ≤ γ`` of ``det S`` expect at least :data:`GATE_CLUTTER`
    false alarms at densities ``lam``: ``λ π γ √det S ≥ GATE_CLUTTER``."""
    return expected_false_alarms(lam, det, gamma) >= GATE_CLUTTER


def _looks(
    tracks: TrackArrays, visible: np.ndarray | None, masked: np.ndarray, t: float, pd: float
) -> np.ndarray:
    """Mask of the tracks (before this scan's update) that count as a look of the sensor at
    an established target (:mod:`trackers.detection_rate`): confirmed, with at least
    :data:`~trackers.detection_rate.LOOK_MIN_HITS` detections, in view (at least
    :data:`LOOK_MIN_VISIBLE` of its position, ``visible``), outside every peer's
    resolution cell, and detected within 1.5 revisits ``T̂`` (the track's, as in
    :func:`_coast_rate`): a target missed since counts its first miss only, and a sector of a
    revolution counts the tracks it detected a revolution before."""
    look = tracks.confirmed & (tracks.hits >= LOOK_MIN_HITS)
    look &= t - tracks.updated <= 1.5 * _revisit(tracks, pd)
    look &= masked >= 1.0
    if visible is not None:
        look &= visible >= LOOK_MIN_VISIBLE
    return look


#: A track counts as a look of the sensor when at least this share of its predicted position
#: is in the scan's view (:func:`_looks`): one at the edge of the view says little of P_D.
LOOK_MIN_VISIBLE = 0.95

#: The acceleration a relinked target may have had, at least (m/s²): a car pulling away, a
#: helicopter leaving its hover (the turn-rate bound ``ω_max |v|`` is nothing at rest).
RELINK_MIN_ACCELERATION = 5.0


def _relinked(
    tracks: TrackArrays,
    young: np.ndarray,
    delete: np.ndarray,
    t: float,
    config: TrackerConfig,
    n_old: int,
    clutter_density: float,
    lost: np.ndarray | None = None,
) -> tuple[TrackArrays, np.ndarray, np.ndarray]:
    """Young tracks (``young``: tentative ones with detections of at least 3 instants that
    are confirmed at this scan or score 0 or more) that continue a confirmed track which lost
    their target, merged into it: the old track takes the young one's state and detections,
    goes on under its id, confirmed, with the higher of the two scores as its score and its peak;
    the young one is dropped. Returns the tracks, ``young`` and ``delete`` (the old track
    kept, the young one dropped). Only the first ``n_old`` rows (the tracks before this
    scan's births and hand-backs) take part.

    A confirmed track *o* last updated at ``t_o`` (not at this scan, and before the first
    detection of the young track *n*) is continued by *n* when a constant acceleration
    ``a = (v_n − v_o) / Δt``, ``Δt = t − t_o``, takes *o*'s state at ``t_o`` to *n*'s at
    ``t``, within the gate, no harder than a manoeuvre can be and likelier than a new target:

        e = p_n − p̂_o − ½ (v_n − v_o) Δt,
        S = P_n,pp + P̂_o,pp + (Δt/2)² (P_n,vv + P̂_o,vv),
        eᵀ S⁻¹ e ≤ γ,   N(e; 0, S) ≥ λ_nt,
        |a| ≤ min(a_max, max(a_0, ω v)),   v = max(|v_o|, |v_n|),

    with ``p̂_o = p_o + v_o Δt`` the old track's prediction to ``t`` (its covariance grown
    by the coasting), ``λ_nt`` the new-target density in force against the scan's typical
    false-alarm density ``clutter_density``
    (:func:`trackers.scoring.new_target_odds_density`; a vague old track, long lost, loses
    to a new target), ``a_max`` and ``ω`` the manoeuvre search's bounds (``ω_max``, or from
    25 m/s the agile rate of ``motion.agile_acceleration`` within 1 rad over ``Δt``) and ``a_0`` =
    :data:`RELINK_MIN_ACCELERATION`. The likeliest pairs (highest ``N(e; 0, S)``) are merged
    first, each track at most once. A target that set off from a hover, braked hard or
    turned out of its track's gate was otherwise seen by a second track while the first
    coasted on beside it, then deleted: the target changed id. A young track that is not
    confirmed yet must score 0 or more: in dense clutter three false alarms in a row fit a
    coasting track's wide prediction now and then."""
    new = np.flatnonzero(young[:n_old])
    old = np.flatnonzero((tracks.confirmed & (tracks.updated < t))[:n_old])
    if lost is not None:
        old = old[~lost[old]]
    if new.size and old.size:  # only those lost before the youngest started
        old = old[tracks.updated[old] < tracks.created[new].max()]
    if new.size == 0 or old.size == 0:
        return tracks, young, delete
    gating = config.gating
    gamma = gating.threshold
    nt_density = config.track_management.new_target_density
    xn, Pn = tracks.x_comb[new], tracks.P_comb[new]
    xo, Po = tracks.x_comb[old], tracks.P_comb[old]
    dt = t - tracks.updated[old]
    speed = np.maximum(
        np.hypot(xn[:, None, 2], xn[:, None, 3]), np.hypot(xo[None, :, 2], xo[None, :, 3])
    )
    rate = agile_turn_rate(
        speed,
        gating.manoeuvre_turn_rate,
        config.motion.agile_acceleration,
        dt[None, :],
        MAX_AGILE_SEARCH_TURN,
    )
    a_bound = np.minimum(
        gating.manoeuvre_acceleration, np.maximum(RELINK_MIN_ACCELERATION, rate * speed)
    )

    # A cheap bound first (traces for the largest eigenvalues): |p_n − p̂_o| can be at most
    # the gate's radius plus half the largest velocity change's displacement.
    tr_n = np.trace(Pn[:, 0:2, 0:2], axis1=1, axis2=2), np.trace(Pn[:, 2:4, 2:4], axis1=1, axis2=2)
    tr_o = np.trace(Po[:, 0:2, 0:2], axis1=1, axis2=2), np.trace(Po[:, 2:4, 2:4], axis1=1, axis2=2)
    h2 = (0.5 * dt)[None, :] ** 2
    radius = (
        np.sqrt(
            gamma
            * (tr_n[0][:, None] + tr_o[0][None, :] + h2 * (tr_n[1][:, None] + tr_o[1][None, :]))
        )
        + 0.5 * a_bound * dt[None, :] ** 2
    )
    near = np.hypot(xn[:, None, 0] - xo[None, :, 0], xn[:, None, 1] - xo[None, :, 1]) <= radius
    near &= tracks.updated[old][None, :] < tracks.created[new][:, None]
    ni, oj = np.nonzero(near)
    if ni.size == 0:
        return tracks, young, delete
    dv = xn[ni, 2:4] - xo[oj, 2:4]
    e = xn[ni, 0:2] - xo[oj, 0:2] - 0.5 * dv * dt[oj, None]
    S = (
        Pn[ni, 0:2, 0:2]
        + Po[oj, 0:2, 0:2]
        + h2[0, oj, None, None] * (Pn[ni, 2:4, 2:4] + Po[oj, 2:4, 2:4])
    )
    a, b, c = S[:, 0, 0], S[:, 0, 1], S[:, 1, 1]
    det = a * c - b * b
    ex, ey = e[:, 0], e[:, 1]
    m = (c * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / np.maximum(det, 1e-300)
    cost = 0.5 * m + np.log(2.0 * np.pi * np.sqrt(np.maximum(det, 1e-300)))  # −ln N(e; 0, S)
    fits = (
        (det > 0.0)
        & (m <= gamma)
        & (cost <= -math.log(new_target_odds_density(nt_density, clutter_density)))
        & (np.hypot(dv[:, 0], dv[:, 1]) <= a_bound[ni, oj] * dt[oj])
    )
    if not fits.any():
        return tracks, young, delete
    ni, oj, cost = ni[fits], oj[fits], cost[fits]
    pairs: list[tuple[int, int]] = []
    used_n: set[int] = set()
    used_o: set[int] = set()
    for k in np.argsort(cost, kind="stable").tolist():
        i, j = int(ni[k]), int(oj[k])
        if i not in used_n and j not in used_o:
            used_n.add(i)
            used_o.add(j)
            pairs.append((int(new[i]), int(old[j])))
    rn = np.array([p[0] for p in pairs])
    ro = np.array([p[1] for p in pairs])
    fields = {k: getattr(tracks, k).copy() for k in tracks.__dataclass_fields__}
    for k in ("x", "P", "mu", "x_comb", "P_comb", "updated", "detection_ids", "took", "looked"):
        fields[k][ro] = fields[k][rn]
    fields["hits"][ro] += fields["hits"][rn]
    fields["instants"][ro] += fields["instants"][rn]
    fields["score"][ro] = np.maximum(fields["score"][ro], fields["score"][rn])
    fields["peak"][ro] = fields["score"][ro]  # found again: the drop from the peak restarts
    young = young.copy()
    delete = delete.copy()
    young[rn] = False
    delete[rn] = True
    delete[ro] = False
    return _frozen(TrackArrays(**fields)), young, delete


#: A track whose estimated speed exceeds this many times ``initiation.max_speed`` is deleted
#: (:func:`_runaway`).
RUNAWAY_SPEED = 1.25


def _runaway(tracks: TrackArrays, max_speed: float) -> np.ndarray:
    """Mask of the tracks whose combined velocity estimate ``|v|`` exceeds
    :data:`RUNAWAY_SPEED` × ``max_speed``, the fastest target the tracker starts a track on:
    such an estimate follows no target. At a 10 s revisit over sparse clutter (100 false
    alarms over 150 km × 150 km), a jet's track that lost it in a 5 g turn took a false alarm
    in its grown gate at every scan, each costing its score less than a miss, and ran on for
    70 s at up to 1600 m/s (0.3 of the 0.9 false confirmed tracks a scan were such)."""
    v = tracks.x_comb[:, 2:4]
    return np.hypot(v[:, 0], v[:, 1]) > RUNAWAY_SPEED * max_speed


def _best_of_each_origin(tracks: TrackArrays, last: np.ndarray | None = None) -> np.ndarray:
    """Mask of the tracks to keep: every confirmed track, and of the tentative tracks that
    share an origin (rival starts from one detection) only the one with the highest score,
    unless a confirmed track of that origin exists; the tracks ``last`` (indices) rank below
    every other rival whatever their score."""
    # (a confirmed track sorts first as a score of +inf: two sort keys instead of three)
    ranked = np.where(tracks.confirmed, np.inf, tracks.score)
    if last is not None and last.size:
        ranked = ranked.copy()
        ranked[last] = -np.inf
    order, rank = sort_within_groups(tracks.origin, ranked)
    best = np.zeros(len(tracks), dtype=bool)
    best[order] = rank == 0
    return best | tracks.confirmed


def _siblings_sharing(
    tracks: TrackArrays,
    ti: np.ndarray,
    dj: np.ndarray,
    gain: np.ndarray,
    pairs: np.ndarray,
    chosen: np.ndarray,
) -> np.ndarray:
    """The gate pairs (indices into ``ti``, ``dj``, ``gain``) by which tentative tracks
    share a detection with a *sibling*, a tentative track whose last detection was theirs
    (``tracks.took``) and that took this one (``chosen``, among ``pairs``): for each track
    the assignment left without a detection, its pair of highest gain among such, where the
    gain is positive. Siblings are rival readings of one target (a detection paired with
    different earlier ones, or taken by an older track and by a pair born on it): the
    assignment gives a detection to one of them, but a detection of the same instant (a
    second radar reporting with the first) says nothing of their velocities, and one of a
    later instant is for their scores to tell apart. Alone, all but one would take a miss
    and most would be deleted however right their velocity."""
    none = np.zeros(0, dtype=np.intp)
    if chosen.size == 0 or pairs.size == chosen.size:
        return none
    key = np.where(tracks.confirmed, -1, tracks.took)
    took = np.zeros(len(tracks), dtype=bool)
    took[ti[chosen]] = True
    c = chosen[key[ti[chosen]] >= 0]
    rest = pairs[~took[ti[pairs]] & (key[ti[pairs]] >= 0) & (gain[pairs] > 0)]
    if rest.size == 0 or c.size == 0:
        return none
    # (last detection, this one) of each pair, on small numbers: the keys' ranks
    _, rank = np.unique(np.concatenate([key[ti[c]], key[ti[rest]]]), return_inverse=True)
    n_det = int(dj.max()) + 1
    code = rank * n_det + np.concatenate([dj[c], dj[rest]])
    rest = rest[np.isin(code[c.size :], code[: c.size])]
    order, rank = sort_within_groups(ti[rest], gain[rest])  # each track's best pair
    return rest[order[rank == 0]]


def _sibling_losers(tracks: TrackArrays, serial: int) -> tuple[np.ndarray, np.ndarray]:
    """Of the tentative tracks that took one detection at this batch (its detections are
    numbered from ``serial``; siblings sharing it, :func:`_siblings_sharing`), those that
    are not the likeliest (the highest score), and the likeliest sibling of each: two index
    arrays."""
    none = np.zeros(0, dtype=np.intp)
    k = np.flatnonzero(~tracks.confirmed & (tracks.took >= serial))
    if k.size < 2:
        return none, none
    order, rank = sort_within_groups(tracks.took[k], tracks.score[k])
    if not rank.any():  # no two took one detection
        return none, none
    k = k[order]
    winner = k[np.arange(k.size) - rank]  # each one's group's first, its likeliest
    return k[rank > 0], winner[rank > 0]


def _snapshots(
    tr: TrackArrays, names: tuple[str, ...], t: float, *, confirmed_only: bool
) -> tuple[TrackSnapshot, ...]:
    if confirmed_only:
        tr = tr.take(tr.confirmed)
    if not len(tr):
        return ()
    pos = tr.x_comb[:, :2].tolist()
    vel = tr.x_comb[:, 2:4].tolist()
    cov = tr.P_comb[:, :4, :4].copy()
    cov.flags.writeable = False  # a snapshot cannot change the tracker, nor another snapshot
    status = np.where(tr.confirmed, "confirmed", "tentative").tolist()
    return tuple(
        TrackSnapshot(
            id=tid,
            kind=KIND,
            status=st,
            time=t,
            position=(p[0], p[1]),
            velocity=(v[0], v[1]),
            covariance=c,
            score=s,
            hits=h,
            created=cr,
            updated=up,
            model_probabilities=dict(zip(names, m, strict=True)),
            detection_ids=d,
        )
        for tid, st, p, v, c, s, h, cr, up, m, d in zip(
            tr.ids.tolist(),
            status,
            pos,
            vel,
            cov,
            tr.score.tolist(),
            tr.hits.tolist(),
            tr.created.tolist(),
            tr.updated.tolist(),
            tr.mu.tolist(),
            tr.detection_ids.tolist(),
            strict=True,
        )
    )
