"""The formation tracker's state as plain data (:mod:`trackers.state`), and back.

Every formation with its members' IMM states, scores and life-cycle fields, the groups of
tracks seen moving together and the tracks seen moving with a formation (both counted
across scans), the formations asked for by ids, the id counter and the time. The members
are taken from the point tracker while in a formation, so a restart without this section
would lose them; with it they come back as they were, still members. Member states saved
under other motion models restart their modes from their combined estimates.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from trackers.models.motion import STATE_DIM
from trackers.state import (
    SectionReader,
    StateError,
    StateSection,
    check_id_counter,
    positive_definite,
    put_string_groups,
    put_strings,
)

if TYPE_CHECKING:
    from trackers.formation.tracker import _State

__all__ = ["FormationCheckpoint", "read_state"]


@dataclass(frozen=True, eq=False)
class FormationCheckpoint:
    """A :class:`~trackers.formation.tracker.FormationTracker`'s state at one moment."""

    state: _State

    def export(self) -> StateSection:
        """Plain data: the time, the id counter, the motion models' names, the formations
        (their members end to end) and the counts across scans, as arrays."""
        st = self.state
        fs = st.formations
        M, D = len(st.config.motion.models), STATE_DIM
        arrays: dict[str, np.ndarray] = {}
        put_strings(arrays, "formations.ids", [f.id for f in fs])
        put_string_groups(arrays, "formations.members", [f.members for f in fs])
        for name in ("time", "started", "last_update"):
            arrays[f"formations.{name}"] = np.array([getattr(f, name) for f in fs], dtype=float)
        arrays["formations.scans"] = np.array([f.scans for f in fs], dtype=np.int64)

        def stacked(name: str, shape: tuple[int, ...], dtype: type) -> np.ndarray:
            parts = [np.asarray(getattr(f, name), dtype=dtype) for f in fs]
            return np.concatenate(parts) if parts else np.zeros((0, *shape), dtype=dtype)

        arrays["members.x"] = stacked("x", (M, D), float)
        arrays["members.P"] = stacked("P", (M, D, D), float)
        arrays["members.mu"] = stacked("mu", (M,), float)
        for name in ("score", "created", "updated"):
            arrays[f"members.{name}"] = stacked(name, (), float)
        arrays["members.hits"] = stacked("hits", (), np.int64)
        arrays["members.departed"] = stacked("departed", (), bool)
        leaving = stacked("leaving", (), float)
        arrays["members.is_leaving"] = np.isfinite(leaving)
        arrays["members.leaving"] = np.where(np.isfinite(leaving), leaving, 0.0)
        put_string_groups(arrays, "members.detection_ids", [d for f in fs for d in f.detection_ids])
        groups = sorted(st.groups.items())
        put_string_groups(arrays, "groups.members", [k for k, _ in groups])
        arrays["groups.first"] = np.array([v[0] for _, v in groups], dtype=float)
        arrays["groups.scans"] = np.array([v[1] for _, v in groups], dtype=np.int64)
        joining = sorted(st.joining.items())
        put_strings(arrays, "joining.formation", [k[0] for k, _ in joining])
        put_strings(arrays, "joining.track", [k[1] for k, _ in joining])
        arrays["joining.first"] = np.array([v[0] for _, v in joining], dtype=float)
        arrays["joining.scans"] = np.array([v[1] for _, v in joining], dtype=np.int64)
        put_strings(arrays, "requests.ids", [r.id for r in st.requests])
        put_string_groups(arrays, "requests.members", [r.members for r in st.requests])
        values = {
            "time": st.time,
            "next_id": st.next_id,
            "models": list(st.config.motion.models),
            "n_formations": len(fs),
            "n_members": sum(len(f) for f in fs),
            "n_groups": len(groups),
            "n_joining": len(joining),
            "n_requests": len(st.requests),
        }
        return StateSection(values, arrays)


