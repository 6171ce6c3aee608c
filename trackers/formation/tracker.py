"""Formation tracks by template matching (paper 003, MSFT-TM); a peer of the point tracker.

A formation is a few resolvable targets flying together. Its members are individual tracks
that the formation tracker takes over from the point tracker and updates itself, each with
the detection that the formation's template matches to it, so that members closer to each
other than their gates never swap and clutter near them is not taken for them. Each scan (one
sensor's batch; several sensors' batches come one after another, each with its own noise):

1. **Prediction.** Every member's IMM (the modes of ``motion``, the constant-velocity mode
   with the formation's own noise, sojourn time and turn-rate reset) is predicted to the
   scan's time.
2. **Pre-association** (section III.A). The detections near a formation are split into groups
   by a distance threshold (the formation's largest member spacing); a group whose centre
   ``z̄`` passes the centre gate ``(z̄ − c̄)ᵀ S̄⁻¹ (z̄ − c̄) ≤ γ`` (eq. 4; ``c̄`` the members' mean
   predicted position, ``S̄ = P̄ + R̄/n + r² I`` its covariance, the noise of the group's mean
   and the formation's radius ``r``, since the centre of a group of some of its members lies
   anywhere within it) is the formation's; a group that fails sheds its detection farthest
   from ``c̄`` and is tried again; a group that passes several formations' gates goes to the
   nearest.
3. **Template matching** (section III.B, :mod:`trackers.formation.template`), in the
   formation's own frame (x along its heading): the template is the members' predicted
   positions; the grid's cells follow eq. 7; the placement with the most matched members and
   the least cost wins. When it leaves members unmatched, the template is also tried turned
   and scaled about its centre (a formation that turns or opens up faster than its members'
   predictions follow), and the better match kept.
4. **Update** (section III.C). Each matched member's IMM is updated with its detection when it
   lies inside the member's gate; the members share one mode probability, the product of
   their modes' likelihoods with the shared prediction, less a member whose likelihoods
   disagree with the others' (:func:`_shared_modes`). A member missed while the others
   were seen looks once more, as a manoeuvring lone track, among the detections no member's
   gate holds; one found so flies off on its own: it is updated with that detection and
   handed back (:func:`_departures`). A member's
   score gains ``ln(P_D Λ / λ)``, a missed member's ``ln(1 − P_D)``. The formation claims
   its matched detections and every other detection in a member's gate, so none of them
   starts an individual track.
5. **Life cycle.** Groups of confirmed individual tracks that move together (the rules of
   :class:`~trackers.config.FormationConfig`) for several scans become formations, their
   tracks taken over under their ids; a formation can also be asked for by track ids
   (:meth:`FormationTracker.request`), taken at the next scan. A confirmed track that moves
   with a formation as long joins it (a member confirmed after the others). A member that
   leaves or goes undetected too long is handed back to the point tracker; a formation of
   fewer than two members ends, its last member handed back.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from trackers.association.gating import inverse_2x2, max_eigenvalue_2x2
from trackers.association.manoeuvre import manoeuvre_search
from trackers.association.spatial import pairs_within
from trackers.config import FormationConfig, MotionConfig, TrackerConfig
from trackers.coverage import Coverage
from trackers.extended.partition import component_labels
from trackers.filters.imm import (
    MU_FLOOR,
    imm_combine,
    imm_predict,
    imm_update,
    transition_matrix,
)
from trackers.formation.state import FormationCheckpoint, read_state
from trackers.formation.template import cell_sizes, match_template
from trackers.models.motion import ConstantVelocity, CoordinatedTurn, build_models
from trackers.peers import PeerProposal, PointTrackState, PointTrackView, SavesImmutableState
from trackers.types import Scan, TrackSnapshot

__all__ = ["KIND", "Formation", "FormationTracker", "formation_snapshots"]

KIND = "formation"

#: Turns (rad) and scales tried about the template's centre when the template as predicted
#: leaves members unmatched: a formation turning or opening up faster than predicted.
_TURNS = (0.05, -0.05, 0.1, -0.1, 0.2, -0.2)
_SCALES = (0.9, 1.1)

#: A member whose modes' log-likelihood ratios differ by more than this from the other
#: members' median keeps its own mode probabilities (:func:`_shared_modes`): ln 20.
MODE_OUTLIER = math.log(20.0)

#: How far beyond a formation's outermost member its detections are first looked for (m);
#: the members' gates then decide.
COARSE_REACH = 5000.0

_H = np.zeros((2, 5))
_H[0, 0] = _H[1, 1] = 1.0


@dataclass(frozen=True, eq=False)
class Formation:
    """One formation: its members' ids and IMM states (``x (N, M, 5)``, ``P (N, M, 5, 5)``,
    ``mu (N, M)``) at ``time``, their scores, hits, first and latest detection times,
    ``leaving`` (since when each has looked like leaving, NaN if not) and latest detection ids;
    ``started`` when the formation began, ``updated`` its latest detection and ``hits`` the
    scans that updated it."""

    id: str
    members: tuple[str, ...]
    time: float
    x: np.ndarray
    P: np.ndarray
    mu: np.ndarray
    score: np.ndarray
    hits: np.ndarray
    created: np.ndarray
    updated: np.ndarray
    leaving: np.ndarray
    detection_ids: tuple[tuple[str, ...], ...]
    #: Members found flying off on their own this scan (:func:`_departures`), handed back.
    departed: np.ndarray
    started: float
    last_update: float
    scans: int = 0

    def __len__(self) -> int:
        return len(self.members)

    def combined(self) -> tuple[np.ndarray, np.ndarray]:
        """Each member's moment-matched estimate: ``x (N, 5)``, ``P (N, 5, 5)`` (computed once
        per formation state)."""
        cached = self.__dict__.get("_combined")
        if cached is None:
            cached = imm_combine(self.x, self.P, self.mu)
            object.__setattr__(self, "_combined", cached)
        return cached

    def with_members(self, new: Formation) -> Formation:
        """The formation with ``new``'s members after its own (their states, scores, ...)."""
        return replace(
            self,
            members=self.members + new.members,
            x=np.concatenate([self.x, new.x]),
            P=np.concatenate([self.P, new.P]),
            mu=np.concatenate([self.mu, new.mu]),
            score=np.concatenate([self.score, new.score]),
            hits=np.concatenate([self.hits, new.hits]),
            created=np.concatenate([self.created, new.created]),
            updated=np.concatenate([self.updated, new.updated]),
            leaving=np.concatenate([self.leaving, new.leaving]),
            detection_ids=self.detection_ids + new.detection_ids,
            departed=np.concatenate([self.departed, new.departed]),
        )

    def take(self, keep: np.ndarray) -> Formation:
        """The formation with only the members where ``keep`` is true."""
        idx = np.flatnonzero(keep)
        return replace(
            self,
            members=tuple(self.members[i] for i in idx.tolist()),
            x=np.take(self.x, idx, axis=0),
            P=np.take(self.P, idx, axis=0),
            mu=np.take(self.mu, idx, axis=0),
            score=self.score[idx],
            hits=self.hits[idx],
            created=self.created[idx],
            updated=self.updated[idx],
            leaving=self.leaving[idx],
            detection_ids=tuple(self.detection_ids[i] for i in idx.tolist()),
            departed=self.departed[idx],
        )


