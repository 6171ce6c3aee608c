"""A clutter map: the false-alarm density of each area, learned from a sensor's own scans.

A track score weighs each detection against the false-alarm density λ_fa where it fell
(``ln(P_D g / λ_fa)``). A batch may state one density; clutter is rarely uniform, though (sea
clutter near a coastal radar, ground clutter near a radar site), and a newcomer states none,
so that the configured ``track_management.clutter_density`` (1e-6 per m²) stands for the whole
picture: ten times too low near the coast (false tracks) or a hundred times too high far out
(a turning boat's detection loses to the clutter hypothesis and its track breaks).

For scans that state no density, each sensor gets a grid of square cells of side
:data:`CELL_SIGMAS` times the median position standard deviation of its first detections.
Each cell counts the detections that no confirmed track took or had in its gate and no track
of three or more detections took (what the pipeline passes to :meth:`ClutterMap.learn`), with
exponential forgetting over about :data:`MEMORY_SCANS` of the sensor's scans, and its density
is the posterior mean of a Poisson rate with a gamma prior whose weight is :data:`PRIOR_SCANS`
scans and whose mean λ₀ is the scene's: the density of all the sensor's counts ``C`` over the
box ``A_s`` that those of its last :data:`SCENE_SCANS` scans span (the median of their
boxes, grown by a cell), the
configured density ``λ_c`` weighing :data:`SCENE_PRIOR_SCANS` scans of it, times
:data:`SCENE_MARGIN` and no more than ``λ_c``:

    λ₀ = min(λ_c, m (λ_c A_s β_s + C) / ((β_s + E) A_s)),
    λ̂ = max((α₀ + c) / ((β₀ + E) A), λ_c β₀ / (β₀ + MEMORY_SCANS)),
    α₀ = λ₀ A β₀,   β₀ = PRIOR_SCANS,

``c`` the cell's decayed count, ``E = Σ_k γ^k`` the decayed number of scans (the same for
every cell: a scan looks at all of them), ``A`` the cell's area and ``γ = 1 − 1/MEMORY_SCANS``.
A new sensor's map is the configured density everywhere; it moves towards the counts as scans
come. The scene's density is known after a scan or two where a cell's own counts take some
50 scans: a newcomer's sparse clutter (70 times below the configured density) no longer
delays the first tracks. The margin and the ceiling keep the cells' prior on the safe side
where clutter is dense (there the configured density stands, as before). The floor keeps a
long-quiet area at a 51st of the configured density or more, so that a new false alarm
there is not a near-certain target.
A target's detections are counted until its track holds three of them; then the map takes
its first two back (:meth:`ClutterMap.reclaim`) and holds them with the rest, as below, where
they are about all that their cell and the eight around it have seen: at most
:data:`RECLAIM_RATE` other detections a look (the track's third is its own too). It knows
the detections of the last :data:`COUNTED_BATCHES` batches it learned from (all sensors'
together, no more than :data:`COUNTED_POINTS` detections) and those its sweeps gather; a
track's first detection counted before that is left counted. Before, a slow target present
from a sensor's first scans read as clutter ten to a thousand times the scene's in its own
cell until it left the cell, and so confirmed late: in a clean scene, parked to 15 m/s,
at the 5th to 10th scan of a 4 s radar (4 seeds, a mean of 6.3), the 4th to 6th now (5.0).

A radar that reports its turn sector by sector (batches stating a sector of their own as
``coverage``, or found to stream sectors without saying so:
:meth:`~trackers.coverage.CoverageLearner.sweeping`) looks at each cell once a turn, not at
every batch: its sectors' clutter detections are gathered (:meth:`ClutterMap.learn_sector`)
until the sweep comes round, and then learned as one scan.

Detections held back: those a tentative track of three or more detections took are held
(:meth:`ClutterMap.hold`) until the track's fate is known (:meth:`ClutterMap.settle`). If
the sequential test deletes it as no target, they were false alarms and count then, in
their cells and at their own scans' weight ``γ^age``; if it is confirmed, continues a
confirmed track, or loses to a rival reading of its start, they are dropped. A detection
two tracks took (siblings) counts once, when its last holder goes, and only if none of them
was accepted. Without this, a patch of clutter denser than the map believes fed itself: the
tracks it started took its detections, so the map never learned it (a newcomer's coastal
radars: 5-10 false alarms a scan in 500 m x 500 m of sea, 4.4-7.0 false tracks a scan,
the map reading a thirtieth of the density). The held-back detections of tracks that go
without a verdict (handed over, taken by a peer, coasted out of view) are forgotten, as are
those waiting longer than :data:`HELD_SCANS` scans of their sensor, or of a sensor whose map
was started afresh, and the oldest beyond :data:`MAX_HELD`.
"""

from __future__ import annotations

import bisect
import itertools
from collections import OrderedDict, deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from trackers.association.gating import position_noise

__all__ = [
    "AROUND_CELLS",
    "CELL_SIGMAS",
    "COUNTED_BATCHES",
    "COUNTED_POINTS",
    "HELD_SCANS",
    "MAX_CELLS",
    "MAX_HELD",
    "MAX_SENSORS",
    "MEMORY_SCANS",
    "PRIOR_SCANS",
    "RECLAIM_RATE",
    "SCENE_MARGIN",
    "SCENE_PRIOR_SCANS",
    "SCENE_SCANS",
    "SWEEP_BATCHES",
    "SWEEP_BINS",
    "SWEEP_COMPLETE",
    "SWEEP_MAX_POINTS",
    "SWEEP_OVERLAP",
    "SWEEP_SHARE",
    "SWEEP_SPAN",
    "ClutterMap",
    "arc_bins",
]

