"""The extended tracker's state as plain data (:mod:`trackers.state`), and back.

Every track's random-matrix estimate (centroid ``x``, ``P``, extent ``X``, ``α``), its score,
life-cycle counters and split and shed evidence, the clusters seen but not yet born
(their centroid lines), the individual tracks being absorbed, the id counter and the time.
Ids and detection ids are packed UTF-8 strings; an infinite cluster origin (a track started
by hand) is kept as a flag beside a finite number, since saved arrays hold finite numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from trackers.extended.random_matrix import ExtendedEstimate
from trackers.state import (
    SectionReader,
    StateError,
    StateSection,
    check_tracks,
    positive_definite,
    put_string_groups,
    put_strings,
)

if TYPE_CHECKING:
    from trackers.extended.tracker import _State

__all__ = ["ExtendedCheckpoint", "read_state"]


@dataclass(frozen=True, eq=False)
class ExtendedCheckpoint:
    """An :class:`~trackers.extended.tracker.ExtendedTracker`'s state at one moment."""

    state: _State

    def export(self) -> StateSection:
        """Plain data: the time, the id counter, and every field of the tracks, the clusters
        not yet born and the tracks being absorbed, as arrays."""
        st = self.state
        tracks, cands = st.tracks, st.candidates
        n = len(tracks)
        arrays: dict[str, np.ndarray] = {}
        put_strings(arrays, "tracks.ids", [t.id for t in tracks])
        put_string_groups(arrays, "tracks.detection_ids", [t.detection_ids for t in tracks])
        put_string_groups(arrays, "tracks.visitors", [tuple(sorted(t.visitors)) for t in tracks])
        arrays["tracks.x"] = np.array([t.estimate.x for t in tracks]).reshape(n, 4)
        arrays["tracks.P"] = np.array([t.estimate.P for t in tracks]).reshape(n, 4, 4)
        arrays["tracks.X"] = np.array([t.estimate.X for t in tracks]).reshape(n, 2, 2)
        for name in _TRACK_FLOATS:
            arrays[f"tracks.{name}"] = np.array([getattr(t, name) for t in tracks], dtype=float)
        for name in _TRACK_INTS:
            arrays[f"tracks.{name}"] = np.array([getattr(t, name) for t in tracks], dtype=np.int64)
        arrays["tracks.alpha"] = np.array([t.estimate.alpha for t in tracks], dtype=float)
        arrays["tracks.confirmed"] = np.array([t.confirmed for t in tracks], dtype=bool)
        for name in ("split_centroid", "shed_centroid"):
            arrays[f"tracks.{name}"] = np.array(
                [getattr(t, name) for t in tracks], dtype=float
            ).reshape(n, 2)
        origin = np.array([t.origin for t in tracks], dtype=float)
        arrays["tracks.has_origin"] = np.isfinite(origin)
        arrays["tracks.origin"] = np.where(np.isfinite(origin), origin, 0.0)
        k = len(cands)
        arrays["candidates.centroid"] = np.array([c.centroid for c in cands], float).reshape(k, 2)
        arrays["candidates.first_time"] = np.array([c.first_time for c in cands], dtype=float)
        arrays["candidates.time"] = np.array([c.time for c in cands], dtype=float)
        arrays["candidates.seen"] = np.array([c.seen for c in cands], dtype=np.int64)
        arrays["candidates.sums"] = np.array([c.sums for c in cands], dtype=float).reshape(k, 7)
        put_strings(arrays, "candidates.sensors", [c.sensor for c in cands])
        arrays["candidates.missed"] = np.array([c.missed for c in cands], dtype=np.int64)
        put_strings(arrays, "absorbing.ids", [tid for tid, _ in st.absorbing])
        put_strings(arrays, "noise.sensors", [e[0] for e in st.noise])
        arrays["noise.sigma"] = np.array([e[1] for e in st.noise], dtype=float)
        arrays["noise.time"] = np.array([e[2] for e in st.noise], dtype=float)
        arrays["absorbing.scans"] = np.array([s for _, s in st.absorbing], dtype=np.int64)
        values = {
            "time": st.time,
            "next_id": st.next_id,
            "n_tracks": n,
            "n_candidates": k,
            "n_absorbing": len(st.absorbing),
        }
        return StateSection(values, arrays)


#: Float fields of a track, one number each.
_TRACK_FLOATS = (
    "time",
    "score",
    "peak",
    "created",
    "updated",
    "gamma",
    "split_gap",
    "split_time",
    "shed_gap",
    "shed_time",
)
#: Integer fields of a track.
_TRACK_INTS = ("hits", "split_evidence", "shed_evidence")