@dataclass(frozen=True)
class _Request:
    """A formation asked for by track ids, formed at the next scan."""

    id: str
    members: tuple[str, ...]


@dataclass(frozen=True)
class _State:
    config: TrackerConfig
    formations: tuple[Formation, ...] = ()
    #: Groups of tracks seen moving together: sorted member ids → (first time, scans).
    groups: dict[tuple[str, ...], tuple[float, int]] = field(default_factory=dict)
    #: Tracks seen moving with a formation: (formation id, track id) → (first time, scans).
    joining: dict[tuple[str, str], tuple[float, int]] = field(default_factory=dict)
    requests: tuple[_Request, ...] = ()
    next_id: int = 1
    time: float | None = None


def _member_sojourn_times(config: TrackerConfig) -> tuple[float, ...]:
    """``motion.sojourn_times`` with the constant-velocity mode's ``formation.cv_sojourn_time``."""
    return _sojourn_times_of(config.motion, config.formation)


def _sojourn_times_of(motion: MotionConfig, formation: FormationConfig) -> tuple[float, ...]:
    return tuple(
        formation.cv_sojourn_time if name == "cv" else tau
        for name, tau in zip(motion.models, motion.sojourn_times, strict=True)
    )


def member_motion(config: TrackerConfig) -> MotionConfig:
    """The members' IMM: the modes of ``motion``, the constant-velocity mode with the
    formation's ``q_cv``, ``cv_sojourn_time`` and ``cv_turn_rate_std``, and no agile turns."""
    return _member_motion_of(config.motion, config.formation)


def _member_motion_of(motion: MotionConfig, formation: FormationConfig) -> MotionConfig:
    return replace(
        motion,
        q_cv=formation.q_cv,
        sojourn_times=_sojourn_times_of(motion, formation),
        cv_turn_rate_std=formation.cv_turn_rate_std,
        agile_acceleration=0.0,  # a formation flies steadily: no agile turns
    )


def _models(config: TrackerConfig) -> tuple[ConstantVelocity | CoordinatedTurn, ...]:
    """The members' modes (:func:`member_motion`), built once per configuration."""
    return _models_of(config.motion, config.formation)


@lru_cache(maxsize=8)
def _models_of(
    motion: MotionConfig, formation: FormationConfig
) -> tuple[ConstantVelocity | CoordinatedTurn, ...]:
    return build_models(_member_motion_of(motion, formation))


def _new_formation(
    fid: str, rows: Sequence[int], view: PointTrackView, config: TrackerConfig
) -> Formation:
    """A formation of the view's tracks ``rows``, every mode started from the track's state."""
    idx = np.asarray(rows, dtype=np.intp)
    M = len(config.motion.models)
    x = np.take(view.x, idx, axis=0)
    P = np.take(view.P, idx, axis=0)
    n = idx.size
    return Formation(
        id=fid,
        members=tuple(view.ids[i] for i in idx.tolist()),
        time=view.time,
        x=np.repeat(x[:, None], M, axis=1),
        P=np.repeat(P[:, None], M, axis=1),
        mu=np.tile(np.asarray(config.motion.initial_mode_probabilities, dtype=float), (n, 1)),
        score=view.score[idx].copy(),
        hits=view.hits[idx].copy(),
        created=view.created[idx].copy(),
        updated=view.updated[idx].copy(),
        leaving=np.full(n, np.nan),
        detection_ids=((),) * n,
        departed=np.zeros(n, dtype=bool),
        started=view.time,
        last_update=float(view.updated[idx].max()),
    )


def _joined(f: Formation, rows: Sequence[int], view: PointTrackView, config: TrackerConfig):
    """``f`` with the view's tracks ``rows`` as new members, started as in
    :func:`_new_formation`."""
    return f.with_members(_new_formation(f.id, rows, view, config))


