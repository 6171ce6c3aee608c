"""The clutter map: the learned false-alarm density per area, and what it changes."""

from __future__ import annotations

import numpy as np
import pytest

from trackers.clutter import (
    AROUND_CELLS,
    CELL_SIGMAS,
    MEMORY_SCANS,
    PRIOR_SCANS,
    ClutterMap,
)
from trackers.config import TrackerConfig
from trackers.pipeline import TrackingPipeline
from trackers.types import Scan

PRIOR = 1e-6


def _R(n: int, sigma: float = 10.0) -> np.ndarray:
    return np.tile(sigma**2 * np.eye(2), (n, 1, 1))


def test_a_sensor_not_seen_has_the_prior_everywhere() -> None:
    m = ClutterMap()
    z = np.array([[0.0, 0.0], [5e3, -2e3]])
    np.testing.assert_array_equal(m.density("r", z, PRIOR), [PRIOR, PRIOR])
    m.learn("r", np.zeros((0, 2)), np.zeros((0, 2, 2)))  # no detection yet: nothing to size
    assert m.cell_side("r") is None
    np.testing.assert_array_equal(m.density("r", z, PRIOR), [PRIOR, PRIOR])


def test_worked_example_of_one_scan() -> None:
    # sigma 10 m: cells of 200 m (area 4e4 m²); one scan with 4 false alarms in cell (0, 0)
    m = ClutterMap()
    clutter = np.array([[10.0, 10.0], [50.0, 150.0], [190.0, 5.0], [100.0, 100.0]])
    m.learn("r", clutter, _R(4))
    assert m.cell_side("r") == CELL_SIGMAS * 10.0
    area = 200.0**2
    alpha0 = PRIOR * area * PRIOR_SCANS
    lam = m.density("r", np.array([[120.0, 30.0], [-50.0, 30.0]]), PRIOR)
    # E = 1 scan
    assert lam[0] == pytest.approx((alpha0 + 4.0) / ((PRIOR_SCANS + 1.0) * area))
    # an empty cell after one scan: the prior's share, alpha0 / ((beta0 + 1) A)
    assert lam[1] == pytest.approx(alpha0 / ((PRIOR_SCANS + 1.0) * area))


def test_worked_example_of_the_density_about_a_point() -> None:
    """The block of 7 x 7 cells about a point: the counts of all its cells over its area, the
    scene's density its prior; a point whose block leaves the counted cell out reads the
    prior's share alone. Uniform clutter reads the scene's density: no more."""
    m = ClutterMap()
    clutter = np.array([[10.0, 10.0], [50.0, 150.0], [190.0, 5.0], [100.0, 100.0]])
    m.learn("r", clutter, _R(4))
    rate = m._grids["r"].scene_rate(PRIOR)
    cells = (2 * AROUND_CELLS + 1) ** 2
    area = cells * 200.0**2
    z = np.array([[120.0, 30.0], [650.0, -550.0], [850.0, 30.0]])  # cell 0; 3 away; 4 away
    lam = m.around("r", z, PRIOR)
    assert lam[0] == pytest.approx((rate * area * PRIOR_SCANS + 4.0) / ((PRIOR_SCANS + 1.0) * area))
    assert lam[1] == lam[0]
    assert lam[2] == pytest.approx(rate * PRIOR_SCANS / (PRIOR_SCANS + 1.0))
    assert lam[0] < m.density("r", z[:1], PRIOR)[0]  # the cell's own, 49 times less spread
    np.testing.assert_array_equal(ClutterMap().around("r", z, PRIOR), [PRIOR] * 3)

    rng = np.random.default_rng(2)
    uniform = ClutterMap()
    for _ in range(60):  # 400 a scan over 40 km x 40 km: 2.5e-7 per m², below the prior
        uniform.learn("r", rng.uniform(-2e4, 2e4, (400, 2)), _R(400, 30.0))
    here = rng.uniform(-1.5e4, 1.5e4, (50, 2))
    scene = uniform._grids["r"].scene_rate(PRIOR)
    ratio = uniform.around("r", here, PRIOR) / scene
    assert 0.8 < float(np.median(ratio)) < 1.1 and float(ratio.max()) < 1.5


def test_counts_are_forgotten_and_the_density_is_floored() -> None:
    m = ClutterMap()
    here = np.array([[100.0, 100.0]])
    m.learn("r", np.repeat(here, 10, axis=0), _R(10))
    before = m.density("r", here, PRIOR)[0]
    for _ in range(int(MEMORY_SCANS)):
        m.learn("r", np.zeros((0, 2)), _R(1))
    after = m.density("r", here, PRIOR)[0]
    # the count has decayed by about e⁻¹ while the scans counted grew a hundredfold
    assert after < 0.05 * before
    # far from any false alarm, long quiet: the prior's share of a full memory, λ₀ β₀ / (β₀ + M)
    for _ in range(int(10 * MEMORY_SCANS)):
        m.learn("r", np.zeros((0, 2)), _R(1))
    far = m.density("r", np.array([[1e5, 1e5]]), PRIOR)[0]
    assert far == pytest.approx(PRIOR * PRIOR_SCANS / (PRIOR_SCANS + MEMORY_SCANS), rel=1e-3)