def read_state(section: StateSection, base: _State, id_prefix: str = "") -> _State:
    """The state a section of :meth:`ExtendedCheckpoint.export` holds, checked, under the
    configuration of ``base`` (kept as it is); :class:`StateError` naming the field."""
    from trackers.extended.tracker import RUN_MISSES, ExtendedTrack, _Candidate

    r = SectionReader(section, "peer/extended")
    t = r.time("time")
    next_id = r.integer("next_id", ge=1)
    n = r.integer("n_tracks", ge=0)
    k = r.integer("n_candidates", ge=0)
    a = r.integer("n_absorbing", ge=0)
    ids = [s or "" for s in r.strings("tracks.ids", n)]
    det_ids = r.string_groups("tracks.detection_ids", n)
    visitors = r.string_groups("tracks.visitors", n)
    x = r.floats("tracks.x", (n, 4))
    P = r.floats("tracks.P", (n, 4, 4))
    X = r.floats("tracks.X", (n, 2, 2))
    alpha = r.floats("tracks.alpha", (n,))
    floats = {name: r.floats(f"tracks.{name}", (n,)) for name in _TRACK_FLOATS}
    ints = {name: r.integers(f"tracks.{name}", (n,), ge=0) for name in _TRACK_INTS}
    confirmed = r.booleans("tracks.confirmed", (n,))
    split_c = r.floats("tracks.split_centroid", (n, 2))
    shed_c = r.floats("tracks.shed_centroid", (n, 2))
    has_origin = r.booleans("tracks.has_origin", (n,))
    origin = r.floats("tracks.origin", (n,))
    c_centroid = r.floats("candidates.centroid", (k, 2))
    c_first = r.floats("candidates.first_time", (k,))
    c_time = r.floats("candidates.time", (k,))
    c_seen = r.integers("candidates.seen", (k,), ge=1)
    c_sums = r.floats("candidates.sums", (k, 7))
    # files written before runs knew their sensor: any sensor's miss ends them
    c_sensors = [""] * k
    if r.has("candidates.sensors.len"):
        c_sensors = [s or "" for s in r.strings("candidates.sensors", k)]
    # files written before runs could miss a scan: none missed
    c_missed = (
        r.integers("candidates.missed", (k,), ge=0).tolist()
        if r.has("candidates.missed")
        else [0] * k
    )
    absorbing_ids = [s or "" for s in r.strings("absorbing.ids", a)]
    absorbing_scans = r.integers("absorbing.scans", (a,), ge=0)
    noise: tuple[tuple[str, float, float], ...] = ()
    if r.has("noise.sigma"):  # files written before it was kept have none
        sigma = r.floats("noise.sigma", (r.length("noise.sigma"),))
        n_s = int(sigma.shape[0])
        sensors = [x or "" for x in r.strings("noise.sensors", n_s)]
        times = r.floats("noise.time", (n_s,))
        noise = tuple(zip(sensors, sigma.tolist(), times.tolist(), strict=True))
    r.finish()

    def bad(detail: str) -> StateError:
        return StateError(f"peer/extended: {detail}")

    if any(e[1] <= 0 for e in noise):
        raise bad("noise.sigma: must be positive")

    check_tracks(
        "peer/extended",
        ids,
        next_id,
        id_prefix,
        "E",
        created=floats["created"],
        updated=floats["updated"],
        time=floats["time"],
        score=floats["score"],
        peak=floats["peak"],
    )
    if k and t is None:
        raise bad("clusters without the time of the last scan")
    if n:
        if (alpha <= 0).any() or (floats["gamma"] <= 0).any():
            raise bad("extent degrees of freedom and expected counts must be positive")
        if not (positive_definite(P) and positive_definite(X)):
            raise bad("a covariance or extent is not symmetric positive definite")
    if k:
        assert t is not None
        if (c_first > c_time).any() or (c_time > t).any():
            raise bad("cluster times must satisfy first <= latest <= time")
    tracks = tuple(
        ExtendedTrack(
            id=ids[i],
            estimate=ExtendedEstimate(x=x[i], P=P[i], X=X[i], alpha=float(alpha[i])),
            time=float(floats["time"][i]),
            score=float(floats["score"][i]),
            peak=float(floats["peak"][i]),
            hits=int(ints["hits"][i]),
            confirmed=bool(confirmed[i]),
            created=float(floats["created"][i]),
            updated=float(floats["updated"][i]),
            gamma=float(floats["gamma"][i]),
            detection_ids=det_ids[i],
            split_evidence=int(ints["split_evidence"][i]),
            split_centroid=(float(split_c[i, 0]), float(split_c[i, 1])),
            split_gap=float(floats["split_gap"][i]),
            split_time=float(floats["split_time"][i]),
            shed_evidence=int(ints["shed_evidence"][i]),
            shed_centroid=(float(shed_c[i, 0]), float(shed_c[i, 1])),
            shed_gap=float(floats["shed_gap"][i]),
            shed_time=float(floats["shed_time"][i]),
            origin=float(origin[i]) if has_origin[i] else math.inf,
            visitors=frozenset(visitors[i]),
        )
        for i in range(n)
    )
    candidates = tuple(
        _Candidate(
            (float(c_centroid[j, 0]), float(c_centroid[j, 1])),
            float(c_first[j]),
            float(c_time[j]),
            int(c_seen[j]),
            tuple(float(v) for v in c_sums[j]),  # type: ignore[arg-type]
            c_sensors[j],
            min(int(c_missed[j]), RUN_MISSES),
        )
        for j in range(k)
    )
    absorbing = tuple(zip(absorbing_ids, absorbing_scans.tolist(), strict=True))
    return replace(
        base,
        tracks=tracks,
        candidates=candidates,
        next_id=next_id,
        time=t,
        absorbing=absorbing,
        noise=noise,
    )
