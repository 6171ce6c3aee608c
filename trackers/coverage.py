"""What a sensor looked at: the area of one scan, inside which a track without a detection was
missed, and outside which it was merely not looked at.

A scan's coverage is a polygon and/or a disc of ``max_range`` about the sensor. A point is in
view when it is inside (or within ``margin`` of) every shape given. Without a coverage a scan
covers the whole plane, which is right for one sensor watching one area and wrong for
several: a second radar 50 km off would count a miss on every track of the first at each of
its scans (``ln(1 − P_D)`` = −2.3 of score each with P_D = 0.9), so that tracks started
slowly and died young.

When a scan states no coverage and more than one sensor reports, :class:`CoverageLearner`
gives it the box that held its sensor's detections over its last :data:`LEARN_SCANS` scans
(clutter included; empty scans count as scans), grown by a tenth of its diagonal and three
standard deviations of the largest detection noise: a sensor is taken to look where it has
been seeing things, and one that has seen nothing in that while to look nowhere. A lone
sensor's scans cover everything, as before.
"""

from __future__ import annotations

import math
from collections import OrderedDict, deque
from dataclasses import dataclass

import numpy as np

__all__ = [
    "LEARN_SCANS",
    "MAX_SENSORS",
    "MAX_VERTICES",
    "Coverage",
    "CoverageLearner",
    "point_in_polygon",
    "polygon_distance",
]

#: The most vertices a coverage polygon may have.
MAX_VERTICES = 1024
#: A learned coverage is the box of the detections of a sensor's last this many scans.
LEARN_SCANS = 32
#: A learned box is grown by this fraction of its diagonal, and by this many standard
#: deviations of the largest detection noise of those scans.
LEARN_GROWTH = 0.1
LEARN_SIGMAS = 3.0
#: Point-in-polygon tests are done in blocks of at most this many points x vertices.
CHUNK_CELLS = 1 << 18
#: The most sensors remembered; beyond, the least recently heard is forgotten.
MAX_SENSORS = 256
#: A sensor not heard for this long (s of scan time) no longer counts as one of several.
FORGET_AFTER = 600.0


def point_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd rule: whether each of ``points (N, 2)`` lies inside the simple polygon with
    vertices ``polygon (k, 2)`` (either orientation, not repeated at the end). A point is
    inside when a ray from it along +x crosses the boundary an odd number of times: edge
    ``(a, b)`` is crossed where ``(a_y > y) ≠ (b_y > y)`` and
    ``x < a_x + (y − a_y)(b_x − a_x)/(b_y − a_y)``."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    a = np.asarray(polygon, dtype=float)
    b = np.roll(a, -1, axis=0)
    x, y = p[:, 0, None], p[:, 1, None]
    straddle = (a[:, 1] > y) != (b[:, 1] > y)
    dy = np.where(b[:, 1] == a[:, 1], 1.0, b[:, 1] - a[:, 1])
    x_cross = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / dy
    crossings = np.count_nonzero(straddle & (x < x_cross), axis=1)
    return (crossings % 2) == 1