def test_sensors_have_their_own_maps() -> None:
    m = ClutterMap()
    spot = np.array([[0.0, 0.0]])
    for _ in range(20):
        m.learn("a", np.repeat(spot, 50, axis=0), _R(50))
        m.learn("b", np.zeros((0, 2)), _R(1))
    a, b = m.density("a", spot, PRIOR)[0], m.density("b", spot, PRIOR)[0]
    assert a > 100 * PRIOR and b < 0.2 * PRIOR


def _dense(clutter_map: bool, scans: int = 15, n_fa: int = 600):
    """A 1.5 km square with ``n_fa`` false alarms a scan (2.7e-4 per m²) and one 100 m/s
    target 20 km away, T = 1 s, no density stated: the confirmed tracks at the end and the
    target's track."""
    rng = np.random.default_rng(0)
    cfg = TrackerConfig().merged({"track_management": {"clutter_map": clutter_map}})
    pipe = TrackingPipeline.all_kinds(cfg)
    x0, v = np.array([20e3, 0.0]), np.array([-100.0, 50.0])
    for k in range(scans):
        z = np.vstack([rng.uniform(-750, 750, (n_fa, 2)), x0 + v * k + rng.normal(0, 20, (1, 2))])
        res = pipe.process(Scan("r", float(k), z, _R(len(z), 20.0)))
    confirmed = res.confirmed()
    target = [
        t for t in confirmed if np.hypot(*(np.array(t.position) - (x0 + v * (scans - 1)))) < 100
    ]
    return confirmed, target


def test_dense_local_clutter_makes_no_tracks_with_the_map() -> None:
    """Without a stated density the configured 1e-6 per m² stood for the whole picture, 270
    times too low in the square: most false alarms there became confirmed tracks."""
    without, _ = _dense(False)
    with_map, target = _dense(True)
    assert len(without) > 100
    assert len(target) == 1 and len(with_map) <= 3


def test_a_stated_density_is_used_as_it_is() -> None:
    """Batches that state their density are scored alike with the map on or off."""
    runs = []
    for on in (False, True):
        rng = np.random.default_rng(3)
        cfg = TrackerConfig().merged({"track_management": {"clutter_map": on}})
        pipe = TrackingPipeline.all_kinds(cfg)
        for k in range(12):
            z = np.vstack(
                [
                    rng.uniform(-2e3, 2e3, (20, 2)),
                    np.array([[100.0 + 30 * k, 0.0]]) + rng.normal(0, 10, 2),
                ]
            )
            pipe.process(Scan("r", float(k), z, _R(len(z)), clutter_density=5e-6))
        runs.append([(t.id, t.position, t.score) for t in pipe.snapshot()])
    assert runs[0] and runs[0] == runs[1]


def test_a_confirmed_targets_detections_are_not_counted_as_clutter() -> None:
    """A parked target seen for 60 scans with no clutter: only the detections before its
    track was confirmed count, not the 60 a map of every detection would hold."""
    rng = np.random.default_rng(1)
    pipe = TrackingPipeline(TrackerConfig())
    every = ClutterMap()
    for k in range(60):
        z = np.array([[0.0, 0.0]]) + rng.normal(0, 10, (1, 2))
        pipe.process(Scan("r", float(k), z, _R(1)))
        every.learn("r", z, _R(1))
    here = np.array([[0.0, 0.0]])
    assert pipe._clutter.density("r", here, PRIOR)[0] < 0.2 * every.density("r", here, PRIOR)[0]
    assert pipe.snapshot()[0].confirmed


def test_the_maps_are_bounded_whatever_is_sent() -> None:
    """Many sensor ids, and detections strewn far apart: at most MAX_SENSORS maps of at most
    MAX_CELLS cells each (the most recently heard sensors, the strongest cells kept)."""
    from trackers.clutter import MAX_CELLS, MAX_SENSORS

    m = ClutterMap()
    rng = np.random.default_rng(0)
    for i in range(MAX_SENSORS + 20):
        m.learn(f"s{i}", rng.uniform(-1e3, 1e3, (2, 2)), _R(2))
    assert len(m._grids) == MAX_SENSORS and m.cell_side("s0") is None
    assert m.cell_side(f"s{MAX_SENSORS + 19}") is not None
    strong = np.array([[5.0, 5.0]])
    m.learn("wide", np.repeat(strong, 50, axis=0), _R(50))
    side = m.cell_side("wide")
    n = MAX_CELLS // 2 + 100
    for _ in range(3):
        m.learn("wide", rng.uniform(-1e6, 1e6, (n, 2)), _R(n))
    grid = m._grids["wide"]
    # four cells became one as often as needed, nothing of the counts lost
    assert grid.keys.size <= MAX_CELLS and np.all(np.diff(grid.keys) > 0)
    assert grid.cell > side and np.log2(grid.cell / side) % 1 == 0
    total = grid.decayed(np.arange(grid.keys.size)).sum()
    gamma = 1.0 - 1.0 / MEMORY_SCANS
    assert total == pytest.approx(50 * gamma**3 + n * (gamma**2 + gamma + 1))


