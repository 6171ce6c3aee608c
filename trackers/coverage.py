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
been seeing things, and one that has seen nothing in that while to look nowhere. When those
scans gave the sensor's position, the box is cut to the disc about it (its latest position)
of the farthest detection's range, grown a little: a radar's box would reach 41 % beyond
its range at the corners. A lone sensor's scans cover everything, as before, but for a
radar that streams its turn sector by sector without saying so: when the detections of each
of its scans lie within a narrow arc of bearings about its position and those of its last
scans together span a wide one (:meth:`CoverageLearner.sweeping`), each scan looked at the
arc of its own detections, grown by the bearing noise, out to the range it reaches (one
without a detection at nothing). Counted as a look everywhere, each of 16 sectors a turn
missed every track outside it 15 times a turn, and a newcomer's radar kept no track at all.

How much of a target's possible positions a scan looked at decides how much its silence
says: :func:`visible_fraction` is the share of a Gaussian (a track's predicted position) and
:func:`disc_fraction` the share of a disc (the reach of a target of unknown velocity) inside
the coverage, estimated on a fixed spread of sample points where the shape straddles its
edge (exactly 0 or 1 elsewhere). A scan misses a target with probability ``1 − P_D · f``: a
camera watching a 200 m square ten times a second says nothing of a car 100 m outside it,
whose radar track it would otherwise have missed ten times a second.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "LEARN_SCANS",
    "MAX_SENSORS",
    "MAX_VERTICES",
    "SECTOR_KEEP_SCANS",
    "SECTOR_LONG_SPAN",
    "SECTOR_SCANS",
    "SECTOR_SHARE",
    "SECTOR_SPAN",
    "SECTOR_WINDOW",
    "Coverage",
    "CoverageLearner",
    "bearing_arc",
    "disc_fraction",
    "point_in_polygon",
    "polygon_arc",
    "polygon_distance",
    "same_area",
    "visible_fraction",
]

