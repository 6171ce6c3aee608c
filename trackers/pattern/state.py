"""The point-pattern tracker's state as plain data (:mod:`trackers.state`), and back.

Every track's multiple-model estimate (the combined state and covariance, the layers' mode
probabilities, every filter's state, covariance and probability, the algorithm), the shape
names it was made under, its score, life-cycle times and detection ids; the patterns sighted
but not yet tracked; each sensor's latest scan time; the id counter and the time. A track
saved under other patterns or another filter is adapted as a configuration change adapts it
(its shape probabilities carried over by name); with no pattern configured the tracks are
kept as they are, as a configuration change keeps them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from trackers.pattern.bending import STATE_DIM
from trackers.pattern.multiple_model import MMEstimate
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
    from trackers.pattern.tracker import _State

__all__ = ["PatternCheckpoint", "read_state"]

_ALGORITHMS = ("imm", "lmm")


def _cat(parts: list[np.ndarray], tail: tuple[int, ...]) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros((0, *tail))


@dataclass(frozen=True, eq=False)
class PatternCheckpoint:
    """A :class:`~trackers.pattern.tracker.PatternTracker`'s state at one moment."""

    state: _State

    def export(self) -> StateSection:
        """Plain data: the time, the id counter, the tracks (their filters end to end), the
        sightings and the sensors' times, as arrays."""
        st = self.state
        tracks, sights = st.tracks, st.candidates
        n, D = len(tracks), STATE_DIM
        arrays: dict[str, np.ndarray] = {}
        put_strings(arrays, "tracks.ids", [t.id for t in tracks])
        put_string_groups(arrays, "tracks.shapes", [t.shapes for t in tracks])
        put_string_groups(arrays, "tracks.detection_ids", [t.detection_ids for t in tracks])
        for name in ("time", "score", "peak", "created", "updated"):
            arrays[f"tracks.{name}"] = np.array([getattr(t, name) for t in tracks], dtype=float)
        arrays["tracks.hits"] = np.array([t.hits for t in tracks], dtype=np.int64)
        arrays["tracks.lmm"] = np.array([t.estimate.algorithm == "lmm" for t in tracks], bool)
        arrays["tracks.x"] = np.array([t.estimate.x for t in tracks], dtype=float).reshape(n, D)
        arrays["tracks.P"] = np.array([t.estimate.P for t in tracks], dtype=float).reshape(n, D, D)
        layers = [t.estimate.layer_probabilities for t in tracks]
        arrays["tracks.layer_sizes"] = np.array(
            [[len(m) for m in lp] for lp in layers], dtype=np.int64
        ).reshape(n, 3)
        arrays["tracks.layer_probabilities"] = _cat([np.concatenate(lp) for lp in layers], ())
        arrays["tracks.filters"] = np.array(
            [t.estimate.filter_x.shape[0] for t in tracks], dtype=np.int64
        )
        arrays["tracks.filter_x"] = _cat([t.estimate.filter_x for t in tracks], (D,))
        arrays["tracks.filter_P"] = _cat([t.estimate.filter_P for t in tracks], (D, D))
        arrays["tracks.filter_probabilities"] = _cat(
            [t.estimate.filter_probabilities for t in tracks], ()
        )
        arrays["tracks.pattern_points"] = _cat(
            [np.asarray(t.pattern_points, dtype=float).reshape(-1, 2) for t in tracks], (2,)
        )
        arrays["tracks.pattern_points.count"] = np.array(
            [len(t.pattern_points) for t in tracks], dtype=np.int64
        )
        k = len(sights)
        arrays["sightings.shape"] = np.array([s.shape for s in sights], dtype=np.int64)
        arrays["sightings.origin"] = np.array([s.origin for s in sights], float).reshape(k, 2)
        for name in ("attitude", "time", "sigma", "attitude_rate", "baseline"):
            arrays[f"sightings.{name}"] = np.array([getattr(s, name) for s in sights], float)
        for name in ("support", "seen"):
            arrays[f"sightings.{name}"] = np.array([getattr(s, name) for s in sights], np.int64)
        arrays["sightings.rows"] = np.array([r for s in sights for r in s.rows], dtype=np.int64)
        arrays["sightings.rows.count"] = np.array([len(s.rows) for s in sights], dtype=np.int64)
        moving = [s.velocity is not None for s in sights]
        arrays["sightings.moving"] = np.array(moving, dtype=bool)
        arrays["sightings.velocity"] = np.array(
            [s.velocity if s.velocity is not None else (0.0, 0.0) for s in sights], float
        ).reshape(k, 2)
        put_strings(arrays, "sensors.ids", [s for s, _ in st.sensor_times])
        arrays["sensors.time"] = np.array([t for _, t in st.sensor_times], dtype=float)
        values = {
            "time": st.time,
            "next_id": st.next_id,
            "patterns": [] if st.modes is None else list(st.modes.layers[2]),
            "n_tracks": n,
            "n_filters": int(arrays["tracks.filters"].sum()),
            "n_layer_probabilities": int(arrays["tracks.layer_sizes"].sum()),
            "n_pattern_points": int(arrays["tracks.pattern_points"].shape[0]),
            "n_sightings": k,
            "n_sighting_rows": int(arrays["sightings.rows"].size),
            "n_sensors": len(st.sensor_times),
        }
        return StateSection(values, arrays)