def test_sector_and_empty_batches_teach_the_map_nothing() -> None:
    """A batch with its own coverage (a sector) or no detection would count as a look at every
    cell and thin the density out: the pipeline learns only from the others."""
    from trackers.coverage import Coverage

    pipe = TrackingPipeline(TrackerConfig())
    rng = np.random.default_rng(4)
    sector = Coverage(polygon=np.array([[0.0, 0.0], [5e3, 0.0], [5e3, 5e3]]))
    for k in range(10):
        z = rng.uniform(0, 5e3, (30, 2))
        pipe.process(Scan("r", 2.0 * k, z, _R(30)))
        pipe.process(Scan("r", 2.0 * k + 0.5, np.zeros((0, 2)), _R(0)))
        pipe.process(Scan("r", 2.0 * k + 1.0, z[:3], _R(3), coverage=sector))
    assert pipe._clutter._grids["r"].scans == 10


def test_a_fixed_field_of_view_teaches_the_map_and_sectors_do_not() -> None:
    """A camera whose batches all state its field of view (one polygon) teaches the map from
    its second batch on (before, a stated polygon taught nothing, and a camera scene's false
    alarms were taken at the configured 1e-6 per m²); pointed elsewhere, its map starts
    afresh; a radar reporting a revolution sector by sector, each batch with its own polygon,
    still teaches nothing."""
    from trackers.coverage import Coverage

    def box(x0: float) -> Coverage:  # a new array each batch, as each batch's JSON gives it
        return Coverage(
            polygon=np.array([[x0, 0.0], [x0 + 60.0, 0.0], [x0 + 60.0, 40.0], [x0, 40.0]])
        )

    pipe = TrackingPipeline(TrackerConfig())
    rng = np.random.default_rng(5)
    for k in range(10):
        z = rng.uniform([0.0, 0.0], [60.0, 40.0], (3, 2))
        pipe.process(Scan("cam", 0.1 * k, z, _R(3, 0.5), coverage=box(-0.0 if k % 2 else 0.0)))
        angle = np.radians(45.0 * k)
        rim = [[np.cos(a), np.sin(a)] for a in (angle, angle + np.radians(45.0))]
        sector = Coverage(polygon=np.array([[0.0, 0.0], *(5e3 * np.array(rim))]))
        pipe.process(
            Scan("radar", 0.1 * k + 0.05, rng.uniform(0, 5e3, (5, 2)), _R(5), coverage=sector)
        )
    assert pipe._clutter._grids["cam"].scans == 9
    assert "radar" not in pipe._clutter._grids
    # the camera's scene: 3 false alarms a frame over 2,400 m², about 1.2e-3 per m²
    assert pipe._clutter.read("cam", np.zeros((1, 2)), 1e-6)[1] > 1e-4
    for k in range(10, 13):  # pointed 100 m east: forgotten, then learned from its 2nd batch
        z = rng.uniform([100.0, 0.0], [160.0, 40.0], (3, 2))
        pipe.process(Scan("cam", 0.1 * k, z, _R(3, 0.5), coverage=box(100.0)))
    assert pipe._clutter._grids["cam"].scans == 2


def test_a_much_finer_first_batch_does_not_set_the_cells_for_good() -> None:
    m = ClutterMap()
    m.learn("r", np.zeros((1, 2)), _R(1, 0.05))  # one detection of 5 cm: 1 m cells
    assert m.cell_side("r") == 1.0
    m.learn("r", np.zeros((5, 2)), _R(5, 30.0))  # the sensor's own: 600 m, afresh
    assert m.cell_side("r") == CELL_SIGMAS * 30.0 and m._grids["r"].scans == 1


def test_a_sparse_scene_lowers_its_cells_prior_from_the_first_scans() -> None:
    """A newcomer's radar: 50 false alarms a scan over 60 km x 60 km (1.4e-8 per m², seventy
    times below the configured 1e-6). With the configured density as every cell's prior the
    map needed some 50 scans to come down, and the first tracks were confirmed late. The
    scene's density (all counts over the box they span, the configured density worth a
    fiftieth of a scan of it), twice over, is the cells' prior instead."""
    from trackers.clutter import SCENE_MARGIN, SCENE_PRIOR_SCANS

    m = ClutterMap()
    rng = np.random.default_rng(0)
    gamma = 1.0 - 1.0 / MEMORY_SCANS
    seen = []
    for _ in range(3):
        z = rng.uniform(-30e3, 30e3, (50, 2))
        seen.append(z)
        m.learn("r", z, _R(50, 25.0))
    allz = np.vstack(seen)
    cell = m.cell_side("r")
    span = allz.max(axis=0) - allz.min(axis=0) + cell
    area = float(span[0] * span[1])
    E = 1.0 + gamma + gamma**2
    total = 50.0 * E
    scene = (PRIOR * area * SCENE_PRIOR_SCANS + total) / ((SCENE_PRIOR_SCANS + E) * area)
    assert 50 / 3600e6 < scene < 2 * 50 / 3600e6  # the true density, and the prior's share
    far = np.array([[1e6, 1e6]])  # a cell with no count: the prior's share, or the floor
    floor = PRIOR * PRIOR_SCANS / (PRIOR_SCANS + MEMORY_SCANS)
    expected = max(SCENE_MARGIN * scene * PRIOR_SCANS / (PRIOR_SCANS + E), floor)
    assert m.density("r", far, PRIOR)[0] == pytest.approx(expected)
    assert expected < PRIOR / 50  # it was PRIOR β₀ / (β₀ + E) = PRIOR / 2.5