#: A cell's side, in median position standard deviations of the sensor's detections.
CELL_SIGMAS = 20.0
#: The counts' memory, in scans of the sensor (forgetting factor γ = 1 − 1/MEMORY_SCANS).
MEMORY_SCANS = 100.0
#: The prior's weight, in scans.
PRIOR_SCANS = 2.0
#: The scene density's prior weight (the configured density), in scans of the whole area.
SCENE_PRIOR_SCANS = 0.02
#: The scene density stands for the configured one times this margin, no higher than it.
SCENE_MARGIN = 2.0
#: The scene's area is the box of the counted detections of this many of the sensor's last
#: scans that had any.
SCENE_SCANS = 32
#: A cell's side at least (m).
MIN_CELL = 1.0
#: A batch whose detections would set cells more than this many times finer or coarser than
#: a sensor's cells starts its map afresh.
RESIZE = 4.0
#: The most sensors with a map (beyond, the least recently heard is forgotten), and the most
#: cells a sensor's map keeps (beyond, its cells are made twice as wide, their counts
#: summed): a sender of many sensor ids or of detections strewn over a continent cannot grow
#: the maps past about MAX_SENSORS x MAX_CELLS x 32 bytes (134 MB).
MAX_SENSORS = 256
MAX_CELLS = 1 << 14
#: Cell indices are packed into one int64 key: ix · _STRIDE + iy, each within ±_STRIDE/2.
_STRIDE = 1 << 31

#: A held-back detection whose track has no fate after this many of its sensor's scans is
#: dropped (its weight would be below 5 %), ...
HELD_SCANS = 300
#: ... and so is the oldest beyond this many.
MAX_HELD = 1 << 15
#: The counted detections of the last COUNTED_BATCHES learned batches (and no more than
#: COUNTED_POINTS of them) are kept by serial number, for a track that proves a target's to
#: take its first two back (:meth:`ClutterMap.reclaim`).
COUNTED_BATCHES = 1024
COUNTED_POINTS = 1 << 16
#: A detection is taken back only if its cell and the eight around it saw besides the
#: track's own detections at most this many a scan (decayed count of all the sensor's
#: detections there over decayed scans): where a track's first two are about all that part
#: of the map ever saw. Where clutter is dense two counts less change little for one track,
#: but taken back from every young track there they hollowed the map out (600 false alarms
#: a scan in a 1.5 km square: 194 confirmed tracks); from a patch of clutter in its first
#: scans (a cell of it that by chance saw little), tracks confirmed there and then kept the
#: patch from the map.
RECLAIM_RATE = 0.05

#: Sectors of a revolution (batches that each looked at an arc of bearings about their
#: sensor) are gathered until the sweep comes round: a batch whose arc overlaps by more than
#: SWEEP_OVERLAP the arcs gathered since the last look (but for the previous batch's), when
#: these cover at least SWEEP_COMPLETE of the bearings the sensor's last SWEEP_BATCHES
#: batches looked at and at least SWEEP_SPAN, none of them more than SWEEP_SHARE of it,
#: makes them one look at every cell; otherwise (a camera panning) they are dropped. The
#: arcs are kept in SWEEP_BINS bins of bearing; at most SWEEP_MAX_POINTS detections wait.
SWEEP_OVERLAP = 0.25
SWEEP_COMPLETE = 0.9
SWEEP_BATCHES = 32
SWEEP_BINS = 360
SWEEP_SPAN = 60
SWEEP_SHARE = 0.4
SWEEP_MAX_POINTS = 1 << 14

_GAMMA = 1.0 - 1.0 / MEMORY_SCANS
_GRID_NUMBERS = itertools.count()


@dataclass
class _Sweep:
    """One sensor's sectors since its last look: the bins of bearing they covered
    (``gathered``), their clutter detections (``waiting``, one array a batch) and the last
    non-empty batch's covariances; and the bins of its last :data:`SWEEP_BATCHES` batches."""

    gathered: np.ndarray = field(default_factory=lambda: np.zeros(SWEEP_BINS, dtype=bool))
    waiting: list[np.ndarray] = field(default_factory=list)
    #: the serial numbers of ``waiting``'s detections, one array a batch (−1: none given)
    serials: list[np.ndarray] = field(default_factory=list)
    #: all the detections of the batches gathered, one array a batch, each of them standing
    #: for ``seen_weight`` of its batch's (1, or more once thinned: at most
    #: SWEEP_MAX_POINTS are kept)
    seen: list[np.ndarray] = field(default_factory=list)
    seen_weight: list[float] = field(default_factory=list)
    seen_points: int = 0
    #: the first serial of each batch of ``waiting`` that has any (ascending) and the batch
    firsts: list[int] = field(default_factory=list)
    batches: list[int] = field(default_factory=list)
    points: int = 0
    #: the most bins one gathered batch covered
    widest: int = 0
    R: np.ndarray | None = None
    recent: deque[np.ndarray] = field(default_factory=lambda: deque(maxlen=SWEEP_BATCHES))
    #: the previous batch's bins, and the arc of its detections (``swept`` batches)
    last: np.ndarray = field(default_factory=lambda: np.zeros(SWEEP_BINS, dtype=bool))
    arc: tuple[float, float] | None = None

    def restart(self) -> None:
        """Gather afresh (a look learned, or a sweep that never came round)."""
        self.gathered[:] = False
        self.waiting, self.serials, self.firsts, self.batches = [], [], [], []
        self.seen, self.seen_weight, self.seen_points = [], [], 0
        self.points, self.widest = 0, 0

    def add_seen(self, z: np.ndarray) -> None:
        """Gather a batch's detections; beyond SWEEP_MAX_POINTS every other one of those
        gathered is kept, standing for twice as many."""
        self.seen.append(z)
        self.seen_weight.append(1.0)
        self.seen_points += z.shape[0]
        while self.seen_points > SWEEP_MAX_POINTS:
            self.seen = [w[::2] for w in self.seen]
            self.seen_weight = [2.0 * w for w in self.seen_weight]
            self.seen_points = sum(len(w) for w in self.seen)

    def seen_in(self, grid: _Grid, block: np.ndarray) -> float:
        """How many of the detections gathered lie in the cells ``block`` of ``grid``."""
        return sum(
            w * int(np.isin(grid.cells(z), block).sum())
            for z, w in zip(self.seen, self.seen_weight, strict=True)
            if len(z)
        )

    def find(self, serial: int) -> tuple[int, int] | None:
        """The batch and row of waiting detection ``serial``, or ``None``."""
        k = bisect.bisect_right(self.firsts, serial) - 1
        if k < 0:
            return None
        b = self.batches[k]
        numbers = self.serials[b]
        i = int(np.searchsorted(numbers, serial))
        if i < numbers.size and numbers[i] == serial:
            return b, i
        return None