def _joining(
    view: PointTrackView,
    formations: Sequence[Formation],
    config: TrackerConfig,
    counts: dict[tuple[str, str], tuple[float, int]],
    t: float,
    exclude: set[str],
) -> tuple[dict[tuple[str, str], tuple[float, int]], dict[int, list[int]]]:
    """Confirmed individual tracks moving with a formation: at least ``min_speed`` fast,
    within ``max_spacing`` of one of its members and ``max_velocity_difference`` of that
    member's velocity, no closer than the resolution distance to any member if the formation
    is slow enough to be an extended object (:func:`_extended_reach`), and within
    ``max_spacing`` of no other formation's member; counted across scans by (formation id,
    track id). A member confirmed after its formation formed (or one handed back that
    rejoins) so becomes a member after ``confirm_scans`` scans spanning ``confirm_time``.
    Returns the new counts and, by formation index, the view rows ripe to join it."""
    cfg = config.formation
    if not formations or len(view) == 0:
        return {}, {}
    speed = np.hypot(view.x[:, 2], view.x[:, 3])
    ok = view.confirmed & (speed >= cfg.min_speed)
    if exclude:
        ok &= np.array([tid not in exclude for tid in view.ids])
    rows = np.flatnonzero(ok)
    if rows.size == 0:
        return {}, {}
    p = np.take(view.x[:, :2], rows, axis=0)
    v = np.take(view.x[:, 2:4], rows, axis=0)
    reach = _extended_reach(config)
    near = np.zeros(rows.size, dtype=np.int64)
    moving_with: list[tuple[int, int]] = []
    for fi, f in enumerate(formations):
        x, _ = f.combined()
        slow = float(np.mean(np.hypot(x[:, 2], x[:, 3]))) <= reach
        d_res = config.extended.resolution_distance if slow else 0.0
        d = np.hypot(p[:, None, 0] - x[None, :, 0], p[:, None, 1] - x[None, :, 1])
        nearest = np.argmin(d, axis=1)
        d_min = d[np.arange(rows.size), nearest]
        dv = np.hypot(*(v - x[nearest, 2:4]).T)
        near += d_min <= cfg.max_spacing
        with_f = (d_min <= cfg.max_spacing) & (d_min >= d_res) & (dv <= cfg.max_velocity_difference)
        moving_with.extend((fi, j) for j in np.flatnonzero(with_f).tolist())
    out: dict[tuple[str, str], tuple[float, int]] = {}
    ripe: dict[int, list[int]] = {}
    for fi, j in moving_with:
        if near[j] > 1:
            continue  # near two formations: neither's until it is clear
        row = int(rows[j])
        key = (formations[fi].id, view.ids[row])
        first, n = counts.get(key, (t, 0))
        n += 1
        if n >= cfg.confirm_scans and t - first >= cfg.confirm_time:
            ripe.setdefault(fi, []).append(row)
        else:
            out[key] = (first, n)
    return out, ripe