def test_a_scene_denser_than_configured_keeps_the_configured_prior() -> None:
    # 4 false alarms in one 200 m cell: the scene is dense, but its prior stays the
    # configured density (the cells' own counts raise them)
    m = ClutterMap()
    m.learn("r", np.array([[10.0, 10.0], [50.0, 150.0], [190.0, 5.0], [100.0, 100.0]]), _R(4))
    far = np.array([[5e3, 5e3]])
    assert m.density("r", far, PRIOR)[0] == pytest.approx(PRIOR * PRIOR_SCANS / (PRIOR_SCANS + 1))


def test_the_scene_density_is_not_capped_by_the_configured_one() -> None:
    """What a cluster of detections must beat to be a group: the whole scene's density, all
    counts over the box they span, even where it is far above the configured density."""
    from trackers.clutter import SCENE_PRIOR_SCANS

    m = ClutterMap()

    def scene_rate(sensor: str, prior: float) -> float | None:
        return m.read(sensor, np.zeros((0, 2)), prior)[1]

    assert scene_rate("r", PRIOR) is None  # a sensor not heard
    z = np.array([[0.0, 0.0], [400.0, 0.0], [0.0, 400.0], [400.0, 400.0], [200.0, 200.0]])
    m.learn("r", z, _R(5))
    side = 400.0 + m.cell_side("r")  # the box of the counts, grown by a cell (200 m)
    area = side * side
    expected = (PRIOR * area * SCENE_PRIOR_SCANS + 5.0) / ((SCENE_PRIOR_SCANS + 1.0) * area)
    assert scene_rate("r", PRIOR) == pytest.approx(expected)
    assert expected > 10 * PRIOR  # 5 false alarms over 600 m x 600 m: 1.4e-5 per m²
    assert scene_rate("other", PRIOR) is None


def _scans_to_confirm(seed: int, clutter_map: bool = True) -> int:
    """Scans until a 250 m/s target (T = 4 s, 50 m noise, P_D 0.9) among 50 false alarms a
    scan over 60 km x 60 km, no density stated, has a confirmed track within 300 m."""
    cfg = TrackerConfig().merged({"track_management": {"clutter_map": clutter_map}})
    pipe = TrackingPipeline.all_kinds(cfg)
    rng = np.random.default_rng(seed)
    h = rng.uniform(0.0, 2.0 * np.pi)
    v = 250.0 * np.array([np.cos(h), np.sin(h)])
    x0 = rng.uniform(-15e3, 15e3, 2)
    for k in range(30):
        x = x0 + 4.0 * k * v
        zt = (x + rng.normal(0.0, 50.0, 2))[None] if rng.random() < 0.9 else np.zeros((0, 2))
        z = np.vstack([zt, rng.uniform(-30e3, 30e3, (50, 2))])
        res = pipe.process(Scan("r", 4.0 * k, z, _R(len(z), 50.0)))
        if any(np.hypot(*np.subtract(t.position, x)) < 300.0 for t in res.confirmed()):
            return k + 1
    return 99


def test_a_target_in_sparse_clutter_is_confirmed_sooner() -> None:
    """10 runs: a median of 6 scans to confirmation (9 when every cell's prior was the
    configured density, 13 with that density and no map)."""
    on = [_scans_to_confirm(s) for s in range(10)]
    off = [_scans_to_confirm(s, clutter_map=False) for s in range(10)]
    assert np.median(on) <= 6.5 < 12 <= np.median(off)


def _quiet(m: ClutterMap, scans: int) -> None:
    for _ in range(scans):
        m.learn("r", np.zeros((0, 2)), _R(1))


def test_held_detections_count_when_their_track_is_rejected() -> None:
    """Detections a tentative track holds back count nothing until the sequential test
    deletes it; then each counts in its cell at its own scan's weight γ^age."""
    m = ClutterMap()
    _quiet(m, 1)  # scan 1 sizes the cells: 200 m
    here = np.array([[50.0, 50.0]])
    m.hold("r", np.array([[10.0, 10.0], [30.0, 40.0]]), ("T1", "T1"), [5, 6])
    _quiet(m, 3)
    quiet = m.density("r", here, PRIOR)[0]
    m.settle((), ("T1",))
    gamma = 1.0 - 1.0 / MEMORY_SCANS
    exposure = sum(gamma**k for k in range(4))
    area = 200.0**2
    late = m.density("r", here, PRIOR)[0]
    assert late - quiet == pytest.approx(2 * gamma**3 / ((PRIOR_SCANS + exposure) * area))
    assert m._held == {} and m._holding == {}
    m.settle((), ("T1",))  # told twice: nothing more
    assert m.density("r", here, PRIOR)[0] == late


def test_held_detections_of_a_target_never_count() -> None:
    m = ClutterMap()
    _quiet(m, 1)
    here = np.array([[50.0, 50.0]])
    before = m.density("r", here, PRIOR)[0]
    m.hold("r", np.array([[10.0, 10.0]]), ("T1",), [5])
    m.settle(("T1",), ())
    m.settle((), ("T1",))
    assert m.density("r", here, PRIOR)[0] == before and m._held == {}