def _probabilities_ok(p: np.ndarray) -> bool:
    return bool(((p >= 0) & (p <= 1 + 1e-9)).all())


def read_state(section: StateSection, base: _State, id_prefix: str = "") -> _State:
    """The state a section of :meth:`PatternCheckpoint.export` holds, checked, under the
    configuration of ``base`` (kept as it is); :class:`StateError` naming the field."""
    from trackers.pattern.tracker import PatternTrack, PatternTracker, _Sighting

    r = SectionReader(section, "peer/point_patterns")
    t = r.time("time")
    next_id = r.integer("next_id", ge=1)
    n = r.integer("n_tracks", ge=0)
    nfil = r.integer("n_filters", ge=0)
    nlp = r.integer("n_layer_probabilities", ge=0)
    npts = r.integer("n_pattern_points", ge=0)
    k = r.integer("n_sightings", ge=0)
    nrows = r.integer("n_sighting_rows", ge=0)
    ns = r.integer("n_sensors", ge=0)
    saved_patterns = r.values.get("patterns")
    if not (isinstance(saved_patterns, list) and all(isinstance(p, str) for p in saved_patterns)):
        raise StateError("peer/point_patterns.patterns: must be a list of pattern names")
    D = STATE_DIM
    ids = [s or "" for s in r.strings("tracks.ids", n)]
    shapes = r.string_groups("tracks.shapes", n)
    det_ids = r.string_groups("tracks.detection_ids", n)
    f = {name: r.floats(f"tracks.{name}", (n,)) for name in ("time", "score", "peak")}
    f.update({name: r.floats(f"tracks.{name}", (n,)) for name in ("created", "updated")})
    hits = r.integers("tracks.hits", (n,), ge=0)
    lmm = r.booleans("tracks.lmm", (n,))
    x = r.floats("tracks.x", (n, D))
    P = r.floats("tracks.P", (n, D, D))
    sizes = r.integers("tracks.layer_sizes", (n, 3), ge=1)
    layer_p = r.floats("tracks.layer_probabilities", (nlp,))
    filters = r.integers("tracks.filters", (n,), ge=1)
    fx = r.floats("tracks.filter_x", (nfil, D))
    fP = r.floats("tracks.filter_P", (nfil, D, D))
    fp = r.floats("tracks.filter_probabilities", (nfil,))
    points = r.floats("tracks.pattern_points", (npts, 2))
    points_count = r.integers("tracks.pattern_points.count", (n,), ge=0)
    s_shape = r.integers("sightings.shape", (k,), ge=0)
    s_origin = r.floats("sightings.origin", (k, 2))
    s = {
        name: r.floats(f"sightings.{name}", (k,))
        for name in ("attitude", "time", "sigma", "attitude_rate", "baseline")
    }
    s_support = r.integers("sightings.support", (k,), ge=0)
    s_seen = r.integers("sightings.seen", (k,), ge=1)
    s_rows = r.integers("sightings.rows", (nrows,), ge=0)
    s_rows_count = r.integers("sightings.rows.count", (k,), ge=0)
    s_moving = r.booleans("sightings.moving", (k,))
    s_velocity = r.floats("sightings.velocity", (k, 2))
    sensor_ids = [x_ or "" for x_ in r.strings("sensors.ids", ns)]
    sensor_time = r.floats("sensors.time", (ns,))
    r.finish()

    def bad(detail: str) -> StateError:
        return StateError(f"peer/point_patterns: {detail}")

    check_tracks(
        "peer/point_patterns",
        ids,
        next_id,
        id_prefix,
        "B",
        created=f["created"],
        updated=f["updated"],
        time=f["time"],
        score=f["score"],
        peak=f["peak"],
    )
    if (
        int(sizes.sum()) != nlp
        or int(filters.sum()) != nfil
        or int(s_rows_count.sum()) != nrows
        or int(points_count.sum()) != npts
    ):
        raise bad("the counts of layer probabilities, filters, points or rows do not add up")
    if k and t is None:
        raise bad("sightings without the time of the last scan")
    if k and (s_shape >= len(saved_patterns)).any():
        raise bad("a sighting's shape is not one of the saved patterns")
    if n:
        if not (positive_definite(P) and positive_definite(fP)):
            raise bad("a covariance is not symmetric positive definite")
        if not (_probabilities_ok(layer_p) and _probabilities_ok(fp)):
            raise bad("mode probabilities must be in [0, 1]")
        if any(len(sh) != int(z[2]) for sh, z in zip(shapes, sizes, strict=True)):
            raise bad("a track's shape names do not match its shape layer")
    if k and (s["time"] > t).any():  # type: ignore[operator]
        raise bad("a sighting is later than the last scan")
    if n and not (points_count >= 3).all():
        raise bad("a track's pattern has fewer than 3 points")
    tracks = []
    lp_at = fil_at = pt_at = 0
    state = base
    for i in range(n):
        lp = []
        for size in sizes[i].tolist():
            lp.append(layer_p[lp_at : lp_at + size])
            lp_at += size
        fil = slice(fil_at, fil_at + int(filters[i]))
        fil_at = fil.stop
        pts = points[pt_at : pt_at + int(points_count[i])]
        pt_at += int(points_count[i])
        try:
            est = MMEstimate(
                x=x[i],
                P=P[i],
                layer_probabilities=tuple(lp),
                filter_x=fx[fil],
                filter_P=fP[fil],
                filter_probabilities=fp[fil],
                algorithm=_ALGORITHMS[int(lmm[i])],
            )
        except ValueError as exc:
            raise bad(f"track {ids[i]}: {exc}") from None
        best = int(np.argmax(est.layer_probabilities[2]))
        track = PatternTrack(
            id=ids[i],
            estimate=est,
            shapes=shapes[i],
            time=float(f["time"][i]),
            score=float(f["score"][i]),
            peak=float(f["peak"][i]),
            hits=int(hits[i]),
            created=float(f["created"][i]),
            updated=float(f["updated"][i]),
            pattern_points=pts.copy(),
            detection_ids=det_ids[i],
        )
        modes, cfg = state.modes, state.config
        if modes is None:  # no pattern configured: kept as a configuration change keeps it
            tracks.append(track)
            continue
        same = (
            tuple(track.shapes) == tuple(modes.layers[2])
            and est.algorithm == cfg.filter
            and tuple(sizes[i].tolist()) == modes.sizes
        )
        if same:
            tracks.append(replace(track, pattern_points=modes.patterns[best]))
        else:
            tracks.append(PatternTracker._adapted(track, modes, cfg))
    rows_at = 0
    sightings = []
    for j in range(k):
        rows = tuple(s_rows[rows_at : rows_at + int(s_rows_count[j])].tolist())
        rows_at += int(s_rows_count[j])
        sightings.append(
            _Sighting(
                shape=int(s_shape[j]),
                origin=(float(s_origin[j, 0]), float(s_origin[j, 1])),
                attitude=float(s["attitude"][j]),
                time=float(s["time"][j]),
                rows=rows,
                support=int(s_support[j]),
                sigma=float(s["sigma"][j]),
                seen=int(s_seen[j]),
                velocity=(
                    (float(s_velocity[j, 0]), float(s_velocity[j, 1])) if s_moving[j] else None
                ),
                attitude_rate=float(s["attitude_rate"][j]),
                baseline=float(s["baseline"][j]),
            )
        )
    # Sightings are of the patterns configured when they were made: kept only under the same.
    if state.modes is None or list(state.modes.layers[2]) != saved_patterns:
        sightings = []
    if not all(math.isfinite(v) for v in sensor_time.tolist()):
        raise bad("a sensor time is not finite")
    return replace(
        state,
        tracks=tuple(tracks),
        candidates=tuple(sightings),
        next_id=next_id,
        time=t,
        sensor_times=tuple(zip(sensor_ids, sensor_time.tolist(), strict=True)),
    )