class FormationTracker(SavesImmutableState):
    """Formation tracks (paper 003); a peer of the point tracker
    (:class:`trackers.peers.PeerTracker`). See the module docstring for the step."""

    kind = KIND
    _checkpoint_type = FormationCheckpoint
    _kept_on_reset = ("config", "next_id")
    _read_state = staticmethod(read_state)

    def __init__(self, config: TrackerConfig | None = None, *, id_prefix: str = "") -> None:
        """``id_prefix`` goes before every new formation's id (``{id_prefix}F2``)."""
        self.id_prefix = id_prefix
        self._state = _State(config=config or TrackerConfig())

    @property
    def formations(self) -> tuple[Formation, ...]:
        return self._state.formations

    def reconfigure(self, config: TrackerConfig) -> None:
        st = self._state
        formations = st.formations
        if len(config.motion.models) != len(st.config.motion.models):
            formations = tuple(_remoded(f, config) for f in formations)
        self._state = replace(st, config=config, formations=formations)

    def commit(self, proposal: PeerProposal) -> None:
        if isinstance(proposal.state, _State):
            self._state = proposal.state

    def snapshot(self) -> tuple[TrackSnapshot, ...]:
        st = self._state
        names = st.config.motion.models
        return tuple(s for f in st.formations for s in formation_snapshots(f, names))

    def members(self) -> dict[str, str]:
        """Member track id → its formation's id, for every formation and request."""
        out = {m: f.id for f in self._state.formations for m in f.members}
        out.update({m: r.id for r in self._state.requests for m in r.members})
        return out

    def request(self, member_ids: Sequence[str], view: PointTrackView) -> TrackSnapshot:
        """Ask for a formation of the point tracks ``member_ids`` (live in ``view``, the point
        tracks as they are now): it is formed at the next scan from those still live then.
        Returns the formation's track as of now; raises ``ValueError`` naming the problem (an
        unknown id, a tentative track, one already in a formation, fewer than two, one twice,
        members not linked by steps of at most ``max_spacing``) and changes nothing then."""
        st = self._state
        if not st.config.formation.enabled:
            raise ValueError("formation tracking is switched off (formation.enabled)")
        ids = [str(i) for i in member_ids]
        if len(ids) < 2:
            raise ValueError(f"members: at least 2 track ids, got {len(ids)}")
        if len(set(ids)) != len(ids):
            raise ValueError("members: a track id is named twice")
        taken = self.members()
        index = view.index()
        for tid in ids:
            if tid in taken:
                raise ValueError(f"members: track {tid!r} is already in formation {taken[tid]!r}")
            if tid not in index:
                raise ValueError(f"members: no live individual track {tid!r}")
            if not view.confirmed[index[tid]]:
                raise ValueError(f"members: track {tid!r} is tentative, not confirmed")
        p = np.take(view.x[:, :2], [index[tid] for tid in ids], axis=0)
        spacing = st.config.formation.max_spacing
        a, b = pairs_within(p, np.full(len(ids), spacing), p)
        labels = component_labels(len(ids), a, b)
        if (labels != labels[0]).any():
            d = _distances(p)[labels == labels[0]][:, labels != labels[0]]
            i, j = np.unravel_index(int(np.argmin(d)), d.shape)
            near, far = (
                np.flatnonzero(labels == labels[0])[i],
                np.flatnonzero(labels != labels[0])[j],
            )
            raise ValueError(
                f"members: tracks {ids[near]!r} and {ids[far]!r} are {d[i, j]:.0f} m apart and "
                f"no chain of members closer than formation.max_spacing ({spacing:g} m) "
                "links them"
            )
        fid = f"{self.id_prefix}F{st.next_id}"
        rows = [index[tid] for tid in ids]
        snap = formation_snapshots(
            _new_formation(fid, rows, view, st.config), st.config.motion.models
        )[0]
        self._state = replace(
            st, requests=(*st.requests, _Request(fid, tuple(ids))), next_id=st.next_id + 1
        )
        return snap

    # -- the step ----------------------------------------------------------------------------

    def propose(self, scan: Scan, view: PointTrackView) -> PeerProposal:
        st = self._state
        config = st.config
        cfg = config.formation
        t = float(scan.time)
        claimed = np.zeros(scan.size, dtype=bool)
        if not cfg.enabled:
            if not st.formations and not st.requests:
                return PeerProposal(
                    claimed=claimed, state=replace(st, time=t, groups={}, joining={})
                )
            # Handed back at the scan's time: the members' states predicted to it first.
            formations = _predicted(st.formations, _models(config), config, t)
            handed = tuple(_handed(f, np.arange(len(f)), t) for f in formations)
            return PeerProposal(
                claimed=claimed,
                hand_back=tuple(s for group in handed for s in group),
                deleted=tuple(f.id for f in st.formations),
                state=replace(st, formations=(), requests=(), groups={}, joining={}, time=t),
            )
        models = _models(config)
        formations = _predicted(st.formations, models, config, t)
        # New formations: requested ones, then groups that have moved together long enough.
        index = view.index()
        taken: list[str] = []
        next_id = st.next_id
        for req in st.requests:
            live = [m for m in req.members if m in index]
            if len(live) >= 2:
                formations.append(_new_formation(req.id, [index[m] for m in live], view, config))
                taken.extend(live)
        joining, joins = _joining(view, formations, config, st.joining, t, exclude=set(taken))
        for fi, rows in joins.items():
            formations[fi] = _joined(formations[fi], rows, view, config)
            taken.extend(view.ids[i] for i in rows)
        groups, ripe = _moving_together(view, config, st.groups, t, exclude=set(taken))
        for rows in ripe:
            formations.append(_new_formation(f"{self.id_prefix}F{next_id}", rows, view, config))
            taken.extend(view.ids[i] for i in rows)
            next_id += 1
        # Matching and update.
        pd = config.track_management.pd if scan.pd is None else float(scan.pd)
        lam = (
            config.track_management.clutter_density
            if scan.clutter_density is None
            else float(scan.clutter_density)
        )
        formations, claimed = _update(formations, scan, config, pd, lam, set(taken))
        # Members leaving, lost, and formations ending.
        kept: list[Formation] = []
        hand_back: list[PointTrackState] = []
        deleted: list[str] = []
        for f in formations:
            f, out = _leaving(f, cfg, t)
            if len(f) - int(out.sum()) < 2:
                out[:] = True
            if out.any():
                hand_back.extend(_handed(f, np.flatnonzero(out), t))
            if out.all():
                deleted.append(f.id)
            else:
                kept.append(f.take(~out) if out.any() else f)
        # A member taken and handed back at once stays with the point tracker.
        handed_ids = {s.id for s in hand_back}
        take = tuple(m for m in taken if m not in handed_ids)
        taken_ids = set(taken)
        hand_back = [s for s in hand_back if s.id not in taken_ids]
        new_state = replace(
            st,
            formations=tuple(kept),
            groups=groups,
            joining=joining,
            requests=(),
            next_id=next_id,
            time=t,
        )
        names = config.motion.models
        return PeerProposal(
            claimed=claimed,
            take=take,
            hand_back=tuple(hand_back),
            tracks=tuple(s for f in kept for s in formation_snapshots(f, names)),
            deleted=tuple(deleted),
            state=new_state,
        )


# -- prediction and update ----------------------------------------------------------------------


def _predicted(
    formations: Sequence[Formation],
    models: Sequence[ConstantVelocity | CoordinatedTurn],
    config: TrackerConfig,
    t: float,
) -> list[Formation]:
    """Every formation's members predicted to ``t``: one IMM call for all the formations of
    one time (all of them, but for those started by hand since)."""
    out = list(formations)
    by_time: dict[float, list[int]] = {}
    for i, f in enumerate(formations):
        if f.time < t:
            by_time.setdefault(f.time, []).append(i)
    for t0, group in by_time.items():
        dt = t - t0
        x = np.concatenate([formations[i].x for i in group])
        P = np.concatenate([formations[i].P for i in group])
        mu = np.concatenate([formations[i].mu for i in group])
        Pi = transition_matrix(_member_sojourn_times(config), dt)
        xp, Pp, cbar = imm_predict(models, x, P, mu, Pi, dt)
        start = 0
        for i in group:
            sl = slice(start, start + len(formations[i]))
            out[i] = replace(formations[i], x=xp[sl], P=Pp[sl], mu=cbar[sl], time=t)
            start = sl.stop
    return out