def test_a_detection_two_tracks_held_counts_once_after_both() -> None:
    """Siblings share a detection: it counts once, when the last holder is rejected, and not
    at all when one of them turns out a target."""
    m = ClutterMap()
    _quiet(m, 1)
    here = np.array([[50.0, 50.0]])
    z = np.array([[10.0, 10.0], [10.0, 10.0]])
    m.hold("r", z, ("a", "b"), [7, 7])
    base = m.density("r", here, PRIOR)[0]
    m.settle((), ("a",))
    assert m.density("r", here, PRIOR)[0] == base
    m.settle((), ("b",))
    one = m.density("r", here, PRIOR)[0] - base
    assert one == pytest.approx(1.0 / ((PRIOR_SCANS + 1.0) * 200.0**2))
    m.hold("r", z, ("c", "d"), [8, 8])
    after = m.density("r", here, PRIOR)[0]
    m.settle((), ("c",))
    m.settle(("d",), ())
    assert m.density("r", here, PRIOR)[0] == after and m._held == {} and m._holding == {}


def test_a_tracks_first_two_detections_are_taken_back_at_its_third() -> None:
    """Counted at their scans (serials 0 and 1), a track's first two detections alone in a
    quiet part of the map are taken back when it takes its third: its cell reads the floor
    again, and counts them late if the test then rejects the track, never if it is
    accepted."""
    here = np.array([[50.0, 50.0]])

    def three_scans() -> ClutterMap:
        m = ClutterMap()
        m.learn("r", here, _R(1), np.array([0]), here)
        m.learn("r", here + 5.0, _R(1), np.array([1]), here + 5.0)
        m.learn("r", np.zeros((0, 2)), _R(1), np.zeros(0, np.int64), here + 9.0)  # the third
        return m

    counted = three_scans().density("r", here, PRIOR)[0]
    third = ("r", np.repeat(here + 9.0, 2, axis=0), False)
    for fate in ("rejected", "accepted"):
        m = three_scans()
        m.reclaim(np.array([0, 1]), ("T1", "T1"), third)
        taken = m.density("r", here, PRIOR)[0]
        assert taken < 0.01 * counted and m._grids["r"].total == pytest.approx(0.0)
        m.reclaim(np.array([0, 1]), ("T1", "T1"), third)  # told twice: held once, by T1 twice
        assert len(m._held) == 2
        if fate == "rejected":
            m.settle((), ("T1",))
            # each counts once, at its own scan's weight: as if never taken back
            assert m.density("r", here, PRIOR)[0] == pytest.approx(counted)
        else:
            m.settle(("T1",), ())
            assert m.density("r", here, PRIOR)[0] == taken
        assert m._held == {} and m._holding == {}


def test_nothing_is_taken_back_where_the_cells_saw_more() -> None:
    """Where the cell and those around it saw other detections (a patch of clutter whose
    detections young tracks took, or another target), a track's first two stay counted: taken
    back from every young track in dense clutter they hollowed the map out."""
    here = np.array([[50.0, 50.0]])
    others = np.array([[150.0, 350.0], [-120.0, 20.0]])  # not counted: tracks took them
    m = ClutterMap()
    for k in range(3):
        z = here + k
        m.learn("r", z, _R(1), np.array([k]), np.vstack([z, others]))
    before = m.density("r", here, PRIOR)[0]
    m.reclaim(np.array([0, 1]), ("T1", "T1"), ("r", np.repeat(here + 2.0, 2, axis=0), False))
    assert m.density("r", here, PRIOR)[0] == before and m._held == {}
    # detections the map no longer knows, or never counted, are passed over
    m.reclaim(np.array([-1, 77]), ("T2", "T2"))
    assert m._held == {} and m._holding == {}


def test_only_the_tracks_own_detections_are_discounted() -> None:
    """What a block saw less the track's own: its first two (once each, however often named)
    and its third only where the third was counted (one false alarm in the cell besides is
    too many after three scans); siblings of the same two hold them together."""
    here = np.array([[50.0, 50.0]])
    far = np.array([[5050.0, 50.0]])

    def scans(extra: np.ndarray) -> ClutterMap:
        m = ClutterMap()
        m.learn("r", here, _R(1), np.array([0]), here)
        m.learn("r", here + 5.0, _R(1), np.array([1]), here + 5.0)
        m.learn("r", np.zeros((0, 2)), _R(1), np.zeros(0, np.int64), extra)
        return m

    # its third 5 km away (a fast target), a false alarm in the cell: nothing taken back
    m = scans(np.vstack([far, here + 20.0]))
    m.reclaim(np.array([0, 1]), ("T1", "T1"), ("r", np.repeat(far, 2, axis=0), False))
    assert m._held == {}
    # its third in the cell and nothing else: both taken back; a serial named twice counts
    # once
    m = scans(here + 9.0)
    total = m._grids["r"].total
    m.reclaim(np.array([0, 0, 1]), ("T1", "T1", "T1"), ("r", np.repeat(here, 3, axis=0), False))
    assert sorted(m._held) == [0, 1] and m._grids["r"].total == pytest.approx(0.0)
    assert total == pytest.approx((1 - 1 / 100) ** 2 + (1 - 1 / 100))
    # a sibling of the same two: it holds them too, and they count once when both go
    m = scans(here + 9.0)
    third = ("r", np.repeat(here, 4, axis=0), False)
    m.reclaim(np.array([0, 1, 0, 1]), ("T1", "T1", "T2", "T2"), third)
    assert sorted(m._held) == [0, 1] and m._held[0][5] == m._held[1][5] == 2
    m.settle((), ("T1",))
    assert m._grids["r"].total == pytest.approx(0.0)
    m.settle((), ("T2",))
    assert m._grids["r"].total == pytest.approx(total)