def _swept(before: tuple[float, float], now: tuple[float, float]) -> tuple[float, float]:
    """The arc the sweep passed over from the arc ``before`` to ``now`` (``(start, width)``,
    rad), turning whichever way is shorter, less than half a turn; ``now`` when neither."""
    s0, w0 = before
    s1, w1 = now
    ahead = (s1 - (s0 + w0)) % (2.0 * np.pi)  # from the end of ``before`` to ``now``
    behind = (s0 - (s1 + w1)) % (2.0 * np.pi)  # from the end of ``now`` to ``before``
    if ahead <= behind and ahead < np.pi:
        return s0 + w0, ahead + w1
    if behind < np.pi:
        return s1, w1 + behind
    return now


def arc_bins(start: float, width: float) -> np.ndarray:
    """The :data:`SWEEP_BINS` bins of bearing that the arc from ``start`` over ``width``
    (rad) touches, as a mask."""
    step = 2.0 * np.pi / SWEEP_BINS
    first = int(np.floor(start / step))
    n = min(SWEEP_BINS, int(np.floor((start + width) / step)) - first + 1)
    out = np.zeros(SWEEP_BINS, dtype=bool)
    out[np.mod(np.arange(first, first + n), SWEEP_BINS)] = True
    return out


@dataclass
class _Counted:
    """The detections one :meth:`ClutterMap.learn` counted for a sensor: their ``serials``
    (ascending), positions ``z``, the number of the grid (:attr:`_Grid.number`; the grid
    itself is not kept: a forgotten one is let go) and its scan number they were counted in,
    and which of them are still counted (``alive``: not taken back)."""

    sensor_id: str
    grid: int
    scan: int
    serials: np.ndarray
    z: np.ndarray
    alive: np.ndarray


@dataclass
class _Found:
    """Where the map holds detection ``serial``, one it counted (``record`` row ``i``) or
    gathers for a sweep (``sweep`` batch ``batch``): its grid and cell ``key``, the weight
    it counts with now and how many detections its cell and the eight around it have seen
    (decayed; those of the sweep's gathered batches included)."""

    serial: int
    sensor_id: str
    grid: _Grid
    key: int
    weight: float
    seen: float
    record: _Counted | None
    i: int
    sweep: _Sweep | None
    batch: int

    def take(self) -> list:
        """Take it out of its cell (or sweep): the held-back entry it becomes."""
        grid = self.grid
        if self.record is not None:
            rec = self.record
            rec.alive[self.i] = False
            x, y = rec.z[self.i].tolist()
            rows, found = grid.find(np.array([self.key], dtype=np.int64))
            if found[0]:
                r = rows[:1]
                grid.seen[r] = grid.decayed_seen(r)
                grid.counts[r] = np.maximum(0.0, grid.decayed(r) - self.weight)
                grid.stamps[r] = grid.scans
            grid.total = max(0.0, grid.total - self.weight)
            return [self.sensor_id, x, y, rec.scan, grid, 0]
        sweep = self.sweep
        assert sweep is not None
        i = int(np.flatnonzero(sweep.serials[self.batch] == self.serial)[0])
        x, y = sweep.waiting[self.batch][i].tolist()
        sweep.waiting[self.batch] = np.delete(sweep.waiting[self.batch], i, axis=0)
        sweep.serials[self.batch] = np.delete(sweep.serials[self.batch], i)
        # (counted, it would have been at the sweep's look, a scan from now)
        return [self.sensor_id, x, y, grid.scans, grid, 0]


def _around(key: int) -> np.ndarray:
    """The packed keys of cell ``key`` and the eight around it."""
    return (key + _NEIGHBOURS).astype(np.int64)


def _block(k: int) -> np.ndarray:
    """The ``ix · _STRIDE + iy`` offsets of the (2k + 1)² cells centred on a cell, row by row."""
    steps = range(-k, k + 1)
    return np.array([dx * _STRIDE + dy for dx in steps for dy in steps], dtype=np.int64)


#: a cell's 3 x 3 block
_NEIGHBOURS = _block(1)