def _rotation(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def _match_one(
    zhat: np.ndarray, S_pos: np.ndarray, vel: np.ndarray, Z: np.ndarray, R: np.ndarray, gamma: float
) -> np.ndarray:
    """Template matching of one formation's predicted member positions ``zhat (N, 2)`` to its
    pre-associated detections ``Z (K, 2)`` (covariances ``R``), in the formation's frame.
    Returns the detection index of each member (−1: none)."""
    N = zhat.shape[0]
    v = vel.mean(axis=0)
    theta = math.atan2(v[1], v[0]) if math.hypot(v[0], v[1]) > 1.0 else 0.0
    rot = _rotation(theta)  # body → world; world → body is rot.T
    c = zhat.mean(axis=0)
    A = (zhat - c) @ rot  # rows: R(−θ)(ẑ − c)
    B = (Z - c) @ rot
    Rb = np.einsum("ji,kjl,lm->kim", rot, R, rot)  # rotᵀ R rot
    sigma = np.sqrt(np.maximum(Rb[:, [0, 1], [0, 1]].max(axis=0), 1e-6))
    mu = cell_sizes(A, sigma)
    Sc = rot.T @ S_pos.mean(axis=0) @ rot
    max_shift = np.sqrt(gamma * (np.diag(Sc) + sigma**2))
    miss = math.sqrt(gamma * float(np.linalg.eigvalsh(S_pos.mean(axis=0) + R.mean(axis=0))[-1]))
    best = match_template(A, B, mu, max_shift=max_shift, miss_cost=miss)
    if N >= 3 and Z.shape[0] >= 2 and (best is None or best.count < min(N, Z.shape[0])):
        # The turned and scaled templates are tried when fewer members were matched than
        # there are detections within reach of one of them: of a member's prediction, by
        # the miss cost plus the most that turning or scaling moves it (a member's miss,
        # with no detection near it, does not call for them).
        r_max = float(np.sqrt((A * A).sum(axis=1).max()))
        moved = r_max * max(
            2.0 * math.sin(0.5 * max(map(abs, _TURNS))), *(abs(k - 1.0) for k in _SCALES)
        )
        d = np.hypot(zhat[:, None, 0] - Z[None, :, 0], zhat[:, None, 1] - Z[None, :, 1])
        reachable = int((d.min(axis=0) <= miss + moved).sum())
    else:
        reachable = 0
    if reachable >= 2 and (best is None or best.count < min(N, reachable)):
        for s, turn in [(1.0, a) for a in _TURNS] + [(k, 0.0) for k in _SCALES]:
            At = s * (A @ _rotation(turn).T)
            m = match_template(At, B, mu, max_shift=max_shift, miss_cost=miss)
            if m is not None and (best is None or (m.count > best.count and m.cost < best.cost)):
                best = m
    if best is None:
        return np.full(N, -1, dtype=np.int64)
    return best.assignment


def _update(
    formations: list[Formation],
    scan: Scan,
    config: TrackerConfig,
    pd: float,
    lam: float,
    taken: set[str] = frozenset(),  # type: ignore[assignment]
) -> tuple[list[Formation], np.ndarray]:
    """Pre-association, template matching and the members' updates for one scan; the
    detections claimed. Members ``taken`` from the point tracker this scan are not looked
    for as departing (one handed back at once would stay the point tracker's, and the
    detection found for it would be lost)."""
    claimed = np.zeros(scan.size, dtype=bool)
    if scan.coverage is not None and formations:
        seen = _in_view(formations, scan.coverage)
        if not seen.all():  # those out of the sensor's view are not looked at, nor missed
            rows = np.flatnonzero(seen).tolist()
            looked, claimed = _update([formations[i] for i in rows], scan, config, pd, lam, taken)
            out = [_missed(f, 0.0) for f in formations]
            for i, f in zip(rows, looked, strict=True):
                out[i] = f
            return out, claimed
    if not formations or scan.size == 0:
        return [_missed(f, pd) for f in formations], claimed
    cfg = config.formation
    gamma = cfg.gate_threshold
    Z, Rz = scan.z, scan.R
    combined = [f.combined() for f in formations]
    # Pre-association (III.A): for each formation, the detections within reach of its
    # members, split into groups; a group goes to the formation whose centre gate it passes,
    # the nearest when several do.
    centres = np.array([x[:, :2].mean(axis=0) for x, _ in combined])
    radius = np.array(
        [
            float(np.hypot(*(x[:, :2] - c).T).max())
            for (x, _), c in zip(combined, centres, strict=True)
        ]
    )
    fi, k = pairs_within(centres, radius + COARSE_REACH, Z)
    owner = np.full(scan.size, -1, dtype=np.int64)
    best_d2 = np.full(scan.size, np.inf)
    for i in np.unique(fi).tolist():
        rows = k[fi == i]
        x, P = combined[i]
        c = centres[i]
        # Within reach: a member's gate, with the largest noise of the detections about.
        R_near = float(max_eigenvalue_2x2(Rz[rows]).max())
        lam_P = float(max_eigenvalue_2x2(P[:, :2, :2]).max())
        margin = math.sqrt(gamma * (lam_P + R_near))
        rows = rows[np.hypot(*(Z[rows] - c).T) <= radius[i] + margin]
        if rows.size == 0:
            continue
        # The centre of a group of the formation's detections (some members, perhaps a false
        # alarm) lies anywhere within the formation: its radius enters S̄ in every direction.
        Sbar = P[:, :2, :2].mean(axis=0) + radius[i] ** 2 * np.eye(2)
        sub = Z[rows]
        gap = _largest_gap(x[:, :2]) + 3.0 * math.sqrt(R_near)
        a, b = pairs_within(sub, np.full(rows.size, gap), sub)
        labels = component_labels(rows.size, a, b)
        for g in np.unique(labels).tolist():
            group = rows[labels == g]
            # eq. 4 on the group's centre; a group that fails it sheds its detection farthest
            # from the formation's centre (clutter at its edge) and is tried again.
            while group.size:
                zbar = Z[group].mean(axis=0)
                S = Sbar + Rz[group].mean(axis=0) / group.size
                d = zbar - c
                d2 = float(d @ np.linalg.solve(S, d))
                if d2 <= gamma:
                    closer = d2 < best_d2[group]
                    owner[group[closer]] = i
                    best_d2[group[closer]] = d2
                    break
                e = Z[group] - c
                far = np.einsum("ni,ij,nj->n", e, np.linalg.inv(Sbar + Rz[group].mean(axis=0)), e)
                group = np.delete(group, int(np.argmax(far)))
    # Template matching (III.B) per formation; the matched pairs, gated per member.
    rows_all: list[int] = []
    dets_all: list[int] = []
    starts = np.cumsum([0] + [len(f) for f in formations])
    for i in range(len(formations)):
        dets = np.flatnonzero(owner == i)
        if dets.size == 0:
            continue
        x, P = combined[i]
        zhat = x[:, :2]
        S_pos = P[:, :2, :2]
        assign = _match_one(zhat, S_pos, x[:, 2:4], Z[dets], Rz[dets], gamma)
        S_all = S_pos[:, None] + Rz[dets][None]  # (N, K, 2, 2)
        nu = Z[dets][None] - zhat[:, None]
        d2 = np.einsum("nki,nkij,nkj->nk", nu, inverse_2x2(S_all)[0], nu)
        claimed[dets[(d2 <= gamma).any(axis=0)]] = True
        for n, a in enumerate(assign.tolist()):
            if a >= 0 and d2[n, a] <= gamma:
                rows_all.append(int(starts[i]) + n)
                dets_all.append(int(dets[a]))
                claimed[dets[a]] = True
    # Update (III.C): every matched member at once.
    x_all = np.concatenate([f.x for f in formations])
    P_all = np.concatenate([f.P for f in formations])
    mu_all = np.concatenate([f.mu for f in formations])
    c_bar = mu_all.copy()
    score = np.concatenate([f.score for f in formations]) + math.log1p(-min(pd, 1.0 - 1e-12))
    hits = np.concatenate([f.hits for f in formations])
    updated = np.concatenate([f.updated for f in formations])
    det_ids: list[tuple[str, ...]] = [()] * len(x_all)
    hit = np.zeros(len(x_all), dtype=bool)
    if rows_all:
        r = np.asarray(rows_all, dtype=np.intp)
        d = np.asarray(dets_all, dtype=np.intp)
        xu, Pu, muu, ll = imm_update(
            np.take(x_all, r, axis=0),
            np.take(P_all, r, axis=0),
            np.take(mu_all, r, axis=0),
            np.take(Z, d, axis=0),
            np.take(Rz, d, axis=0),
            _H,
        )
        shared = _shared_modes(mu_all, muu, r, starts)
        x_all[r], P_all[r], mu_all[r] = xu, Pu, muu
        for sl, mu_f, own in shared:
            kept = mu_all[own]  # a copy: their own posteriors
            mu_all[sl] = mu_f
            mu_all[own] = kept
        score[r] += math.log(pd) - math.log1p(-min(pd, 1.0 - 1e-12)) + ll - math.log(lam)
        hits[r] += 1
        updated[r] = scan.time
        hit[r] = True
        for row, det in zip(r.tolist(), d.tolist(), strict=True):
            det_ids[row] = (scan.detection_ids[det],) if scan.detection_ids else ()
    departed = np.zeros(len(x_all), dtype=bool)
    seen = np.zeros(len(x_all), dtype=bool)
    for i in range(len(formations)):
        sl = slice(int(starts[i]), int(starts[i + 1]))
        seen[sl] = hit[sl].any()
    if taken:
        seen &= np.array([m not in taken for f in formations for m in f.members], dtype=bool)
    found = _departures(
        np.flatnonzero(seen & ~hit),
        np.flatnonzero(~claimed),
        (x_all, P_all, c_bar, combined, np.concatenate([f.updated for f in formations])),
        scan,
        config,
        pd,
        lam,
    )
    if found is not None:
        rows, dets, fx, fP, fmu, gain = found
        x_all[rows], P_all[rows], mu_all[rows] = fx, fP, fmu
        score[rows] += gain - math.log1p(-min(pd, 1.0 - 1e-12))
        hits[rows] += 1
        updated[rows] = scan.time
        hit[rows] = departed[rows] = True
        claimed[dets] = True
        for row, det in zip(rows.tolist(), dets.tolist(), strict=True):
            det_ids[row] = (scan.detection_ids[det],) if scan.detection_ids else ()
    out: list[Formation] = []
    for i, f in enumerate(formations):
        sl = slice(int(starts[i]), int(starts[i + 1]))
        any_hit = bool(hit[sl].any())
        out.append(
            replace(
                f,
                departed=departed[sl],
                x=x_all[sl],
                P=P_all[sl],
                mu=mu_all[sl],
                score=score[sl],
                hits=hits[sl],
                updated=updated[sl],
                detection_ids=tuple(det_ids[sl]),
                last_update=scan.time if any_hit else f.last_update,
                scans=f.scans + int(any_hit),
            )
        )
    return out, claimed


def _departures(
    missed: np.ndarray,
    free: np.ndarray,
    members: tuple[np.ndarray, np.ndarray, np.ndarray, list, np.ndarray],
    scan: Scan,
    config: TrackerConfig,
    pd: float,
    lam: float,
) -> tuple[np.ndarray, ...] | None:
    """Members flying off on their own. A member ``missed`` (rows of the formations' stacked
    members) at a scan in which its formation was seen may have turned away, out of its gate
    and of the formation's motion: it looks once more, as a lone confirmed track does, among
    the ``free`` detections (those in no member's gate), under the hypothesis that it
    manoeuvred since its last update (:func:`~trackers.association.manoeuvre.manoeuvre_search`
    with the individual tracker's gate and straight-flight sojourn time). ``members``: every
    member's predicted mode states ``x``, ``P`` and probabilities ``c̄``, the formations'
    combined estimates and the members' last detection times. Returns the rows that found
    their detection, those detections (scan rows), the rows' IMM posteriors ``x``, ``P``,
    ``μ`` and score increments, or ``None``; such a member is then handed back."""
    if missed.size == 0 or free.size == 0:
        return None
    x, P, c_bar, combined, updated = members
    gating = config.gating
    xc = np.concatenate([c[0] for c in combined])
    Pc = np.concatenate([c[1] for c in combined])
    found = manoeuvre_search(
        x[missed],
        P[missed],
        c_bar[missed],
        xc[missed],
        Pc[missed],
        scan.time - updated[missed],
        scan.z[free],
        scan.R[free],
        np.full(missed.size, pd),
        lam,
        a_max=gating.manoeuvre_acceleration,
        omega_max=gating.manoeuvre_turn_rate,
        straight_sojourn=config.motion.sojourn_times[0],
        gamma=gating.threshold,
    )
    if found is None:
        return None
    return missed[found.track], free[found.detection], found.x, found.P, found.mu, found.hit


def _shared_modes(
    c_bar: np.ndarray, mu: np.ndarray, rows: np.ndarray, starts: np.ndarray
) -> list[tuple[slice, np.ndarray, np.ndarray]]:
    """One mode probability vector per formation with a member updated: a formation flies as
    one body, so its members are in the same mode, and every member's detection is evidence
    for it. With ``c̄`` the members' predicted mode probabilities (shared, so their mean) and
    ``μ_i ∝ Λ_i c̄_i`` the posterior of updated member ``i`` (``rows``)::

        μ_f ∝ c̄ Π_i Λ_i = c̄ Π_i (μ_i / c̄_i)

    floored at :data:`~trackers.filters.imm.MU_FLOOR`. A member that does not move with the
    others (one turning away from a formation flying straight) would carry them all into its
    mode: with three or more updated, a member whose log-likelihood ratios between the modes,
    ``ln Λ_i(m) − ln Λ_i(0)``, differ from the members' median by more than
    :data:`MODE_OUTLIER` (natural log) for some mode is left out of the product and keeps its
    own ``μ_i``. Returns (the formation's rows, ``μ_f``, the rows of those left out) for each
    formation with an updated member (``starts``: the first row of each)."""
    out: list[tuple[slice, np.ndarray, np.ndarray]] = []
    log_ratio = np.log(np.maximum(mu, MU_FLOOR)) - np.log(np.maximum(c_bar[rows], MU_FLOOR))
    for i in range(len(starts) - 1):
        lo, hi = int(starts[i]), int(starts[i + 1])
        sel = np.flatnonzero((rows >= lo) & (rows < hi))
        if sel.size == 0:
            continue
        own = sel[:0]
        if sel.size >= 3:
            rel = log_ratio[sel] - log_ratio[sel, :1]
            apart = (np.abs(rel - np.median(rel, axis=0)) > MODE_OUTLIER).any(axis=1)
            own, sel = sel[apart], sel[~apart]
        prior = np.maximum(c_bar[lo:hi].mean(axis=0), MU_FLOOR)
        log_mu = np.log(prior) + log_ratio[sel].sum(axis=0)
        w = np.exp(log_mu - log_mu.max())
        w = np.maximum(w / w.sum(), MU_FLOOR)
        out.append((slice(lo, hi), w / w.sum(), rows[own]))
    return out


def _in_view(formations: list[Formation], coverage: Coverage) -> np.ndarray:
    """Whether each formation's members reach into the scan's coverage: its centre within
    the farthest member's distance plus three standard deviations of the least certain one."""
    centres, reach = [], []
    for f in formations:
        x, P = f.combined()
        c = x[:, :2].mean(axis=0)
        sigma = np.sqrt(max_eigenvalue_2x2(P[:, :2, :2]).max())
        centres.append(c)
        reach.append(float(np.hypot(*(x[:, :2] - c).T).max() + 3.0 * sigma))
    return coverage.contains(np.array(centres), np.array(reach))


def _missed(f: Formation, pd: float) -> Formation:
    return replace(
        f,
        score=f.score + math.log1p(-min(pd, 1.0 - 1e-12)),
        detection_ids=((),) * len(f),
        departed=np.zeros(len(f), dtype=bool),
    )


def _distances(p: np.ndarray) -> np.ndarray:
    """``d_ij = ‖p_i − p_j‖`` of the points ``p (n, 2)``, ``(n, n)``."""
    return np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])