#: The most vertices a coverage polygon may have.
MAX_VERTICES = 1024
#: A learned coverage is the box of the detections of a sensor's last this many scans.
LEARN_SCANS = 32
#: A learned box is grown by this fraction of its diagonal, and by this many standard
#: deviations of the largest detection noise of those scans.
LEARN_GROWTH = 0.1
LEARN_SIGMAS = 3.0
#: A learned range (the farthest detection of those scans from the sensor) is grown by this
#: fraction, and by LEARN_SIGMAS standard deviations: 32 scans of a radar's false alarms put
#: the farthest well within 1 % of its range, a sparser sensor's short of it (its scans then
#: miss no track beyond: the cautious side).
LEARN_RANGE_GROWTH = 0.02
#: A sensor whose scans give its position streams its revolution sector by sector when, of
#: its last LEARN_SCANS scans, at least SECTOR_SCANS had detections, none of which spans (in
#: bearing about the sensor) more than SECTOR_SHARE of the arc that all of them span
#: together, and that arc is at least SECTOR_SPAN wide ...
SECTOR_SCANS = 8
SECTOR_SHARE = 0.4
SECTOR_SPAN = math.radians(60.0)
#: ... or when the same holds of its last SECTOR_WINDOW scans with an arc of at least
#: SECTOR_LONG_SPAN: a radar reporting 48 sectors a turn or more in a sparse scene (14
#: detections a turn) showed fewer than SECTOR_SCANS sectors with detections in its last
#: LEARN_SCANS batches and was never taken to sweep (each of its batches missed every track
#: outside it: no track lived), while a whole-turn radar's few targets, drifting in bearing,
#: span 60° in 128 turns but not half the circle (a lone target drifting 1.5° a turn or more
#: does, and is taken for a sweep: its track is then not missed while its batches are empty,
#: and goes by coasting). Once found, a sweep goes on while SECTOR_KEEP_SCANS of the window's
#: scans with detections meet the first test (a turn of few detections is no sign that the
#: radar stopped turning); over the window, up to one odd scan in every LEARN_SCANS is left
#: out as the first test leaves out one (one in every SECTOR_SCANS with detections at most).
#: Scans spanning too wide an arc for a sector (more than
#: SECTOR_SHARE of the circle) count over the last LEARN_SCANS only ...
SECTOR_WINDOW = 128
SECTOR_LONG_SPAN = math.radians(180.0)
SECTOR_KEEP_SCANS = 3
#: ... and each of its scans then looked at the arc of its own detections, grown on each side
#: by LEARN_SIGMAS standard deviations of the bearing noise of its nearest detection, at
#: least SECTOR_MARGIN and at most SECTOR_MAX_MARGIN (rad).
SECTOR_MARGIN = math.radians(0.5)
SECTOR_MAX_MARGIN = math.radians(10.0)
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
            (x0, y0), (x1, y1) = poly[0], poly[poly.shape[0] // 2]
            box = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
            if x0 < x1 and y0 < y1 and poly.shape[0] == 4 and np.array_equal(poly, box):
                # A box as :meth:`box` makes it (learned coverages among them): tested by
                # comparisons, with the even-odd rule's answers (x0 <= x < x1, y0 <= y < y1).
                object.__setattr__(self, "_bounds", (float(x0), float(y0), float(x1), float(y1)))
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
    def box(
        lo: np.ndarray,
        hi: np.ndarray,
        *,
        learned: bool = False,
        centre: np.ndarray | None = None,
        max_range: float | None = None,
    ) -> Coverage:
        """The axis-aligned box from corner ``lo (2,)`` to corner ``hi (2,)`` (cut to the
        disc of ``max_range`` about ``centre``, if given)."""
        (x0, y0), (x1, y1) = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        return Coverage(
            polygon=np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]),
            centre=centre,
            max_range=max_range,
            learned=learned,
        )

    def _in_range(
        self, points: np.ndarray, margin: float | np.ndarray, sign: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The points ``(N, 2)``, their margins ``(N,)`` and whether each is within
        ``max_range + sign · margin`` of the sensor (all when there is no range; none when
        the coverage is nowhere)."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        m = np.broadcast_to(np.asarray(margin, dtype=float), (p.shape[0],))
        inside = np.full(p.shape[0], not self.nowhere)
        if self.max_range is not None and self.centre is not None and not self.nowhere:
            r = np.hypot(p[:, 0] - self.centre[0], p[:, 1] - self.centre[1])
            inside &= r <= self.max_range + sign * m
        return p, m, inside

    def contains(self, points: np.ndarray, margin: float | np.ndarray = 0.0) -> np.ndarray:
        """Whether each of ``points (N, 2)`` is in view: inside every shape given or within
        ``margin`` (m, a number or one per point) of its edge."""
        p, m, inside = self._in_range(points, margin, 1.0)
        bounds = self.__dict__.get("_bounds")
        if bounds is not None and inside.any():
            x, y = p[:, 0], p[:, 1]
            x0, y0, x1, y1 = bounds
            within = (x >= x0) & (x < x1) & (y >= y0) & (y < y1)
            if (m > 0).any():  # within margin of the box: its distance to the box
                dx = np.maximum(np.maximum(x0 - x, x - x1), 0.0)
                dy = np.maximum(np.maximum(y0 - y, y - y1), 0.0)
                within |= np.sqrt(dx * dx + dy * dy) <= m
            inside &= within
        elif self.polygon is not None and inside.any():
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

    def holds(self, points: np.ndarray, margin: np.ndarray) -> np.ndarray:
        """Whether each of ``points (N, 2)`` is in view with at least ``margin (N,)`` (m) to
        spare: inside every shape given and at least that far from its edge."""
        p, m, inside = self._in_range(points, margin, -1.0)
        bounds = self.__dict__.get("_bounds")
        if bounds is not None and inside.any():
            x, y = p[:, 0], p[:, 1]
            x0, y0, x1, y1 = bounds
            room = np.minimum(np.minimum(x - x0, x1 - x), np.minimum(y - y0, y1 - y))
            inside &= (x >= x0) & (x < x1) & (y >= y0) & (y < y1) & (room >= m)
        elif self.polygon is not None and inside.any():
            rows = np.flatnonzero(inside)
            poly = self.polygon
            lo, hi = poly.min(axis=0), poly.max(axis=0)
            q, mq = p[rows], m[rows]
            ok = ((q >= lo + mq[:, None]) & (q <= hi - mq[:, None])).all(axis=1)
            sub = np.flatnonzero(ok)
            if sub.size:
                deep = point_in_polygon(q[sub], poly)
                deep[deep] = polygon_distance(q[sub[deep]], poly) >= mq[sub[deep]]
                ok[sub] = deep
            inside[rows] = ok
        return inside


#: The sample points of :func:`visible_fraction` and :func:`disc_fraction`: a sunflower
#: spiral (golden-angle steps) of equal-probability rings, of the standard normal
#: distribution and of the unit disc.
SAMPLES = 64
_ANGLE = np.arange(SAMPLES) * math.pi * (3.0 - math.sqrt(5.0))
_U = (np.arange(SAMPLES) + 0.5) / SAMPLES
_NORMAL = np.sqrt(-2.0 * np.log1p(-_U))[:, None] * np.column_stack([np.cos(_ANGLE), np.sin(_ANGLE)])
_DISC = np.sqrt(_U)[:, None] * np.column_stack([np.cos(_ANGLE), np.sin(_ANGLE)])
#: Beyond this many standard deviations a Gaussian counts as wholly on one side of an edge.
GAUSSIAN_REACH = 4.0
#: The most point-edge tests one call of :func:`visible_fraction` or :func:`disc_fraction`
#: makes on a polygon that is not a box: beyond, each shape gets fewer of the sample points
#: (every second, fourth, ...; at least :data:`MIN_SAMPLES`), and past that the shapes at the
#: edge count as wholly in view (the rule before shares were taken), so that a batch stating
#: a polygon of 1024 vertices with thousands of detections at its edge costs milliseconds.
SAMPLE_BUDGET = 1 << 20
MIN_SAMPLES = 8


def _straddling(
    coverage: Coverage, centre: np.ndarray, reach: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The share in view of the discs of radius ``reach_i`` about ``centre_i`` that lie
    wholly outside (0) or inside (1) the coverage, and the rows of those that straddle its
    edge (their share left at 1, to be found)."""
    out = coverage.contains(centre, reach).astype(float)
    partial = np.flatnonzero(out > 0.0)
    if partial.size:
        partial = partial[~coverage.holds(centre[partial], reach[partial])]
    return out, partial


def _samples(coverage: Coverage, rows: int, spread: np.ndarray) -> np.ndarray | None:
    """The sample points ``spread (SAMPLES, 2)`` to use for ``rows`` shapes: all of them, or
    every ``k``-th within :data:`SAMPLE_BUDGET` point-edge tests of a polygon (a box and a
    range disc are tested by comparisons); None when even :data:`MIN_SAMPLES` each would
    exceed it."""
    polygon = coverage.polygon
    edges = 0 if polygon is None or "_bounds" in coverage.__dict__ else len(polygon)
    if rows * SAMPLES * edges <= SAMPLE_BUDGET:
        return spread
    if rows * MIN_SAMPLES * edges > SAMPLE_BUDGET:
        return None
    k = -(-rows * SAMPLES * edges // SAMPLE_BUDGET)  # ceil
    return spread[::k]


def _share(coverage: Coverage, points: np.ndarray) -> np.ndarray:
    """The share of each row's sample points ``points (n, S, 2)`` in view."""
    n = points.shape[0]
    return coverage.contains(points.reshape(-1, 2)).reshape(n, -1).mean(axis=1)


def same_area(a: Coverage | None, b: Coverage | None) -> bool:
    """Whether two coverages are one area (``None``: everywhere): the same polygon, centre
    and range, or both nowhere."""
    if a is None or b is None:
        return a is b
    if a is b:
        return True
    if a.nowhere or b.nowhere:
        return a.nowhere == b.nowhere
    return (
        a.max_range == b.max_range
        and _same_points(a.centre, b.centre)
        and _same_points(a.polygon, b.polygon)
    )


def _same_points(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is b
    return a.shape == b.shape and bool(np.array_equal(a, b))


def visible_fraction(coverage: Coverage, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``f_i = P(x ∈ coverage)`` for ``x ~ N(mean_i, cov_i)`` (``mean (N, 2)``, ``cov (N, 2,
    2)``): 0 or 1 when the ellipse of :data:`GAUSSIAN_REACH` standard deviations lies wholly
    outside or inside, else the share of :data:`SAMPLES` points ``mean_i + L_i u_k``
    (``L_i L_iᵀ = cov_i``, ``u_k`` a fixed spread of the standard normal) in view."""
    mean = np.asarray(mean, dtype=float).reshape(-1, 2)
    cov = np.asarray(cov, dtype=float).reshape(-1, 2, 2)
    a, b, d = cov[:, 0, 0], 0.5 * (cov[:, 0, 1] + cov[:, 1, 0]), cov[:, 1, 1]
    lam = 0.5 * (a + d) + np.sqrt(0.25 * (a - d) ** 2 + b * b)
    out, partial = _straddling(coverage, mean, GAUSSIAN_REACH * np.sqrt(np.maximum(lam, 0.0)))
    if partial.size:
        # L = [[l11, 0], [l21, l22]] (closed form; a zero variance floored)
        a, b, d = a[partial, None], b[partial, None], d[partial, None]
        l11 = np.sqrt(np.maximum(a, 1e-300))
        l21 = b / l11
        l22 = np.sqrt(np.maximum(d - l21 * l21, 0.0))
        spread = _samples(coverage, partial.size, _NORMAL)
        if spread is None:
            return out
        u, w = spread[None, :, 0], spread[None, :, 1]
        pts = np.stack([l11 * u, l21 * u + l22 * w], axis=2) + mean[partial, None, :]
        out[partial] = _share(coverage, pts)
    return out


def disc_fraction(coverage: Coverage, centre: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """``f_i``, the share of the disc of ``radius_i`` about ``centre_i (N, 2)`` in view: 0 or
    1 when the disc lies wholly outside or inside, else the share of :data:`SAMPLES` points
    spread evenly over it."""
    centre = np.asarray(centre, dtype=float).reshape(-1, 2)
    radius = np.broadcast_to(np.asarray(radius, dtype=float), (centre.shape[0],))
    out, partial = _straddling(coverage, centre, radius)
    if partial.size:
        spread = _samples(coverage, partial.size, _DISC)
        if spread is None:
            return out
        pts = centre[partial, None, :] + radius[partial, None, None] * spread[None]
        out[partial] = _share(coverage, pts)
    return out


#: One scan's detections: their box ``(x0, y0, x1, y1)``, largest noise σ (m) and the range of
#: the farthest from the sensor's position (m; None when the scan gave none), or None.
Box = tuple[float, float, float, float, float, float | None] | None
#: The arc of bearings ``(start, width)`` (rad) a scan's detections span about its sensor.
Arc = tuple[float, float] | None
#: What a :class:`CoverageLearner` knows, least recently heard sensor first: each sensor's id,
#: when it was last heard, the boxes of its last :data:`LEARN_SCANS` scans, the arcs of
#: its last :data:`SECTOR_WINDOW` and whether it was taken to sweep.
LearnerSnapshot = tuple[tuple[str, float, tuple[Box, ...], tuple[Arc, ...], bool], ...]


def _finite(value: Any) -> bool:
    """Whether a JSON value is a finite number (not a bool)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _arc(bearings: np.ndarray) -> tuple[float, float]:
    """The shortest arc ``(start, width)`` (rad, ``start`` in [0, 2π)) holding every one of
    ``bearings`` (rad, at least one): the circle less its widest gap between neighbours."""
    b = np.sort(np.mod(bearings, 2.0 * math.pi))
    gaps = np.empty_like(b)
    np.subtract(b[1:], b[:-1], out=gaps[:-1])
    gaps[-1] = b[0] + 2.0 * math.pi - b[-1]
    k = int(gaps.argmax())
    return float(b[(k + 1) % b.size]), max(0.0, float(2.0 * math.pi - gaps[k]))


def bearing_arc(points: np.ndarray, position: np.ndarray) -> tuple[float, float]:
    """The shortest arc ``(start, width)`` (rad) of the bearings of ``points (N ≥ 1, 2)``
    about ``position``."""
    d = np.asarray(points, dtype=float).reshape(-1, 2) - np.asarray(position, dtype=float)
    return _arc(np.arctan2(d[:, 1], d[:, 0]))


def polygon_arc(polygon: np.ndarray, position: np.ndarray) -> tuple[float, float] | None:
    """The arc of bearings about ``position`` that ``polygon`` spans (its vertices' but for
    one at ``position``, a sector's apex), or ``None`` when ``position`` is inside it, off
    its edge (all bearings)."""
    poly = np.asarray(polygon, dtype=float)
    at = np.asarray(position, dtype=float).reshape(1, 2)
    scale = float(np.max(np.abs(poly - at)))
    if polygon_distance(at, poly)[0] > 1e-9 * scale and point_in_polygon(at, poly)[0]:
        return None
    d = poly - at
    away = np.hypot(d[:, 0], d[:, 1]) > 1e-9 * scale
    return bearing_arc(poly[away], at) if away.any() else None


def _arc_of(z: np.ndarray, R: np.ndarray, position: np.ndarray) -> tuple[Arc, float, float]:
    """The arc of bearings of detections ``z`` (at least one) about ``position``, the range
    of the nearest and the largest position noise standard deviation of ``R``."""
    d = z - np.asarray(position, dtype=float).reshape(1, 2)
    ranges = np.hypot(d[:, 0], d[:, 1])
    off = np.abs(R[:, 0, 1])
    sigma = math.sqrt(max(float((R[:, 0, 0] + off).max()), float((R[:, 1, 1] + off).max())))
    away = ranges > LEARN_SIGMAS * sigma  # a detection at the sensor has no bearing
    if not away.any():
        return None, 0.0, sigma
    d = d[away]
    return _arc(np.arctan2(d[:, 1], d[:, 0])), float(ranges[away].min()), sigma


def _sweeping(
    arcs: tuple[Arc, ...],
    min_scans: int = SECTOR_SCANS,
    min_span: float = SECTOR_SPAN,
    odd: int = 1,
) -> bool:
    """Whether the scans of ``arcs`` (None: no detections or no position) are sectors of a
    revolution: at least ``min_scans`` with detections, none spanning more than
    :data:`SECTOR_SHARE` of the circle or of the arc all of them span together, that arc at
    least ``min_span`` wide; the widest of them left out, one in every :data:`SECTOR_SCANS`
    with detections up to ``odd`` (an odd scan does not stop a sweep)."""
    seen = sorted((a for a in arcs if a is not None), key=lambda a: a[1])
    seen = seen[: len(seen) - max(1, min(odd, len(seen) // SECTOR_SCANS))]
    if len(seen) < min_scans:
        return False
    widest = seen[-1][1]
    if widest > SECTOR_SHARE * 2.0 * math.pi:
        return False
    ends = np.array([s for s, _ in seen] + [s + w for s, w in seen])
    span = _arc(ends)[1]
    return span >= min_span and widest <= SECTOR_SHARE * span


def _sweep_found(arcs: tuple[Arc, ...], was: bool) -> bool:
    """Whether the arcs of a sensor's last :data:`SECTOR_WINDOW` scans show a sweep: those of
    its last :data:`LEARN_SCANS` (:func:`_sweeping`), or all of them spanning at least
    :data:`SECTOR_LONG_SPAN` (a radar of many sectors in a sparse scene); and once found
    (``was``), while :data:`SECTOR_KEEP_SCANS` of them with detections span
    :data:`SECTOR_SPAN`; over the whole window, up to one odd scan in every
    :data:`LEARN_SCANS` is left out."""
    odd = SECTOR_WINDOW // LEARN_SCANS  # one odd scan in every LEARN_SCANS
    return (
        _sweeping(arcs[-LEARN_SCANS:])
        or _sweeping(arcs, min_span=SECTOR_LONG_SPAN, odd=odd)
        or (was and _sweeping(arcs, SECTOR_KEEP_SCANS, odd=odd))
    )


def _wide_arcs(arcs: tuple[Arc, ...]) -> int:
    """How many of ``arcs`` span more than :data:`SECTOR_SHARE` of the circle."""
    return sum(1 for a in arcs if a is not None and a[1] > SECTOR_SHARE * 2.0 * math.pi)


def _wedge(centre: np.ndarray, start: float, width: float, r: float) -> np.ndarray:
    """The polygon of the wedge from ``centre`` over bearings ``start`` to ``start + width``
    (rad) reaching past the circle of radius ``r``: its arc's vertices at ``r / cos(δ/2)``,
    ``δ`` their angular step, so that the chords stay outside the circle."""
    n = max(2, math.ceil(width / math.radians(5.0)) + 1)
    a = np.linspace(start, start + width, n)
    reach = r / math.cos(0.5 * width / (n - 1))
    c = np.asarray(centre, dtype=float).reshape(2)
    arc = c + reach * np.column_stack([np.cos(a), np.sin(a)])
    return np.vstack([c, arc])


class CoverageLearner:
    """The coverage of scans that state none, from where each sensor has been seeing things
    (module docstring). :meth:`coverage` answers for a scan without changing anything;
    :meth:`learn` records the scan once it has been processed; :meth:`snapshot` and
    :meth:`restored` save and restore what it knows (with the tracks, so that a restored
    tracker goes on as the one saved)."""

    def __init__(self) -> None:
        #: each sensor's last LEARN_SCANS scans (a tuple, replaced at each: snapshots share it)
        self._boxes: dict[str, tuple[Box, ...]] = {}
        #: when each sensor was last heard, least recently first
        self._heard: OrderedDict[str, float] = OrderedDict()
        #: each sensor's position as its last scan that gave one gave it (not saved)
        self._positions: dict[str, np.ndarray] = {}
        #: the arcs of each sensor's last SECTOR_WINDOW scans (saved with the boxes), how many
        #: of the last LEARN_SCANS of them span too much for a sector (more than SECTOR_SHARE
        #: of the circle), and whether they are sectors of a revolution
        self._arcs: dict[str, tuple[Arc, ...]] = {}
        self._wide: dict[str, int] = {}
        self._sweeping: dict[str, bool] = {}

    @staticmethod
    def _box(z: np.ndarray, R: np.ndarray, position: np.ndarray | None = None) -> Box:
        """A scan's box of detections, the largest noise standard deviation and the range of
        its farthest detection from the sensor's ``position`` (``None`` when not given)."""
        if z.shape[0] == 0:
            return None
        lo, hi = z.min(axis=0), z.max(axis=0)
        # the largest eigenvalue's Gershgorin bound, var + |cov| (exact for a diagonal R)
        off = np.abs(R[:, 0, 1])
        var = max(float((R[:, 0, 0] + off).max()), float((R[:, 1, 1] + off).max()))
        reach = None
        if position is not None:
            d = z - np.asarray(position, dtype=float).reshape(1, 2)
            far = float(np.max(np.hypot(d[:, 0], d[:, 1])))
            reach = far if math.isfinite(far) else None
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]), math.sqrt(var), reach

    def _several(self, sensor_id: str, t: float) -> bool:
        return any(
            sid != sensor_id and t - last <= FORGET_AFTER for sid, last in self._heard.items()
        )

    def coverage(
        self,
        sensor_id: str,
        t: float,
        z: np.ndarray,
        R: np.ndarray,
        position: np.ndarray | None = None,
    ) -> Coverage | None:
        """The learned coverage of a scan of ``sensor_id`` at ``t`` with detections ``z``,
        ``R`` from a sensor at ``position`` (if given): that of a sector (:meth:`sector`)
        when the sensor streams sectors; else ``None`` (everywhere) while no other
        sensor has been heard in the last :data:`FORGET_AFTER` seconds;
        :meth:`Coverage.none` when neither it nor the sensor's last :data:`LEARN_SCANS`
        scans hold a detection. When every one of those scans with a detection gave the
        sensor's position, the box is cut to the disc about it of radius

            r = (1 + LEARN_RANGE_GROWTH) r_max + LEARN_SIGMAS σ,

        ``r_max`` the farthest detection's range (from the sensor's position at its scan):
        a radar's box reaches 41 % beyond its range at the corners, where another radar's
        targets would be missed at each of its scans."""
        sector = self.sector(sensor_id, z, R, position)
        if not self._several(sensor_id, t):
            return sector
        if sector is not None:
            return sector
        boxes = [b for b in self._boxes.get(sensor_id, ()) if b is not None]
        now = self._box(z, R, position)
        if now is not None:
            boxes.append(now)
        if not boxes:
            return Coverage.none(learned=True)
        b = np.array([box[:5] for box in boxes])
        lo, hi = b[:, 0:2].min(axis=0), b[:, 2:4].max(axis=0)
        sigma = float(b[:, 4].max())
        grow = LEARN_GROWTH * float(np.hypot(*(hi - lo))) + LEARN_SIGMAS * sigma
        reaches = [box[5] for box in boxes if box[5] is not None]
        if position is None:  # an empty batch that gives none: where the sensor last was
            position = self._positions.get(sensor_id)
        r = (1.0 + LEARN_RANGE_GROWTH) * max(reaches, default=0.0) + LEARN_SIGMAS * sigma
        if position is None or len(reaches) < len(boxes) or not math.isfinite(r):
            return Coverage.box(lo - grow, hi + grow, learned=True)
        return Coverage.box(
            lo - grow,
            hi + grow,
            learned=True,
            centre=np.asarray(position, dtype=float).reshape(2),
            max_range=max(r, 1e-9),
        )

    def last_arc(self, sensor_id: str) -> Arc:
        """The arc of bearings of the detections of ``sensor_id``'s last scan learned (None:
        none, or no position)."""
        arcs = self._arcs.get(sensor_id, ())
        return arcs[-1] if arcs else None

    def sweeping(self, sensor_id: str) -> bool:
        """Whether ``sensor_id``'s last scans are sectors of a revolution (:func:`_sweep_found`:
        :data:`SECTOR_SCANS`, :data:`SECTOR_SHARE`, :data:`SECTOR_SPAN`,
        :data:`SECTOR_LONG_SPAN`, :data:`SECTOR_KEEP_SCANS`): each scan's detections within a
        narrow arc of bearings about the sensor, the arcs of its scans together a wide one."""
        return self._sweeping.get(sensor_id, False)

    def sector(
        self, sensor_id: str, z: np.ndarray, R: np.ndarray, position: np.ndarray | None
    ) -> Coverage | None:
        """For a scan of a sensor that streams sectors (:meth:`sweeping`, this scan's arc
        counted in), the wedge of its detections' arc about ``position`` grown by the bearing
        noise (:data:`SECTOR_MARGIN`), out to the range its scans reach (cut by that disc);
        :meth:`Coverage.none` for one without detections; ``None`` for any other scan (no
        position, or a sensor that does not stream sectors)."""
        if position is None or self._wide.get(sensor_id, 0) > 2:
            return None  # (two scans in the window with this one span too wide an arc)
        arcs = self._arcs.get(sensor_id, ())
        arc, near, sigma = (None, 0.0, 0.0) if z.shape[0] == 0 else _arc_of(z, R, position)
        if arc is None:
            return Coverage.none(learned=True) if self.sweeping(sensor_id) else None
        if not _sweep_found((*arcs[-(SECTOR_WINDOW - 1) :], arc), self.sweeping(sensor_id)):
            return None
        boxes = [b for b in self._boxes.get(sensor_id, ()) if b is not None and b[5] is not None]
        far = float(np.max(np.hypot(*(z - np.asarray(position, dtype=float).reshape(1, 2)).T)))
        reach = max([far] + [b[5] for b in boxes])
        r = (1.0 + LEARN_RANGE_GROWTH) * reach + LEARN_SIGMAS * sigma
        margin = min(SECTOR_MAX_MARGIN, max(SECTOR_MARGIN, LEARN_SIGMAS * sigma / max(near, 1e-9)))
        start, width = arc
        return Coverage(
            polygon=_wedge(position, start - margin, width + 2.0 * margin, r),
            centre=np.asarray(position, dtype=float).reshape(2),
            max_range=max(r, 1e-9),
            learned=True,
        )

    def learn(
        self,
        sensor_id: str,
        t: float,
        z: np.ndarray,
        R: np.ndarray,
        position: np.ndarray | None = None,
    ) -> None:
        """Record a processed scan (``position``: its sensor's, if given)."""
        self._heard[sensor_id] = t
        self._heard.move_to_end(sensor_id)
        kept = self._boxes.get(sensor_id, ())[-(LEARN_SCANS - 1) :]
        self._boxes[sensor_id] = (*kept, self._box(z, R, position))
        arc = None
        if position is not None and z.shape[0]:
            arc = _arc_of(z, R, position)[0]
        self._set_arcs(sensor_id, (*self._arcs.get(sensor_id, ())[-(SECTOR_WINDOW - 1) :], arc))
        if position is not None:
            self._positions[sensor_id] = np.asarray(position, dtype=float).reshape(2).copy()
        while len(self._heard) > MAX_SENSORS:
            self._forget(next(iter(self._heard)))
        for sid in [sid for sid, last in self._heard.items() if t - last > FORGET_AFTER]:
            self._forget(sid)

    def _set_arcs(self, sensor_id: str, arcs: tuple[Arc, ...]) -> None:
        """Keep ``arcs`` (a sensor's last scans') and whether they are a sweep
        (:func:`_sweep_found`)."""
        self._arcs[sensor_id] = arcs
        self._wide[sensor_id] = wide = _wide_arcs(arcs[-LEARN_SCANS:])
        was = self._sweeping.get(sensor_id, False)
        self._sweeping[sensor_id] = wide <= 1 and _sweep_found(arcs, was)

    def _forget(self, sensor_id: str) -> None:
        """Drop all that is known of ``sensor_id``."""
        del self._heard[sensor_id]
        self._boxes.pop(sensor_id, None)
        self._positions.pop(sensor_id, None)
        self._arcs.pop(sensor_id, None)
        self._wide.pop(sensor_id, None)
        self._sweeping.pop(sensor_id, None)

    def snapshot(self) -> LearnerSnapshot:
        """What the learner knows now, immutable (its boxes are shared, not copied)."""
        return tuple(
            (
                sid,
                t,
                self._boxes.get(sid, ()),
                self._arcs.get(sid, ()),
                self._sweeping.get(sid, False),
            )
            for sid, t in self._heard.items()
        )

    @staticmethod
    def export(snapshot: LearnerSnapshot) -> dict[str, Any]:
        """``snapshot`` as plain JSON values: ``{"sensors": [{"id", "heard", "boxes",
        "arcs", "sweeping"}]}`` (``arcs``: ``[start, width]`` or null a scan, since
        2026-11-27; ``sweeping``, since 2026-11-27 too: a true or false)."""
        return {
            "sensors": [
                {
                    "id": sid,
                    "heard": t,
                    "boxes": [None if b is None else list(b) for b in boxes],
                    "arcs": [None if a is None else list(a) for a in arcs],
                    "sweeping": sweeping,
                }
                for sid, t, boxes, arcs, sweeping in snapshot
            ]
        }

    @classmethod
    def restored(cls, values: Any) -> CoverageLearner:
        """A learner knowing what :meth:`export` wrote; ``ValueError`` naming what is wrong
        with anything else (nothing is half restored)."""
        sensors = values.get("sensors") if isinstance(values, dict) else None
        if not isinstance(sensors, list) or len(sensors) > MAX_SENSORS:
            raise ValueError(f"coverage: 'sensors' must be a list of at most {MAX_SENSORS}")
        out = cls()
        for k, entry in enumerate(sensors):
            where = f"coverage.sensors[{k}]"
            if not isinstance(entry, dict) or not isinstance(entry.get("id"), str):
                raise ValueError(f"{where}: an object with a string 'id'")
            t, boxes = entry.get("heard"), entry.get("boxes")
            if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
                raise ValueError(f"{where}.heard: a finite number")
            if not isinstance(boxes, list) or len(boxes) > LEARN_SCANS:
                raise ValueError(f"{where}.boxes: a list of at most {LEARN_SCANS}")
            read: list[Box] = []
            for b in boxes:
                if b is None:
                    read.append(None)
                    continue
                # [x0, y0, x1, y1, sigma], and the range reached (or null) since 2026-11-27
                ok = isinstance(b, list) and len(b) in (5, 6) and all(map(_finite, b[:5]))
                reach = b[5] if ok and len(b) == 6 else None
                ok = ok and (reach is None or (_finite(reach) and reach >= 0))
                if not ok or b[0] > b[2] or b[1] > b[3] or b[4] < 0:
                    raise ValueError(
                        f"{where}.boxes: [x0, y0, x1, y1, sigma, range or null] or null each"
                    )
                read.append(
                    (
                        float(b[0]),
                        float(b[1]),
                        float(b[2]),
                        float(b[3]),
                        float(b[4]),
                        None if reach is None else float(reach),
                    )
                )
            arcs = entry.get("arcs", [])  # none in a file written before 2026-11-27
            if not isinstance(arcs, list) or len(arcs) > SECTOR_WINDOW:
                raise ValueError(f"{where}.arcs: a list of at most {SECTOR_WINDOW}")
            arcs_read: list[Arc] = []
            for a in arcs:
                ok = a is None or (
                    isinstance(a, list)
                    and len(a) == 2
                    and all(map(_finite, a))
                    and 0.0 <= a[1] <= 2.0 * math.pi
                )
                if not ok:
                    raise ValueError(f"{where}.arcs: [start, width] (rad) or null each")
                arcs_read.append(None if a is None else (float(a[0]), float(a[1])))
            sweeping = entry.get("sweeping", False)  # none before 2026-11-27: found afresh
            if not isinstance(sweeping, bool):
                raise ValueError(f"{where}.sweeping: true or false")
            if entry["id"] in out._heard:
                raise ValueError(f"{where}.id: {entry['id']!r} twice")
            out._heard[entry["id"]] = float(t)
            out._boxes[entry["id"]] = tuple(read)
            out._sweeping[entry["id"]] = sweeping
            out._set_arcs(entry["id"], tuple(arcs_read))
        return out