def polygon_distance(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """The distance of each of ``points (N, 2)`` to the boundary of the polygon ``(k, 2)``:
    the least over its edges ``a + s (b − a)``, ``s = clip(((p − a)·(b − a))/|b − a|², 0, 1)``,
    of ``|p − a − s (b − a)|``."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    a = np.asarray(polygon, dtype=float)
    e = np.roll(a, -1, axis=0) - a
    length2 = np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
    rel = p[:, None, :] - a[None, :, :]
    s = np.clip(np.einsum("nkj,kj->nk", rel, e) / length2, 0.0, 1.0)
    off = rel - s[:, :, None] * e[None, :, :]
    return np.sqrt(np.min(np.einsum("nkj,nkj->nk", off, off), axis=1))


@dataclass(frozen=True, eq=False)
class Coverage:
    """The area a sensor looked at for one scan: the ``polygon (k, 2)`` (m, k ≥ 3) and/or the
    disc of radius ``max_range`` (m) about ``centre (2,)``; at least one of them, or
    ``nowhere`` (:meth:`none`). ``learned`` says that it was inferred from the sensor's
    detections rather than stated."""

    polygon: np.ndarray | None = None
    centre: np.ndarray | None = None
    max_range: float | None = None
    learned: bool = False
    nowhere: bool = False

    @staticmethod
    def none(*, learned: bool = False) -> Coverage:
        """A coverage that holds no point: a sensor that has seen nothing yet while others
        report (its empty scans miss no one's tracks)."""
        return Coverage(nowhere=True, learned=learned)

    def __post_init__(self) -> None:
        if self.nowhere:
            return
        if self.polygon is not None:
            poly = np.asarray(self.polygon, dtype=float)
            if poly.ndim != 2 or poly.shape[1] != 2 or not 3 <= poly.shape[0] <= MAX_VERTICES:
                raise ValueError(f"coverage: a polygon of 3 to {MAX_VERTICES} [x, y] vertices")
            if not np.isfinite(poly).all():
                raise ValueError("coverage: polygon vertices must be finite")
            object.__setattr__(self, "polygon", poly)
        if self.max_range is not None:
            if self.centre is None:
                raise ValueError("coverage: max_range needs the sensor's position")
            if not (math.isfinite(self.max_range) and self.max_range > 0):
                raise ValueError("coverage: max_range must be a finite number > 0")
            centre = np.asarray(self.centre, dtype=float).reshape(2)
            if not np.isfinite(centre).all():
                raise ValueError("coverage: the sensor's position must be finite")
            object.__setattr__(self, "centre", centre)
        if self.polygon is None and self.max_range is None:
            raise ValueError("coverage: a polygon, a max_range, or both")

    @staticmethod
    def box(lo: np.ndarray, hi: np.ndarray, *, learned: bool = False) -> Coverage:
        """The axis-aligned box from corner ``lo (2,)`` to corner ``hi (2,)``."""
        (x0, y0), (x1, y1) = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        return Coverage(polygon=np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]), learned=learned)

    def contains(self, points: np.ndarray, margin: float | np.ndarray = 0.0) -> np.ndarray:
        """Whether each of ``points (N, 2)`` is in view: inside every shape given or within
        ``margin`` (m, a number or one per point) of its edge."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        if self.nowhere:
            return np.zeros(p.shape[0], dtype=bool)
        m = np.broadcast_to(np.asarray(margin, dtype=float), (p.shape[0],))
        inside = np.ones(p.shape[0], dtype=bool)
        if self.max_range is not None and self.centre is not None:
            r = np.hypot(p[:, 0] - self.centre[0], p[:, 1] - self.centre[1])
            inside &= r <= self.max_range + m
        if self.polygon is not None and inside.any():
            rows = np.flatnonzero(inside)
            poly = self.polygon
            lo, hi = poly.min(axis=0), poly.max(axis=0)
            q, mq = p[rows], m[rows]
            near = ((q >= lo - mq[:, None]) & (q <= hi + mq[:, None])).all(axis=1)
            ok = np.zeros(rows.size, dtype=bool)
            # in blocks, so that points x vertices stays within CHUNK_CELLS
            block = max(1, CHUNK_CELLS // poly.shape[0])
            for start in range(0, int(near.size), block):
                sub = start + np.flatnonzero(near[start : start + block])
                if sub.size == 0:
                    continue
                inner = point_in_polygon(q[sub], poly)
                if not inner.all() and (mq[sub] > 0).any():
                    out = sub[~inner]
                    inner[~inner] = polygon_distance(q[out], poly) <= mq[out]
                ok[sub] = inner
            inside[rows] = ok
        return inside


class CoverageLearner:
    """The coverage of scans that state none, from where each sensor has been seeing things
    (module docstring). :meth:`coverage` answers for a scan without changing anything;
    :meth:`learn` records the scan once it has been processed."""

    def __init__(self) -> None:
        #: each sensor's last LEARN_SCANS scans: their detections' box and noise, or None
        self._boxes: dict[str, deque[tuple[float, float, float, float, float] | None]] = {}
        #: when each sensor was last heard, least recently first
        self._heard: OrderedDict[str, float] = OrderedDict()

    @staticmethod
    def _box(z: np.ndarray, R: np.ndarray) -> tuple[float, float, float, float, float] | None:
        if z.shape[0] == 0:
            return None
        lo, hi = z.min(axis=0), z.max(axis=0)
        # the largest eigenvalue's Gershgorin bound, var + |cov| (exact for a diagonal R)
        off = np.abs(R[:, 0, 1])
        var = max(float((R[:, 0, 0] + off).max()), float((R[:, 1, 1] + off).max()))
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]), math.sqrt(var)

    def _several(self, sensor_id: str, t: float) -> bool:
        return any(
            sid != sensor_id and t - last <= FORGET_AFTER for sid, last in self._heard.items()
        )

    def coverage(self, sensor_id: str, t: float, z: np.ndarray, R: np.ndarray) -> Coverage | None:
        """The learned coverage of a scan of ``sensor_id`` at ``t`` with detections ``z``,
        ``R``: ``None`` (everywhere) while no other sensor has been heard in the last
        :data:`FORGET_AFTER` seconds; :meth:`Coverage.none` when neither it nor the sensor's
        last :data:`LEARN_SCANS` scans hold a detection."""
        if not self._several(sensor_id, t):
            return None
        boxes = [b for b in self._boxes.get(sensor_id, ()) if b is not None]
        now = self._box(z, R)
        if now is not None:
            boxes.append(now)
        if not boxes:
            return Coverage.none(learned=True)
        b = np.array(boxes)
        lo, hi = b[:, 0:2].min(axis=0), b[:, 2:4].max(axis=0)
        grow = LEARN_GROWTH * float(np.hypot(*(hi - lo))) + LEARN_SIGMAS * float(b[:, 4].max())
        return Coverage.box(lo - grow, hi + grow, learned=True)

    def learn(self, sensor_id: str, t: float, z: np.ndarray, R: np.ndarray) -> None:
        """Record a processed scan."""
        self._heard[sensor_id] = t
        self._heard.move_to_end(sensor_id)
        self._boxes.setdefault(sensor_id, deque(maxlen=LEARN_SCANS)).append(self._box(z, R))
        while len(self._heard) > MAX_SENSORS:
            gone, _ = self._heard.popitem(last=False)
            self._boxes.pop(gone, None)
        stale = [sid for sid, last in self._heard.items() if t - last > FORGET_AFTER]
        for sid in stale:
            del self._heard[sid]
            self._boxes.pop(sid, None)