def _largest_gap(p: np.ndarray) -> float:
    """The longest edge of the members' minimum spanning tree: the distance threshold that
    keeps all of the formation's detections in one group (pre-association)."""
    n = p.shape[0]
    if n < 2:
        return 0.0
    d = _distances(p)
    # Prim's algorithm on a handful of points.
    inside = np.zeros(n, dtype=bool)
    inside[0] = True
    best = d[0].copy()
    longest = 0.0
    for _ in range(n - 1):
        cand = np.where(inside, np.inf, best)
        j = int(np.argmin(cand))
        longest = max(longest, float(cand[j]))
        inside[j] = True
        best = np.minimum(best, d[j])
    return longest


# -- life cycle ----------------------------------------------------------------------------------


def _leaving(f: Formation, cfg: FormationConfig, t: float) -> tuple[Formation, np.ndarray]:
    """The formation with its members' ``leaving`` times brought up to date, and the mask of
    the members to hand back now: leaving for ``leave_time``, or undetected for
    ``max_coast_time``. A member is leaving when it is farther than ``leave_distance`` from
    every other member, or its velocity parts from the formation's rigid motion (the mean
    velocity plus the mean turn rate times its offset from the centre) by more than
    ``max_velocity_difference`` plus three standard deviations of its own velocity."""
    x, P = f.combined()
    n = len(f)
    p, v = x[:, :2], x[:, 2:4]
    c = p.mean(axis=0)
    r = p - c
    rigid = v.mean(axis=0) + float(x[:, 4].mean()) * np.column_stack([-r[:, 1], r[:, 0]])
    sigma_v = np.sqrt(np.maximum(P[:, 2, 2] + P[:, 3, 3], 0.0))
    apart = np.linalg.norm(v - rigid, axis=1) > cfg.max_velocity_difference + 3.0 * sigma_v
    if n >= 2:
        d = _distances(p)
        np.fill_diagonal(d, np.inf)
        apart |= d.min(axis=1) > cfg.leave_distance
    since = np.where(apart, np.where(np.isnan(f.leaving), t, f.leaving), np.nan)
    out = (apart & (t - since >= cfg.leave_time)) | (t - f.updated > cfg.max_coast_time)
    out |= f.departed
    return replace(f, leaving=since), out