#: The block of cells about a position whose density :meth:`ClutterMap.around` reads: the
#: (2k + 1)² cells centred on its own, k = AROUND_CELLS (7 x 7 cells, 140 position standard
#: deviations across while the cells keep the side the sensor's first detections set).
AROUND_CELLS = 3
_BLOCK = _block(AROUND_CELLS)


def _block_seen(grid: _Grid, key: int) -> float:
    """The decayed count of all detections in cell ``key`` and the eight around it now."""
    rows, found = grid.find(_around(key))
    return float(grid.decayed_seen(rows[found]).sum())


@dataclass
class _Grid:
    """One sensor's counts: ``keys`` (sorted packed cell indices), ``counts`` decayed to
    scan ``stamps`` (the sensor's scan number when each was last brought up to date),
    ``cell`` the side (m), ``scans`` the sensor's scans counted and ``base`` the side its
    detections set; ``seen`` the cells' decayed counts of all the sensor's detections,
    targets' included, likewise (what :meth:`ClutterMap.reclaim` asks)."""

    cell: float
    keys: np.ndarray
    counts: np.ndarray
    stamps: np.ndarray
    seen: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: a number no other grid of the map's process has
    number: int = field(default_factory=lambda: next(_GRID_NUMBERS))
    scans: int = 0
    #: the side the sensor's detections set (``cell`` grows from it when cells are merged)
    base: float = 0.0
    #: the decayed count of all cells, as of scan ``scans``
    total: float = 0.0
    #: the box ``(x0, y0, x1, y1)`` of the counted detections of each of the last
    #: :data:`SCENE_SCANS` scans that had any
    boxes: deque[tuple[float, float, float, float]] = field(
        default_factory=lambda: deque(maxlen=SCENE_SCANS)
    )

    def exposure(self) -> float:
        """``E = Σ_{k<n} γ^k`` over the ``n`` scans counted."""
        return (1.0 - _GAMMA**self.scans) / (1.0 - _GAMMA)

    def scene_rate(self, prior: float) -> float | None:
        """``λ̄``, the density of the whole area the sensor's counted detections span (the
        median of :attr:`boxes`, grown by a cell), with the configured ``prior`` weighing
        :data:`SCENE_PRIOR_SCANS` scans of it; ``None`` before any count."""
        if not self.boxes:
            return None
        # the median of the scans' boxes: one far false alarm (or a target's detection) does
        # not make the whole scene that wide
        x0, y0, x1, y1 = np.median(np.array(self.boxes), axis=0).tolist()
        area = (x1 - x0 + self.cell) * (y1 - y0 + self.cell)
        return (prior * area * SCENE_PRIOR_SCANS + self.total) / (
            (SCENE_PRIOR_SCANS + self.exposure()) * area
        )

    def cells(self, z: np.ndarray, margin: int = 0) -> np.ndarray:
        """The packed keys of the cells of positions ``z (n, 2)``, their indices clipped
        ``margin`` cells inside the packing's bounds (room for a block of cells about them)."""
        ij = np.floor(z / self.cell).astype(np.int64)
        bound = _STRIDE // 2 - 1 - margin
        np.clip(ij, -bound, bound, out=ij)
        return ij[:, 0] * _STRIDE + ij[:, 1]

    def counts_at(self, keys: np.ndarray) -> np.ndarray:
        """The decayed counts of the cells ``keys`` now (0 for a cell the grid lacks)."""
        rows, found = self.find(keys)
        counts = np.zeros(keys.size)
        if found.any():
            counts[found] = self.decayed(rows[found])
        return counts

    def find(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For packed cell ``keys``, the row of each in the grid (clipped into it) and whether
        the grid has that cell."""
        rows = np.minimum(np.searchsorted(self.keys, keys), max(self.keys.size - 1, 0))
        if self.keys.size == 0:
            return rows, np.zeros(keys.size, dtype=bool)
        return rows, self.keys[rows] == keys

    def decayed(self, idx: np.ndarray) -> np.ndarray:
        """The counts of rows ``idx`` of the grid brought to now."""
        return self.counts[idx] * _GAMMA ** (self.scans - self.stamps[idx])

    def decayed_seen(self, idx: np.ndarray) -> np.ndarray:
        """The ``seen`` counts of rows ``idx`` brought to now."""
        return self.seen[idx] * _GAMMA ** (self.scans - self.stamps[idx])

    def add(self, keys: np.ndarray, weights: np.ndarray, seen: np.ndarray | None = None) -> None:
        """Add ``weights`` (as of now) to the counts of the cells of the distinct packed
        ``keys`` and ``seen`` (none if not given) to their ``seen``, new cells included;
        too many cells then, and four become one (their counts summed), as often as
        needed."""
        if seen is None:
            seen = np.zeros(keys.size)
        rows, old = self.find(keys)
        if old.any():
            rows = rows[old]
            self.seen[rows] = self.decayed_seen(rows) + seen[old]
            self.counts[rows] = self.decayed(rows) + weights[old]
            self.stamps[rows] = self.scans
        new = ~old
        if new.any():
            merged = np.concatenate([self.keys, keys[new]])
            order = np.argsort(merged, kind="stable")
            self.keys = merged[order]
            self.counts = np.concatenate([self.counts, weights[new]])[order]
            self.seen = np.concatenate([self.seen, seen[new]])[order]
            self.stamps = np.concatenate(
                [self.stamps, np.full(int(new.sum()), self.scans, dtype=np.int64)]
            )[order]
        while self.keys.size > MAX_CELLS:
            _coarsen(self)


def _coarsen(grid: _Grid) -> None:
    """The grid with cells twice as wide: each new cell's count is the sum of the four it
    covers, brought to now."""
    counts = grid.decayed(np.arange(grid.keys.size))
    seen = grid.decayed_seen(np.arange(grid.keys.size))
    iy = _unpack_iy(grid.keys)
    ix = (grid.keys - iy) // _STRIDE
    keys = np.floor_divide(ix, 2) * _STRIDE + np.floor_divide(iy, 2)
    merged, inverse = np.unique(keys, return_inverse=True)
    grid.keys = merged
    grid.counts = np.bincount(inverse, weights=counts, minlength=merged.size)
    grid.seen = np.bincount(inverse, weights=seen, minlength=merged.size)
    grid.stamps = np.full(merged.size, grid.scans, dtype=np.int64)
    grid.cell *= 2.0


def _unpack_iy(keys: np.ndarray) -> np.ndarray:
    """The iy of packed keys ``ix · _STRIDE + iy`` with ``|iy| < _STRIDE / 2``."""
    iy = np.mod(keys, _STRIDE)
    return np.where(iy >= _STRIDE // 2, iy - _STRIDE, iy)


class ClutterMap:
    """The learned clutter density of each sensor's scans (module docstring). :meth:`density`
    reads without changing anything; :meth:`learn` records a processed scan."""

    def __init__(self) -> None:
        self._grids: OrderedDict[str, _Grid] = OrderedDict()  # least recently heard first
        # Held-back detections by serial: [sensor, x, y, the sensor's scan number, its grid,
        # holders left], oldest first; and each holder's serials.
        self._held: dict[int, list] = {}
        self._holding: dict[str, list[int]] = {}
        self._settled = 0
        # each sweeping sensor's sectors since its last look, least recently heard first
        self._sweeps: OrderedDict[str, _Sweep] = OrderedDict()
        # the detections the last learned batches counted (oldest first), and each one's
        # batch and row by serial
        self._counted: deque[_Counted] = deque()
        self._counted_points = 0
        self._by_serial: dict[int, tuple[_Counted, int]] = {}

    @staticmethod
    def _cell_side(R: np.ndarray) -> float:
        return max(MIN_CELL, CELL_SIGMAS * (position_noise(R) or 0.0))  # R is never empty

    def density(self, sensor_id: str, z: np.ndarray, prior: float) -> np.ndarray:
        """``λ̂`` (per m²) at each of the positions ``z (n, 2)`` for the sensor's next scan,
        with the configured density ``prior``; ``prior`` everywhere for a sensor not seen."""
        return self.read(sensor_id, z, prior)[0]

    def read(self, sensor_id: str, z: np.ndarray, prior: float) -> tuple[np.ndarray, float | None]:
        """:meth:`density` at ``z``, and the false-alarm density of ``sensor_id``'s whole
        scene (per m²): all its counted detections over the box they span
        (:meth:`_Grid.scene_rate`; ``None`` for a sensor with none yet), not capped by the
        configured ``prior`` as the cells' prior mean ``λ₀`` is (:data:`SCENE_MARGIN` times
        it, no more than ``prior``: module docstring). The scene's is found once for both."""
        z = np.asarray(z, dtype=float).reshape(-1, 2)
        grid = self._grids.get(sensor_id)
        rate = None if grid is None else grid.scene_rate(prior)
        if grid is None or grid.scans == 0 or z.shape[0] == 0:
            return np.full(z.shape[0], prior), rate
        area = grid.cell * grid.cell
        lam0 = prior if rate is None else min(SCENE_MARGIN * rate, prior)
        alpha0 = lam0 * area * PRIOR_SCANS
        counts = grid.counts_at(grid.cells(z))
        lam = (alpha0 + counts) / ((PRIOR_SCANS + grid.exposure()) * area)
        return np.maximum(lam, prior * PRIOR_SCANS / (PRIOR_SCANS + MEMORY_SCANS)), rate

    def around(self, sensor_id: str, z: np.ndarray, prior: float) -> np.ndarray:
        """``λ̄`` (per m²) about each of the positions ``z (m, 2)``: the density of the block
        of ``B`` = (2k + 1)² cells centred on its cell (k = :data:`AROUND_CELLS`), its prior
        the scene's density ``λ_s`` (:meth:`_Grid.scene_rate`) with the cells' weight:

            λ̄ = (λ_s B A β₀ + Σ_b c_b) / ((β₀ + E) B A),

        ``c_b`` the decayed counts of the block's cells, ``A`` a cell's area. Unlike a cell's
        density (:meth:`read`) it has neither the margin nor the floor on its prior: where
        the clutter is as dense as the scene's it reads the scene's, not more. The clutter a
        group of detections must stand out from: a patch of backwash a few cells wide is
        many times denser than the block about it, a cluster of sea clutter near a coastal
        radar is not (the scene's density, over tens of kilometres, is a hundred times lower
        there). ``prior`` for a sensor not seen or with no count yet."""
        z = np.asarray(z, dtype=float).reshape(-1, 2)
        grid = self._grids.get(sensor_id)
        rate = None if grid is None else grid.scene_rate(prior)
        if grid is None or rate is None or z.shape[0] == 0:
            return np.full(z.shape[0], prior)
        area = grid.cell * grid.cell * _BLOCK.size
        keys = (grid.cells(z, AROUND_CELLS)[:, None] + _BLOCK[None, :]).ravel()
        sums = grid.counts_at(keys).reshape(z.shape[0], _BLOCK.size).sum(axis=1)
        return (rate * area * PRIOR_SCANS + sums) / ((PRIOR_SCANS + grid.exposure()) * area)

    def learn(
        self,
        sensor_id: str,
        z_clutter: np.ndarray,
        R: np.ndarray,
        serials: np.ndarray | None = None,
        z_seen: np.ndarray | None = None,
        seen_weights: np.ndarray | None = None,
    ) -> None:
        """Record one processed scan of ``sensor_id``: ``z_clutter`` the detections taken for
        clutter (module docstring), ``R`` the covariances of all of the scan's
        detections (to size a new sensor's cells; a sensor is not counted before it has sent
        a detection), ``serials`` the tracker's serial numbers of ``z_clutter``'s rows,
        ascending (−1: none), by which :meth:`reclaim` may take them back, and ``z_seen``
        all of the scan's detections (``z_clutter`` if not given), each standing for
        ``seen_weights`` of them (1 if not given)."""
        grid = self._grids.get(sensor_id)
        if np.shape(R)[0]:
            side = self._cell_side(np.asarray(R, dtype=float))
            # a sensor's first detections set its cells; detections a lot finer or coarser
            # than those (another mode, a first batch of a different kind) start it afresh
            if grid is not None and not grid.base / RESIZE <= side <= grid.base * RESIZE:
                grid = None
        if grid is None:
            if np.shape(R)[0] == 0:
                return
            grid = _Grid(
                cell=side,
                keys=np.zeros(0, dtype=np.int64),
                counts=np.zeros(0),
                stamps=np.zeros(0, dtype=np.int64),
                base=side,
            )
            self._grids[sensor_id] = grid
            while len(self._grids) > MAX_SENSORS:
                self._grids.popitem(last=False)
        self._grids.move_to_end(sensor_id)
        grid.scans += 1
        grid.total *= _GAMMA
        z = np.asarray(z_clutter, dtype=float).reshape(-1, 2)
        seen = z if z_seen is None else np.asarray(z_seen, dtype=float).reshape(-1, 2)
        if seen.shape[0]:
            # of scan number ``scans``: they count in full
            cells = np.concatenate([grid.cells(z), grid.cells(seen)])
            keys, inverse = np.unique(cells, return_inverse=True)
            inverse = inverse.ravel()
            n = keys.size
            grid.add(
                keys,
                np.bincount(inverse[: z.shape[0]], minlength=n).astype(float),
                np.bincount(inverse[z.shape[0] :], weights=seen_weights, minlength=n).astype(float),
            )
        if z.shape[0]:
            grid.total += z.shape[0]
            lo, hi = z.min(axis=0), z.max(axis=0)
            grid.boxes.append((float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])))
            if serials is not None:
                self._remember(sensor_id, grid, z, np.asarray(serials, dtype=np.int64))
        # Cells whose counts have decayed to nothing are dropped now and then.
        if grid.scans % int(MEMORY_SCANS) == 0 and grid.keys.size:
            every = np.arange(grid.keys.size)
            live = np.maximum(grid.decayed(every), grid.decayed_seen(every)) > 1e-3
            grid.keys, grid.counts, grid.seen, grid.stamps = (
                grid.keys[live],
                grid.counts[live],
                grid.seen[live],
                grid.stamps[live],
            )

    def learn_sector(
        self,
        sensor_id: str,
        start: float,
        width: float,
        z_clutter: np.ndarray,
        R: np.ndarray,
        *,
        swept: bool = False,
        serials: np.ndarray | None = None,
        z_seen: np.ndarray | None = None,
    ) -> bool:
        """Record one processed batch of ``sensor_id`` that looked at the arc of bearings
        from ``start`` over ``width`` (rad) about the sensor (a sector of its revolution),
        ``z_clutter`` and ``R`` as :meth:`learn` takes them; ``swept``: the arc is that of
        the batch's detections, and the sweep passed over the bearings between the previous
        batch's and it too. The sectors are gathered until the sweep comes round
        (:data:`SWEEP_OVERLAP`, :data:`SWEEP_COMPLETE`, :data:`SWEEP_SPAN`,
        :data:`SWEEP_SHARE`), then learned as one scan; ``serials`` and ``z_seen`` as
        :meth:`learn` takes them. Returns whether that happened now."""
        sweep = self._sweeps.pop(sensor_id, None) or _Sweep()
        self._sweeps[sensor_id] = sweep
        while len(self._sweeps) > MAX_SENSORS:
            self._sweeps.popitem(last=False)
        own = (start, width)
        if swept and sweep.arc is not None:
            start, width = _swept(sweep.arc, own)
        sweep.arc = own if swept else None
        bins = arc_bins(start, width)
        sweep.recent.append(bins)
        learned = False
        earlier = sweep.gathered & ~sweep.last
        if np.count_nonzero(bins & earlier) > SWEEP_OVERLAP * np.count_nonzero(bins):
            looked = np.logical_or.reduce(np.array(sweep.recent))
            span = np.count_nonzero(sweep.gathered)
            complete = (
                np.count_nonzero(sweep.gathered & looked)
                >= SWEEP_COMPLETE * np.count_nonzero(looked)
                and span >= SWEEP_SPAN
                and sweep.widest <= SWEEP_SHARE * span
            )
            if complete and sweep.R is not None:
                z = np.concatenate(sweep.waiting) if sweep.waiting else np.zeros((0, 2))
                numbers = np.concatenate(sweep.serials) if sweep.serials else np.zeros(0, np.int64)
                seen = np.concatenate(sweep.seen) if sweep.seen else np.zeros((0, 2))
                weights = np.repeat(sweep.seen_weight, [len(w) for w in sweep.seen])
                self.learn(sensor_id, z, sweep.R, numbers, seen, weights)
                learned = True
            sweep.restart()
        z = np.asarray(z_clutter, dtype=float).reshape(-1, 2)
        seen = z if z_seen is None else np.asarray(z_seen, dtype=float).reshape(-1, 2)
        if sweep.points + z.shape[0] > SWEEP_MAX_POINTS:  # a sweep that never comes round
            sweep.restart()
        sweep.gathered |= bins
        sweep.last = bins
        sweep.widest = max(sweep.widest, int(np.count_nonzero(bins)))
        numbers = (
            np.full(z.shape[0], -1, dtype=np.int64)
            if serials is None
            else np.asarray(serials, dtype=np.int64).reshape(z.shape[0])
        )
        if z.shape[0]:  # (a heartbeat adds nothing to the lists)
            if (numbers >= 0).any():
                sweep.firsts.append(int(numbers[numbers >= 0].min()))
                sweep.batches.append(len(sweep.waiting))
            sweep.waiting.append(z)
            sweep.serials.append(numbers)
            sweep.points += z.shape[0]
        if seen.shape[0]:
            sweep.add_seen(seen)
        if np.shape(R)[0]:
            sweep.R = np.asarray(R, dtype=float)[:256].copy()  # (its noise sizes the cells)
        return learned

    def hold(
        self,
        sensor_id: str,
        z: np.ndarray,
        holders: Sequence[str],
        serials: Sequence[int],
    ) -> None:
        """Hold back detections ``z (k, 2)`` of ``sensor_id``'s scan just learned from, taken
        by the tentative tracks ``holders`` (one id a row; a detection two tracks took comes
        twice, with one serial), until :meth:`settle` tells their fate (module docstring)."""
        grid = self._grids.get(sensor_id)
        if grid is None or not len(serials):
            return
        held, holding = self._held, self._holding
        for (x, y), holder, serial in zip(
            np.asarray(z, dtype=float).reshape(-1, 2).tolist(),
            holders,
            np.asarray(serials).tolist(),
            strict=True,
        ):
            entry = held.get(serial)
            if entry is None:
                held[serial] = entry = [sensor_id, x, y, grid.scans, grid, 0]
            entry[5] += 1
            holding.setdefault(holder, []).append(serial)
        self._trim_held()

    def _trim_held(self) -> None:
        held = self._held
        if len(held) > MAX_HELD:  # the oldest quarter goes at once (amortized O(1))
            self._held = dict(list(held.items())[len(held) - 3 * MAX_HELD // 4 :])
            self._prune_holding()

    def reclaim(
        self,
        serials: np.ndarray,
        holders: Sequence[str],
        thirds: tuple[str, np.ndarray, bool] | None = None,
    ) -> None:
        """Take back detections of earlier scans that the map counted (or gathers for a
        sweep) and hold them for the tracks ``holders`` (one a serial; a track's serials come
        together) as :meth:`hold` does, their cells less their weight ``γ^age``: the first
        two of a track that took its third (module docstring). Only where they are about all
        their cells saw: the detections their cell and the eight around it saw besides the
        track's own are at most :data:`RECLAIM_RATE` a look (:meth:`_Grid.exposure`).
        ``thirds`` says where the tracks' thirds lie, which the scan just seen added there:
        the sensor, their positions (one a serial) and whether its sweep gathered them
        rather than the map learned them; ``None``: the scan was not counted. A serial the
        map no longer knows (never counted, too old, its sensor's map started afresh) is
        passed over; one already held gains a holder."""
        held, holding = self._held, self._holding
        numbers = np.asarray(serials).tolist()
        by_holder: dict[str, list[int]] = {}
        third_of: dict[str, np.ndarray] = {}
        for k, (serial, holder) in enumerate(zip(numbers, holders, strict=True)):
            if serial >= 0 and serial not in by_holder.setdefault(holder, []):
                by_holder[holder].append(serial)
            if thirds is not None:
                third_of[holder] = thirds[1][k]
        for holder, own in by_holder.items():
            found = [(s, self._find(s)) for s in own if s not in held]
            found = [(s, f) for s, f in found if f is not None]
            # where the track's own detections lie, with their weights now: those found, those
            # a sibling holds already, and its third (in the cells it was counted in)
            mine = [(f.grid, f.key, f.weight, f.sweep is not None) for _, f in found]
            for s in own:
                e = held.get(s)
                grid = None if e is None else self._grids.get(e[0])
                if grid is not None and grid is e[4]:
                    key = int(grid.cells(np.array([e[1:3]]))[0])
                    mine.append((grid, key, _GAMMA ** (grid.scans - e[3]), False))
            if thirds is not None and holder in third_of:
                grid = self._grids.get(thirds[0])
                if grid is not None:
                    key = int(grid.cells(third_of[holder][None])[0])
                    mine.append((grid, key, 1.0, thirds[2]))
            for s, f in found:
                block = _around(f.key)
                own_here = sum(
                    w
                    for grid, key, w, waiting in mine
                    if grid is f.grid and key in block and (not waiting or f.sweep is not None)
                )
                if f.seen - own_here <= RECLAIM_RATE * f.grid.exposure():
                    held[s] = f.take()
            for s in own:
                entry = held.get(s)
                if entry is not None:
                    entry[5] += 1
                    holding.setdefault(holder, []).append(s)
        self._trim_held()

    def _find(self, serial: int) -> _Found | None:
        """Where the map counted (or gathers) detection ``serial``; ``None`` if it does not
        know it (any more)."""
        hit = self._by_serial.get(serial)
        if hit is not None:
            rec, i = hit
            grid = self._grids.get(rec.sensor_id)
            if not rec.alive[i] or grid is None or grid.number != rec.grid:
                return None
            key = int(grid.cells(rec.z[i : i + 1])[0])
            return _Found(
                serial,
                rec.sensor_id,
                grid,
                key,
                _GAMMA ** (grid.scans - rec.scan),
                _block_seen(grid, key),
                rec,
                i,
                None,
                -1,
            )
        for sensor_id, sweep in self._sweeps.items():
            where = sweep.find(serial)
            grid = self._grids.get(sensor_id)
            if where is None or grid is None:
                continue
            b, i = where
            key = int(grid.cells(sweep.waiting[b][i : i + 1])[0])
            seen = _block_seen(grid, key) + sweep.seen_in(grid, _around(key))
            return _Found(serial, sensor_id, grid, key, 1.0, seen, None, i, sweep, b)
        return None

    def _remember(self, sensor_id: str, grid: _Grid, z: np.ndarray, serials: np.ndarray) -> None:
        """Keep the serials of the detections just counted (:data:`COUNTED_BATCHES`)."""
        known = serials >= 0
        if not known.any():
            return
        order = np.argsort(serials[known], kind="stable")
        numbers = serials[known][order]
        self._counted.append(
            _Counted(
                sensor_id=sensor_id,
                grid=grid.number,
                scan=grid.scans,
                serials=numbers,
                z=z[known][order],
                alive=np.ones(numbers.size, dtype=bool),
            )
        )
        rec = self._counted[-1]
        self._by_serial.update((n, (rec, i)) for i, n in enumerate(numbers.tolist()))
        self._counted_points += numbers.size
        while len(self._counted) > COUNTED_BATCHES or self._counted_points > COUNTED_POINTS:
            old = self._counted.popleft()
            self._counted_points -= old.serials.size
            for n in old.serials.tolist():
                if self._by_serial.get(n, (None,))[0] is old:
                    del self._by_serial[n]

    def settle(self, accepted: Sequence[str], rejected: Sequence[str]) -> None:
        """The fates of tracks that held detections back: ``accepted`` (confirmed, continuing
        a confirmed track, a rival reading of a start that another took, or deleted for
        coasting while out of view: no verdict) drop theirs, ``rejected`` (deleted by the
        sequential test before confirmation, a losing rival too) release theirs, which count
        as false alarms once no track holds them (module docstring)."""
        held, holding = self._held, self._holding
        for holder in accepted:
            for serial in holding.pop(holder, ()):
                held.pop(serial, None)
        late: list[list] = []
        for holder in rejected:
            for serial in holding.pop(holder, ()):
                entry = held.get(serial)
                if entry is not None:
                    entry[5] -= 1
                    if entry[5] <= 0:
                        late.append(held.pop(serial))
        if late:
            self._count_late(late)
        self._settled += 1
        if self._settled % 64 == 0:
            self._drop_stale()

    def _count_late(self, entries: list[list]) -> None:
        """Count held-back detections in their cells, each weighted as of its scan; those
        of a sensor whose map was started afresh (or forgotten) since count nowhere."""
        for grid in {id(e[4]): e[4] for e in entries}.values():
            mine = [e for e in entries if e[4] is grid]
            if self._grids.get(mine[0][0]) is not grid:
                continue
            z = np.array([e[1:3] for e in mine])
            weights = _GAMMA ** (grid.scans - np.array([e[3] for e in mine], dtype=float))
            keys, inverse = np.unique(grid.cells(z), return_inverse=True)
            grid.add(keys, np.bincount(inverse.ravel(), weights=weights, minlength=keys.size))
            grid.total += float(weights.sum())

    def forget(self, sensor_id: str) -> None:
        """Start ``sensor_id``'s map afresh (what it looks at changed: the cells it no longer
        looks at would otherwise be counted as looked at and empty)."""
        self._sweeps.pop(sensor_id, None)
        if self._grids.pop(sensor_id, None) is not None:
            self._drop_stale()

    def forget_held(self) -> None:
        """Drop every held-back detection (the tracks that held them are gone: a state
        restored), and the serials of the counted ones (a restored tracker numbers
        detections afresh)."""
        self._held, self._holding = {}, {}
        self._counted.clear()
        self._counted_points = 0
        self._by_serial = {}
        for sweep in self._sweeps.values():
            sweep.serials = [np.full(len(z), -1, dtype=np.int64) for z in sweep.waiting]
            sweep.firsts, sweep.batches = [], []

    def _drop_stale(self) -> None:
        """Forget held-back detections older than :data:`HELD_SCANS` of their sensor's
        scans or of a sensor whose map was started afresh or forgotten since, and the
        holders left with none."""
        held, grids = self._held, self._grids
        stale = [
            s
            for s, e in held.items()
            if grids.get(e[0]) is not e[4] or e[4].scans - e[3] > HELD_SCANS
        ]
        for serial in stale:
            del held[serial]
        self._prune_holding()

    def _prune_holding(self) -> None:
        """Each holder's serials less those no longer held; holders left with none go."""
        held = self._held
        holding = {h: [s for s in serials if s in held] for h, serials in self._holding.items()}
        self._holding = {h: serials for h, serials in holding.items() if serials}

    def cell_side(self, sensor_id: str) -> float | None:
        """The side (m) of a sensor's cells, ``None`` before its first detection."""
        grid = self._grids.get(sensor_id)
        return None if grid is None else grid.cell