def test_a_sweeps_gathered_detection_is_taken_back_before_the_look() -> None:
    """A radar streaming sectors: the first two detections of a track wait with their sweep
    when it takes its third; taken back, they are not counted when the sweep comes round."""
    m = ClutterMap()
    z = np.array([[1000.0, 10.0]])  # at bearing 0
    for turn in range(2):
        for s in range(16):
            a0 = 2 * np.pi * s / 16
            if s == 0 and turn == 1:
                m.learn_sector("r", a0, 2 * np.pi / 16, z, _R(1), serials=np.array([7]))
            else:
                m.learn_sector("r", a0, 2 * np.pi / 16, np.zeros((0, 2)), _R(1))
    m.reclaim(np.array([7]), ("T1",), ("r", z, True))
    assert list(m._held) == [7]
    m.learn_sector("r", 0.0, 2 * np.pi / 16, np.zeros((0, 2)), _R(1))  # the look
    assert m._grids["r"].total == 0.0


def _scans_to_confirm_parked(seed: int) -> list[int]:
    """Scans until each of three slow targets (0, 5 and 15 m/s) seen from a sensor's first
    scan, in a clean scene (T = 4 s, 10 m noise, P_D 0.9, no density stated), has a
    confirmed track within 50 m."""
    rng = np.random.default_rng(seed)
    pipe = TrackingPipeline.all_kinds(TrackerConfig())
    x0 = rng.uniform(-8e3, 8e3, (3, 2))
    h = rng.uniform(0.0, 2.0 * np.pi, 3)
    v = np.column_stack([np.cos(h), np.sin(h)]) * np.array([[0.0], [5.0], [15.0]])
    first = [99, 99, 99]
    for k in range(14):
        x = x0 + 4.0 * k * v
        seen = rng.random(3) < 0.9
        z = x[seen] + rng.normal(0.0, 10.0, (int(seen.sum()), 2))
        res = pipe.process(Scan("r", 4.0 * k, z, _R(len(z))))
        for i in range(3):
            if first[i] == 99 and any(
                np.hypot(*np.subtract(t.position, x[i])) < 50.0 for t in res.confirmed()
            ):
                first[i] = k + 1
    return first


def test_slow_targets_present_from_the_first_scan_confirm_promptly() -> None:
    """The map counted a target's first two detections until its track took a third, and
    they were all its cell had seen: a slow target's cell read as clutter a thousand times
    the scene's until the target left it (these 4 runs: confirmed at the 4th to 10th scan, a
    mean of 5.92); with them taken back, at the 4th to 6th, a mean of 5.17."""
    scans = [n for seed in range(4) for n in _scans_to_confirm_parked(seed)]
    assert max(scans) <= 6 and np.mean(scans) <= 5.5


def test_held_detections_are_bounded_and_forgotten() -> None:
    from trackers.clutter import HELD_SCANS, MAX_HELD

    m = ClutterMap()
    m.hold("r", np.zeros((1, 2)), ("x",), [1])  # a sensor not seen yet holds nothing
    assert m._held == {}
    _quiet(m, 1)
    n = MAX_HELD + 5
    m.hold("r", np.zeros((n, 2)), tuple(f"T{i % 7}" for i in range(n)), np.arange(n))
    assert len(m._held) == 3 * MAX_HELD // 4 and 0 not in m._held and n - 1 in m._held
    assert all(s in m._held for serials in m._holding.values() for s in serials)
    _quiet(m, HELD_SCANS + 1)
    for _ in range(64):  # the stale ones go now and then
        m.settle((), ())
    assert m._held == {} and m._holding == {}
    # a sensor whose map started afresh since: its old held detections count nowhere
    m.hold("r", np.array([[10.0, 10.0]]), ("T9",), [10**6])
    m.learn("r", np.zeros((0, 2)), _R(1, sigma=1000.0))  # 100 times coarser: a new map
    m.settle((), ("T9",))
    assert m._grids["r"].total == 0.0


def _patch_run(seed: int, scans: int = 120, period: float = 2.5) -> tuple[float, float]:
    """Three targets in a sparse scene (10 false alarms a scan over 20 km x 20 km) and a
    500 m x 500 m patch with 8 false alarms a scan (3.2e-5 per m²), 30 m noise, no density
    stated: over the second half, the map's mean density in the patch and the confirmed
    individual tracks in it a scan."""
    rng = np.random.default_rng(seed)
    pipe = TrackingPipeline.all_kinds(TrackerConfig())
    x0 = np.array([[5e3, 5e3], [-6e3, 2e3], [2e3, -7e3]])
    v = np.array([[8.0, 3.0], [-5.0, 10.0], [0.0, 0.0]])
    inside = np.array([[125.0, 125.0], [-125.0, -125.0], [125.0, -125.0], [-125.0, 125.0]])
    density, found = [], []
    for k in range(scans):
        t = k * period
        det = (x0 + v * t)[rng.random(3) < 0.9]
        z = np.vstack(
            [
                det + rng.normal(0, 30, det.shape),
                rng.uniform(-1e4, 1e4, (rng.poisson(10), 2)),
                rng.uniform(-250, 250, (rng.poisson(8), 2)),
            ]
        )
        res = pipe.process(Scan("r", t, z, _R(len(z), 30.0)))
        if k >= scans // 2:
            density.append(float(pipe._clutter.density("r", inside, PRIOR).mean()))
            p = np.array([c.position for c in res.confirmed() if c.kind == "individual"])
            found.append(int(np.sum(np.all(np.abs(p.reshape(-1, 2)) < 400, axis=1))))
    return float(np.mean(density)), float(np.mean(found))