def _handed(f: Formation, rows: np.ndarray, t: float) -> tuple[PointTrackState, ...]:
    """Members ``rows`` as point-track states at ``t`` (their combined estimates)."""
    x, P = f.combined()
    out = []
    for n in np.asarray(rows, dtype=np.intp).tolist():
        Pn = 0.5 * (P[n] + P[n].T)
        out.append(
            PointTrackState(
                id=f.members[n],
                time=t,
                x=x[n],
                P=Pn,
                score=float(f.score[n]),
                hits=int(f.hits[n]),
                confirmed=True,
                created=float(f.created[n]),
                updated=float(f.updated[n]),
            )
        )
    return tuple(out)


def _extended_reach(config: TrackerConfig) -> float:
    """The highest speed of a group the extended tracker may hold (``extended.max_speed``;
    -inf when extended tracking is off): only such groups need their members farther apart
    than the resolution distance to be told from one unresolved object. A faster group is no
    extended object, and its members, separate confirmed tracks, are resolved."""
    return config.extended.max_speed if config.extended.enabled else -math.inf


def _moving_together(
    view: PointTrackView,
    config: TrackerConfig,
    groups: dict[tuple[str, ...], tuple[float, int]],
    t: float,
    exclude: set[str],
) -> tuple[dict[tuple[str, ...], tuple[float, int]], list[list[int]]]:
    """Groups of confirmed tracks moving together now (each within ``max_spacing`` and
    ``max_velocity_difference`` of another, at least ``min_speed`` fast, at least
    ``min_members``, and no two closer than the resolution distance if the group is slow
    enough to be an extended object, :func:`_extended_reach`), counted across scans; returns
    the new counts and the rows of the groups ripe to become formations."""
    cfg = config.formation
    ok = view.confirmed.copy()
    if len(view) == 0 or ok.sum() < cfg.min_members:
        return {}, []
    speed = np.hypot(view.x[:, 2], view.x[:, 3])
    ok &= speed >= cfg.min_speed
    if exclude:
        ok &= np.array([tid not in exclude for tid in view.ids])
    rows = np.flatnonzero(ok)
    if rows.size < cfg.min_members:
        return {}, []
    p = np.take(view.x[:, :2], rows, axis=0)
    v = np.take(view.x[:, 2:4], rows, axis=0)
    a, b = pairs_within(p, np.full(rows.size, cfg.max_spacing), p)
    keep = (a < b) & (np.hypot(*(v[a] - v[b]).T) <= cfg.max_velocity_difference)
    a, b = a[keep], b[keep]
    if a.size == 0:
        return {}, []
    labels = component_labels(rows.size, a, b)
    reach = _extended_reach(config)
    out: dict[tuple[str, ...], tuple[float, int]] = {}
    ripe: list[list[int]] = []
    # Only the groups large enough are looked at (most tracks are alone: one label each).
    for g in np.flatnonzero(np.bincount(labels) >= cfg.min_members).tolist():
        local = np.flatnonzero(labels == g)
        d = _distances(p[local])
        np.fill_diagonal(d, np.inf)
        if (
            float(np.mean(speed.take(rows[local]))) <= reach
            and d.min() < config.extended.resolution_distance
        ):
            continue  # closer than the resolution distance: one unresolved object
        key = tuple(sorted(view.ids[i] for i in rows[local].tolist()))
        first, n = groups.get(key, (t, 0))
        n += 1
        if n >= cfg.confirm_scans and t - first >= cfg.confirm_time:
            ripe.append(rows[local].tolist())
        else:
            out[key] = (first, n)
    return out, ripe