def read_state(section: StateSection, base: _State, id_prefix: str = "") -> _State:
    """The state a section of :meth:`FormationCheckpoint.export` holds, checked, under the
    configuration of ``base`` (kept as it is); :class:`StateError` naming the field."""
    from trackers.formation.tracker import Formation, _remoded, _Request

    r = SectionReader(section, "peer/formation")
    t = r.time("time")
    next_id = r.integer("next_id", ge=1)
    saved_models = r.names("models")
    nf = r.integer("n_formations", ge=0)
    n = r.integer("n_members", ge=0)
    ng = r.integer("n_groups", ge=0)
    nj = r.integer("n_joining", ge=0)
    nr = r.integer("n_requests", ge=0)
    M, D = len(saved_models), STATE_DIM
    fids = [s or "" for s in r.strings("formations.ids", nf)]
    members = r.string_groups("formations.members", nf)
    f_time = r.floats("formations.time", (nf,))
    f_started = r.floats("formations.started", (nf,))
    f_last = r.floats("formations.last_update", (nf,))
    f_scans = r.integers("formations.scans", (nf,), ge=0)
    x = r.floats("members.x", (n, M, D))
    P = r.floats("members.P", (n, M, D, D))
    mu = r.floats("members.mu", (n, M))
    score = r.floats("members.score", (n,))
    created = r.floats("members.created", (n,))
    updated = r.floats("members.updated", (n,))
    hits = r.integers("members.hits", (n,), ge=0)
    departed = r.booleans("members.departed", (n,))
    is_leaving = r.booleans("members.is_leaving", (n,))
    leaving = np.where(is_leaving, r.floats("members.leaving", (n,)), np.nan)
    det_ids = r.string_groups("members.detection_ids", n)
    g_members = r.string_groups("groups.members", ng)
    g_first = r.floats("groups.first", (ng,))
    g_scans = r.integers("groups.scans", (ng,), ge=1)
    j_formation = [s or "" for s in r.strings("joining.formation", nj)]
    j_track = [s or "" for s in r.strings("joining.track", nj)]
    j_first = r.floats("joining.first", (nj,))
    j_scans = r.integers("joining.scans", (nj,), ge=1)
    req_ids = [s or "" for s in r.strings("requests.ids", nr)]
    req_members = r.string_groups("requests.members", nr)
    r.finish()

    def bad(detail: str) -> StateError:
        return StateError(f"peer/formation: {detail}")

    if sum(len(m) for m in members) != n:
        raise bad(f"the formations' members add up to {sum(len(m) for m in members)}, not {n}")
    if len(set(fids)) != nf or not all(fids) or any(len(m) < 2 for m in members):
        raise bad("formation ids must be unique, each with at least 2 members")
    everyone = [m for ms in members for m in ms]
    if len(set(everyone)) != n or not all(everyone):
        raise bad("a member is in two formations, or twice in one")
    if len(set(req_ids) | set(fids)) != nr + nf or any(len(m) < 2 for m in req_members):
        raise bad("requests must have ids of their own and at least 2 members each")
    check_id_counter(fids + req_ids, next_id, id_prefix, "F", "peer/formation")
    if (nf or ng or nj) and t is None:
        raise bad("formations or counts without the time of the last scan")
    if n:
        assert t is not None
        if (created > updated).any() or (updated > t).any() or (f_time > t).any():
            raise bad("member times must satisfy created <= updated <= time")
        if (mu < 0).any() or (mu > 1).any() or (np.abs(mu.sum(axis=1) - 1.0) > 1e-6).any():
            raise bad("mode probabilities must be in [0, 1] and sum to 1")
        if not positive_definite(P):
            raise bad("a member covariance is not symmetric positive definite")
    config = base.config
    formations: list[Formation] = []
    start = 0
    for i in range(nf):
        sl = slice(start, start + len(members[i]))
        start = sl.stop
        f = Formation(
            id=fids[i],
            members=members[i],
            time=float(f_time[i]),
            x=x[sl].copy(),
            P=P[sl].copy(),
            mu=mu[sl].copy(),
            score=score[sl].copy(),
            hits=hits[sl].copy(),
            created=created[sl].copy(),
            updated=updated[sl].copy(),
            leaving=leaving[sl].copy(),
            detection_ids=tuple(det_ids[sl]),
            departed=departed[sl].copy(),
            started=float(f_started[i]),
            last_update=float(f_last[i]),
            scans=int(f_scans[i]),
        )
        formations.append(f if saved_models == config.motion.models else _remoded(f, config))
    return replace(
        base,
        formations=tuple(formations),
        groups={
            g: (float(first), int(k))
            for g, first, k in zip(g_members, g_first.tolist(), g_scans.tolist(), strict=True)
        },
        joining={
            (fi, ti): (float(first), int(k))
            for fi, ti, first, k in zip(
                j_formation, j_track, j_first.tolist(), j_scans.tolist(), strict=True
            )
        },
        requests=tuple(_Request(i, m) for i, m in zip(req_ids, req_members, strict=True)),
        next_id=next_id,
        time=t,
    )