def test_a_clutter_patch_is_learned_through_the_tracks_it_starts(monkeypatch) -> None:
    """The tracks a patch of clutter starts took its detections, so the map never learned it
    and confirmed more: the detections of the tentative tracks the test deletes count late.
    The map reads the patch about twice as dense with them (8 runs of 120 scans: denser in
    every run). Most of the patch is now held by an extended track, whose detections the
    map does not count, and the false tracks left in it are few and vary much from run to
    run: summed over 40 runs of 240 scans (2026-11-27), 3.9 a scan with the late counts and
    14.1 without; 8 runs, as this test once counted, can give either more."""
    with_late = [_patch_run(s) for s in range(4)]
    monkeypatch.setattr(ClutterMap, "settle", lambda self, accepted, rejected: None)
    without = [_patch_run(s) for s in range(4)]
    assert all(a[0] > b[0] for a, b in zip(with_late, without, strict=True))
    assert sum(a[0] for a in with_late) > 1.3 * sum(b[0] for b in without)


def test_a_restored_state_forgets_the_held_detections() -> None:
    """The restored tracker gives its serial numbers and ids again: detections held back for
    the tracks of the state left behind would be taken for new ones."""
    rng = np.random.default_rng(5)
    pipe = TrackingPipeline(TrackerConfig())
    saved = pipe.export_state()
    for k in range(60):
        z = np.vstack([rng.uniform(-1e4, 1e4, (10, 2)), rng.uniform(-250, 250, (8, 2))])
        pipe.process(Scan("r", 2.5 * k, z, _R(len(z), 30.0)))
        if pipe._clutter._held:
            break
    assert pipe._clutter._held
    pipe.import_state(saved)
    assert pipe._clutter._held == {} and pipe._clutter._holding == {}


def _group_held(seed: int, frames: int = 300, arrive: int = 100) -> float:
    """A camera at 10 Hz (0.3 m noise, P_D 0.95, 2 false alarms a frame over 60 m x 60 m, no
    density stated); after ``arrive`` frames four people walk in side by side 1 m apart at
    1.4 m/s. The share of the frames from 5 s after they came in at which each has its own
    confirmed track within 0.6 m."""
    rng = np.random.default_rng(seed)
    pipe = TrackingPipeline.all_kinds(TrackerConfig())
    start = np.array([[5.0, 20.0 + i] for i in range(4)])
    v = np.array([1.3, 0.4])
    held = []
    for k in range(frames):
        X = start + v * 0.1 * (k - arrive)
        det = X[rng.random(4) < 0.95] if k >= arrive else np.zeros((0, 2))
        z = np.vstack(
            [det + rng.normal(0, 0.3, det.shape), rng.uniform(0, 60, (rng.poisson(2.0), 2))]
        )
        res = pipe.process(Scan("cam", 1000.0 + 0.1 * k, z, _R(len(z), 0.3)))
        if k >= arrive + 50:
            P = np.array([c.position for c in res.confirmed()]).reshape(-1, 2)
            d = np.hypot(X[:, None, 0] - P[None, :, 0], X[:, None, 1] - P[None, :, 1])
            own = len(P) >= 4 and len(set(np.argmin(d, axis=1).tolist())) == 4
            held.append(own and bool((d.min(axis=1) <= 0.6).all()))
    return float(np.mean(held))


@pytest.mark.parametrize("seed", [3, 7, 9])
def test_people_walking_in_side_by_side_each_get_a_track(seed: int) -> None:
    """Where false alarms are dense (a camera's 5.6e-4 per m² a frame) the configured new-
    target density (1e-7 per m²) started every track below the deletion threshold; the map
    then counted the group's first detections as false alarms, its density there rose 30-fold
    and no track could start. These runs held the four in 9 %, 0 % and 0 % of the frames
    without the floor on the new-target odds (trackers.scoring.MIN_NEW_TARGET_ODDS), all but
    a few frames with it."""
    assert _group_held(seed) >= 0.9