def _remoded(f: Formation, config: TrackerConfig) -> Formation:
    """A formation whose members restart their modes from their combined estimates (the set
    of motion models changed)."""
    x, P = f.combined()
    M = len(config.motion.models)
    n = len(f)
    return replace(
        f,
        x=np.repeat(x[:, None], M, axis=1),
        P=np.repeat(P[:, None], M, axis=1),
        mu=np.tile(np.asarray(config.motion.initial_mode_probabilities, dtype=float), (n, 1)),
    )


# -- snapshots -----------------------------------------------------------------------------------


def formation_snapshots(f: Formation, names: Sequence[str]) -> tuple[TrackSnapshot, ...]:
    """The formation's track (``kind`` formation, ``members``) then its members' tracks
    (``kind`` individual, ``formation_id``)."""
    x, P = f.combined()
    t = f.time
    n = len(f)
    cov = P[:, :4, :4].copy()
    cov.flags.writeable = False
    members = tuple(
        TrackSnapshot(
            id=f.members[i],
            kind="individual",
            status="confirmed",
            time=t,
            position=(float(x[i, 0]), float(x[i, 1])),
            velocity=(float(x[i, 2]), float(x[i, 3])),
            covariance=cov[i],
            score=float(f.score[i]),
            hits=int(f.hits[i]),
            created=float(f.created[i]),
            updated=float(f.updated[i]),
            model_probabilities=dict(zip(names, f.mu[i].tolist(), strict=True)),
            detection_ids=f.detection_ids[i],
            formation_id=f.id,
        )
        for i in range(n)
    )
    C = cov.mean(axis=0) / n
    C.flags.writeable = False
    whole = TrackSnapshot(
        id=f.id,
        kind=KIND,
        status="confirmed",
        time=t,
        position=(float(x[:, 0].mean()), float(x[:, 1].mean())),
        velocity=(float(x[:, 2].mean()), float(x[:, 3].mean())),
        covariance=C,
        score=float(f.score.mean()),
        hits=int(f.scans),
        created=float(f.started),
        updated=float(f.last_update),
        members=f.members,
    )
    return (whole, *members)