def _dense_stated(seed: int, scans: int = 120) -> tuple[float, float]:
    """A radar every 2.5 s (10 m noise, P_D 0.9) over 1 km x 1 km with 100 false alarms a
    scan, the density stated (1e-4 per m²), and 3 targets at 5-9 m/s: the share of the
    target-scans after the first 20 scans held by a confirmed track within 50 m, and the
    confirmed tracks a scan more than 50 m from every target."""
    rng = np.random.default_rng(seed)
    pipe = TrackingPipeline(TrackerConfig())
    x0 = np.array([[200.0, 300.0], [-300.0, -100.0], [0.0, 400.0]])
    v = np.array([[5.0, 2.0], [-3.0, 6.0], [8.0, -4.0]])
    false = held = n = 0
    for k in range(scans):
        t = 2.5 * k
        X = x0 + v * t
        det = X[rng.random(3) < 0.9]
        z = np.vstack(
            [det + rng.normal(0, 10, det.shape), rng.uniform(-500, 500, (rng.poisson(100), 2))]
        )
        res = pipe.process(Scan("r", t, z, _R(len(z), 10.0), clutter_density=1e-4))
        if k >= 20:
            P = np.array([c.position for c in res.confirmed()]).reshape(-1, 2)
            if len(P):
                d = np.hypot(X[:, None, 0] - P[None, :, 0], X[:, None, 1] - P[None, :, 1])
                false += int((d.min(axis=0) > 50).sum())
                held += int((d.min(axis=1) <= 50).sum())
            n += 1
    return held / (3 * n), false / n


@pytest.mark.parametrize("seed", [0, 1])
def test_targets_in_dense_stated_clutter_get_tracks(seed: int) -> None:
    """ln(λ_nt / λ_fa) = ln(1e-7 / 1e-4) is the deletion threshold itself: without the floor
    on the new-target odds no target of these runs (6 seeds) was ever confirmed; with it they
    are held in 0.76-0.92 of their scans, and no false track is confirmed."""
    held, false = _dense_stated(seed)
    assert held >= 0.6 and false == 0.0


def test_sectors_of_a_revolution_teach_the_map_once_a_turn() -> None:
    """Sixteen sectors a turn, 2 false alarms each: the map learns when the sweep comes
    round, all 32 as one scan (before, sector batches taught nothing and a batch without a
    polygon counted as a look at every cell: 16 looks a turn, the density 16 times too
    low); arcs that never cover the sweep (a camera panning to and fro) teach nothing."""
    from trackers.clutter import arc_bins

    rng = np.random.default_rng(0)
    m = ClutterMap()
    learned = []
    for _ in range(3):
        for s in range(16):
            a0 = 2 * np.pi * s / 16
            r, a = np.sqrt(rng.uniform(0, 1e8, 2)), rng.uniform(a0, a0 + 2 * np.pi / 16, 2)
            z = np.column_stack([r * np.cos(a), r * np.sin(a)])
            learned.append(m.learn_sector("r", a0, 2 * np.pi / 16, z, _R(2)))
    assert [i for i, x in enumerate(learned) if x] == [16, 32]
    grid = m._grids["r"]
    assert grid.scans == 2 and grid.total == pytest.approx(32.0 * (1 - 1 / 100) + 32.0)
    # a sector's density: its counts over two looks, not 32
    here = m.density("r", np.array([[5e3, 1e3]]), 1e-6)[0]
    assert here < 1e-6
    panning = ClutterMap()
    for k in range(40):
        a0 = 0.3 * abs((k % 8) - 4) / 4  # to and fro over 0.3 rad, 0.2 rad wide
        assert not panning.learn_sector("c", a0, 0.2, np.array([[10.0, 1.0]]), _R(1))
    assert "c" not in panning._grids
    assert arc_bins(2 * np.pi - 0.01, 0.02).nonzero()[0].tolist() == [0, 359]


def test_a_radar_stating_its_sectors_learns_a_clutter_patch() -> None:
    """A radar reporting 16 sector batches a turn, each stating its sector as `coverage`,
    with a 500 m x 500 m patch of 8 false alarms a turn: the map never learned from such
    batches, and the patch kept 1.7 confirmed false tracks (3 runs, 16 batches a turn); it
    now learns once a turn, and an extended track holds the patch."""
    from trackers.coverage import Coverage

    def sector(s):
        a = np.linspace(2 * np.pi * s / 16, 2 * np.pi * (s + 1) / 16, 5)
        return np.vstack([[0.0, 0.0], 2.1e4 * np.column_stack([np.cos(a), np.sin(a)])])

    found = []
    for seed in range(2):
        rng = np.random.default_rng(seed)
        pipe = TrackingPipeline.all_kinds(TrackerConfig())
        centre = np.array([5e3, 1e3])
        for k in range(80):
            patch = centre + rng.uniform(-250, 250, (rng.poisson(8), 2))
            n = rng.poisson(10)
            r, a = np.sqrt(rng.uniform(0, 4e8, n)), rng.uniform(0, 2 * np.pi, n)
            z = np.vstack([patch, np.column_stack([r * np.cos(a), r * np.sin(a)])])
            b = np.mod(np.arctan2(z[:, 1], z[:, 0]), 2 * np.pi)
            for s in range(16):
                zs = z[(b >= 2 * np.pi * s / 16) & (b < 2 * np.pi * (s + 1) / 16)]
                scan = Scan(
                    "r",
                    2.5 * k + 2.5 * (s + 1) / 16,
                    zs,
                    _R(len(zs), 30.0),
                    coverage=Coverage(polygon=sector(s)),
                    sensor_position=np.zeros(2),
                )
                res = pipe.process(scan)
            if k >= 40:
                p = np.array([c.position for c in res.confirmed() if c.kind == "individual"])
                found.append(int(np.sum(np.all(np.abs(p.reshape(-1, 2) - centre) < 400, axis=1))))
    assert np.mean(found) < 0.3
