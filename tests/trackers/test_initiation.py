"""Velocity-gated two-point initiation: worked answers, hand-made scenes, bounded cost."""

import math
from dataclasses import replace

import numpy as np
import pytest

import trackers.initiation as initiation
from trackers.config import TrackerConfig
from trackers.individual import IndividualTracker
from trackers.initiation import Candidates, pair_candidates, search_radius, two_point_estimate


def scan_at(t, points, sigma=30.0, lam=1e-8, pd=0.9):
    from trackers.types import Scan

    z = np.asarray(points, dtype=float).reshape(-1, 2)
    return Scan(
        "r1", float(t), z, np.tile(sigma**2 * np.eye(2), (len(z), 1, 1)), pd=pd, clutter_density=lam
    )


def candidates_at(z, variance=100.0):
    """Candidates of score 0 at time 0, one per row of ``z``, with covariance ``variance I``."""
    n = len(z)
    return Candidates(
        z=np.asarray(z, dtype=float),
        R=np.tile(variance * np.eye(2), (n, 1, 1)),
        time=np.zeros(n),
        score=np.zeros(n),
        detection_ids=np.empty(n, dtype=object),
        origin=np.arange(n),
        group_velocity=np.full((n, 2), np.nan),
        offered=np.zeros(n, dtype=np.int64),
        serial=np.arange(n),
    )


#: pair_candidates settings of the hand-made cases (the defaults' max speed and gate).
PAIRING = dict(
    max_speed=700.0, velocity_std=15.0, slow_fraction=0.8, q=0.5, gamma=18.4, max_pairs=8, pd=0.9
)


def test_fast_component_is_the_two_point_difference():
    """With v_max Δt far beyond the noise and a negligible slow weight the state is the
    classical two-point estimate: p = z_j, v = (z_j − z_c)/Δt, cov(v) = (R_c + R_j)/Δt²."""
    Rc, Rj = np.diag([400.0, 100.0]), np.diag([900.0, 225.0])
    zc, zj, dt = np.array([0.0, 0.0]), np.array([1200.0, -400.0]), 4.0
    x, P, _ = two_point_estimate(
        zc, Rc, zj, Rj, dt, max_speed=5000.0, velocity_std=1.0, slow_fraction=1e-12, q=0.0
    )
    np.testing.assert_allclose(x[0, :2], zj, atol=0.05)
    np.testing.assert_allclose(x[0, 2:], (zj - zc) / dt, rtol=1e-3)
    np.testing.assert_allclose(P[0, :2, :2], Rj, rtol=1e-3)
    np.testing.assert_allclose(P[0, 2:, 2:], (Rc + Rj) / dt**2, rtol=2e-3)
    np.testing.assert_allclose(P[0, :2, 2:], Rj / dt, rtol=1e-3)


def test_slow_component_is_the_kalman_filter_of_a_gaussian_velocity_prior():
    """With all weight on the slow component the result is the Kalman update of the prior
    [z_c, 0], diag(R_c, σ² I), predicted by F over Δt, with z_j."""
    Rc, Rj, s, dt = 25.0 * np.eye(2), 36.0 * np.eye(2), 10.0, 1.5
    zc, zj = np.array([10.0, 20.0]), np.array([25.0, 5.0])
    x, P, loglik = two_point_estimate(
        zc, Rc, zj, Rj, dt, max_speed=700.0, velocity_std=s, slow_fraction=1 - 1e-15, q=0.0
    )
    F = np.block([[np.eye(2), dt * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
    P0 = F @ np.diag([25.0, 25.0, s**2, s**2]) @ F.T
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    S = H @ P0 @ H.T + Rj
    K = P0 @ H.T @ np.linalg.inv(S)
    x_ref = np.r_[zc, 0.0, 0.0] + K @ (zj - zc)
    np.testing.assert_allclose(x[0], x_ref, atol=1e-9)
    np.testing.assert_allclose(P[0], P0 - K @ S @ K.T, atol=1e-9)
    nu = zj - zc
    ref = (
        -0.5 * nu @ np.linalg.solve(S, nu)
        - math.log(2 * math.pi)
        - 0.5 * math.log(np.linalg.det(S))
    )
    assert loglik[0] == pytest.approx(ref, abs=1e-9)


@pytest.mark.parametrize(
    ("speed", "period"), [(680.0, 2.0), (250.0, 4.0), (600.0, 0.5), (0.0, 10.0)]
)
def test_a_target_of_any_speed_starts_with_the_defaults(speed, period):
    """Two detections make a tentative track, a few more confirm it, at any speed up to
    the configured maximum and any revisit from 0.5 to 10 s."""
    tr = IndividualTracker(TrackerConfig())
    rng = np.random.default_rng(1)
    heading = np.array([math.cos(0.7), math.sin(0.7)])
    first_track, first_confirmed = None, None
    for k in range(8):
        truth = np.array([3000.0, -2000.0]) + speed * k * period * heading
        res = tr.step(scan_at(k * period, truth + rng.normal(0, 30.0, 2)))
        if res.tracks and first_track is None:
            first_track = k
        if res.confirmed() and first_confirmed is None:
            first_confirmed = k
            (t,) = res.confirmed()
            np.testing.assert_allclose(t.velocity, speed * heading, atol=max(25.0, 0.1 * speed))
    assert first_track == 1
    assert first_confirmed is not None and first_confirmed <= 4


def test_a_lone_false_alarm_starts_nothing():
    tr = IndividualTracker(TrackerConfig())
    res = tr.step(scan_at(0.0, [[5000.0, 5000.0]]))
    assert res.tracks == ()
    for k in range(1, 6):
        res = tr.step(scan_at(2.0 * k, np.zeros((0, 2))))
        assert res.tracks == ()
    assert len(tr.candidates) == 0  # dropped by its score or its age


def test_single_point_method_cannot_start_a_fast_target():
    """The old start, kept as a method: a 250 m/s target at T = 4 s is never initiated."""
    cfg = TrackerConfig().merged({"initiation": {"method": "single_point"}})
    tr = IndividualTracker(cfg)
    for k in range(8):
        res = tr.step(scan_at(4.0 * k, [[1000.0 * k, 0.0]]))
    assert res.confirmed() == ()


def test_candidate_pairs_stay_bounded_in_dense_clutter():
    """2,000 false alarms a scan within reach of every candidate: each candidate makes at most
    max_pairs_per_candidate pairs, found through the k-d tree."""
    rng = np.random.default_rng(2)
    n = 2000
    cand = candidates_at(rng.uniform(-1000, 1000, (n, 2)))
    z = rng.uniform(-1000, 1000, (n, 2))
    R = np.tile(100.0 * np.eye(2), (n, 1, 1))
    pairs = pair_candidates(
        cand, z, R, np.ones(n, dtype=bool), 1.0, clutter_density=1e-4, **PAIRING
    )
    per_candidate = np.bincount(pairs.candidate, minlength=n)
    assert per_candidate.max() <= 8
    assert pairs.size <= 8 * n


def test_tracker_keeps_new_tracks_bounded_in_dense_clutter():
    """Scan after scan of dense clutter: the tracker's candidates and tracks stay below fixed
    multiples of the detections a scan, and none is confirmed."""
    tr = IndividualTracker(TrackerConfig())
    rng = np.random.default_rng(3)
    n = 500
    for k in range(10):
        res = tr.step(scan_at(k, rng.uniform(-5000, 5000, (n, 2)), sigma=10.0, lam=n / 1e8))
        assert len(tr.candidates) <= 3 * n
        assert len(res.tracks) <= 3 * n
    assert res.confirmed() == ()


def test_two_targets_a_formation_apart_get_two_tracks():
    """Two parallel fast targets 250 m apart: rival pairs (each candidate with each second
    detection) are resolved by the third scan, one track each with the right velocity."""
    tr = IndividualTracker(TrackerConfig())
    v = np.array([-200.0, 300.0])
    rng = np.random.default_rng(4)
    for k in range(7):
        pts = np.array([[5000.0, 800.0], [5200.0, 960.0]]) + v * k
        res = tr.step(scan_at(float(k), pts + rng.normal(0, 20.0, (2, 2)), sigma=20.0))
    conf = res.confirmed()
    assert len(conf) == 2
    for t in conf:
        np.testing.assert_allclose(t.velocity, v, atol=25.0)


def test_a_start_is_not_lost_to_a_weaker_tentative_track_crossing_it():
    """A fast tentative track made of two false alarms passes over a parked target and takes
    its second detection. The target's own pair scores higher than that track, so it still
    starts a track at that scan, at rest, beside the one that took the detection."""
    tr = IndividualTracker(TrackerConfig())
    lam = 1e-6
    tr.step(scan_at(-1.0, [[0.0, -200.0]], lam=lam))  # false alarms at 100 m/s ...
    tr.step(scan_at(0.0, [[0.0, -100.0], [5.0, 0.0]], lam=lam))  # ... and the target
    res = tr.step(scan_at(1.0, [[0.0, 0.0]], lam=lam))
    crossing = [t for t in res.tracks if t.hits == 3]
    assert crossing and crossing[0].velocity[1] > 30.0  # the detection went to this one
    at_rest = [t for t in res.tracks if t.hits == 2 and np.hypot(*t.velocity) < 30.0]
    assert len(at_rest) == 1 and np.hypot(*at_rest[0].position) < 30.0


def test_pairs_below_a_detections_floor_are_left_out():
    """``min_score`` per detection: the same pair is kept under a low floor and dropped under
    one above its score."""
    cand = candidates_at(np.zeros((1, 2)))
    z = np.array([[5.0, 0.0]])
    R = np.tile(100.0 * np.eye(2), (1, 1, 1))
    kw = dict(clutter_density=1e-6, **PAIRING)
    kept = pair_candidates(cand, z, R, np.ones(1, dtype=bool), 1.0, min_score=np.zeros(1), **kw)
    assert kept.size == 1
    floor = np.array([kept.score[0] + 0.1])
    assert pair_candidates(cand, z, R, np.ones(1, dtype=bool), 1.0, min_score=floor, **kw).size == 0


@pytest.mark.parametrize(
    ("clutter_density", "score", "dt"),
    [(1e-6, -2.3, 5.0), (1e-6, -4.6, 10.0), (1e-8, 0.0, 4.0), (1e-4, -1.0, 1.0), (1e-6, 2.0, 0.5)],
)
def test_the_search_radius_drops_no_pair_that_would_be_kept(
    monkeypatch, clutter_density, score, dt
):
    """Pairs found within the score bound's radius are exactly those found when every
    candidate searches its whole velocity gate, whatever the clutter and candidate score."""
    rng = np.random.default_rng(7)
    n = 300
    cand = candidates_at(rng.uniform(-20e3, 20e3, (n, 2)), variance=400.0)
    cand = Candidates(**{**cand.__dict__, "score": np.full(n, score)})
    z = rng.uniform(-20e3, 20e3, (n, 2))
    z[:40] = cand.z[:40] + rng.normal(0, 60.0, (40, 2))  # slow movers among the clutter
    R = np.tile(np.diag([2500.0, 400.0]), (n, 1, 1))
    kwargs = dict(PAIRING, clutter_density=clutter_density, min_score=-6.9)
    bounded = pair_candidates(cand, z, R, np.ones(n, dtype=bool), dt, **kwargs)

    def whole_gate(dt, base, noise, floor, *, max_speed, gamma, **_):
        return max_speed * dt + np.sqrt(gamma * noise)

    monkeypatch.setattr(initiation, "search_radius", whole_gate)
    reference = pair_candidates(cand, z, R, np.ones(n, dtype=bool), dt, **kwargs)
    assert reference.size > 0
    for field in ("candidate", "detection", "x", "P", "score"):
        np.testing.assert_array_equal(getattr(bounded, field), getattr(reference, field))


def test_the_search_radius_shrinks_to_slow_reach_where_fast_starts_cannot_score():
    """With 1e-6 false alarms per m², a candidate that has missed a scan cannot start a fast
    track: its search is a slow target's reach, not 700 m/s times the interval; with sparse
    clutter the whole velocity gate is searched."""
    dt = np.array([10.0])
    noise = np.array([800.0])
    kwargs = dict(max_speed=700.0, velocity_std=15.0, slow_fraction=0.8, q=0.5, gamma=18.4)
    base = -4.6 + math.log(0.9 / 1e-6)
    r = search_radius(dt, np.array([base]), noise, -6.9, **kwargs)[0]
    assert 0 < r < 1000.0
    sparse = -4.6 + math.log(0.9 / 1e-9)
    r = search_radius(dt, np.array([sparse]), noise, -6.9, **kwargs)[0]
    assert r == pytest.approx(700.0 * 10.0 + math.sqrt(18.4 * 800.0))
    hopeless = search_radius(dt, np.array([-40.0]), noise, -6.9, **kwargs)[0]
    assert hopeless < 0


def _reference_two_point(
    zc,
    Rc,
    zj,
    Rj,
    dt,
    *,
    max_speed,
    velocity_std,
    slow_fraction,
    q,
    group_velocity=None,
    group_fraction=0.0,
    group_velocity_std=1.0,
):
    """One pair the long way: the Kalman update of each component's prior (slow, fast and,
    with a group velocity, the group's), predicted by the nearly constant velocity model,
    with the second detection; the moment-matched mixture."""
    F = np.block([[np.eye(2), dt * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
    Q = q * np.block(
        [[dt**3 / 3 * np.eye(2), dt**2 / 2 * np.eye(2)], [dt**2 / 2 * np.eye(2), dt * np.eye(2)]]
    )
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    grouped = group_velocity is not None and np.isfinite(group_velocity).all()
    priors = [(np.zeros(2), velocity_std**2), (np.zeros(2), 0.5 * max_speed**2)]
    if grouped:
        priors.append((np.asarray(group_velocity, float), group_velocity_std**2))
    xs, Ps = [], []
    for v0, var in priors:
        x0 = F @ np.r_[zc, v0]
        P0 = F @ np.diag([0.0, 0.0, var, var]) @ F.T + Q
        P0[:2, :2] += Rc
        S = H @ P0 @ H.T + Rj
        K = P0 @ H.T @ np.linalg.inv(S)
        xs.append(x0 + K @ (zj - x0[:2]))
        Ps.append(P0 - K @ S @ K.T)
    rest = math.log1p(-group_fraction) if grouped else 0.0
    logw = []
    for v0, std, weight in ((np.zeros(2), velocity_std, math.log(slow_fraction) + rest),) + (
        ((group_velocity, group_velocity_std, math.log(group_fraction)),) if grouped else ()
    ):
        d = zj - zc - np.asarray(v0) * dt
        S_m = Rc + Rj + (std**2 * dt**2 + q * dt**3 / 3) * np.eye(2)
        logw.append(
            weight
            - 0.5 * d @ np.linalg.solve(S_m, d)
            - math.log(2 * math.pi)
            - 0.5 * math.log(np.linalg.det(S_m))
        )
    g_f = 1.0 / (math.pi * (max_speed * dt) ** 2 + 2 * math.pi * math.sqrt(np.linalg.det(Rc + Rj)))
    logw.insert(1, math.log1p(-slow_fraction) + rest + math.log(g_f))
    loglik = np.logaddexp.reduce(logw)
    beta = np.exp(np.array(logw) - loglik)
    x = sum(b * xm for b, xm in zip(beta, xs, strict=True))
    P = sum(b * (Pm + np.outer(xm - x, xm - x)) for b, xm, Pm in zip(beta, xs, Ps, strict=True))
    return x, P, loglik


def _random_covariances(rng, n, scale):
    A = rng.normal(0.0, scale, (n, 2, 2))
    return A @ A.transpose(0, 2, 1) + 0.1 * scale**2 * np.eye(2)


@pytest.mark.parametrize("seed", range(4))
def test_two_point_estimate_matches_per_pair_kalman_updates(seed):
    """The vectorised mixture agrees with two Kalman updates and the moment matching done
    pair by pair, for pairs from slow to fast, close to far apart in time."""
    rng = np.random.default_rng(seed)
    n = 40
    kw = dict(max_speed=700.0, velocity_std=15.0, slow_fraction=0.8, q=0.5)
    zc = rng.uniform(-1e4, 1e4, (n, 2))
    dt = rng.uniform(0.05, 12.0, n)
    speed = np.where(rng.random(n) < 0.5, rng.uniform(0, 30, n), rng.uniform(30, 700, n))
    heading = rng.uniform(0, 2 * math.pi, n)
    zj = zc + (speed * dt)[:, None] * np.c_[np.cos(heading), np.sin(heading)]
    Rc, Rj = _random_covariances(rng, n, 20.0), _random_covariances(rng, n, 40.0)
    x, P, loglik = two_point_estimate(zc, Rc, zj, Rj, dt, **kw)
    for i in range(n):
        x_ref, P_ref, ll_ref = _reference_two_point(zc[i], Rc[i], zj[i], Rj[i], dt[i], **kw)
        np.testing.assert_allclose(x[i], x_ref, rtol=1e-12, atol=1e-12 * np.abs(x_ref).max())
        np.testing.assert_allclose(P[i], P_ref, rtol=1e-10, atol=1e-12 * np.abs(P_ref).max())
        assert loglik[i] == pytest.approx(ll_ref, rel=1e-12, abs=1e-12)
        np.testing.assert_array_equal(P[i], P[i].T)


@pytest.mark.parametrize("seed", range(3))
def test_the_group_component_matches_per_pair_kalman_updates(seed):
    """With group velocities (some pairs without: NaN), the three-component mixture agrees
    with the Kalman updates and moment matching done pair by pair."""
    rng = np.random.default_rng(100 + seed)
    n = 30
    kw = dict(max_speed=700.0, velocity_std=15.0, slow_fraction=0.8, q=0.5)
    group = dict(group_fraction=0.5, group_velocity_std=10.0)
    zc = rng.uniform(-1e4, 1e4, (n, 2))
    dt = rng.uniform(0.1, 6.0, n)
    vg = rng.uniform(-400.0, 400.0, (n, 2))
    v = np.where(rng.random(n)[:, None] < 0.6, vg + rng.normal(0, 10.0, (n, 2)), -vg)
    vg[rng.random(n) < 0.3] = np.nan
    zj = zc + v * dt[:, None]
    Rc, Rj = _random_covariances(rng, n, 20.0), _random_covariances(rng, n, 40.0)
    x, P, loglik = two_point_estimate(zc, Rc, zj, Rj, dt, group_velocity=vg, **kw, **group)
    for i in range(n):
        x_ref, P_ref, ll_ref = _reference_two_point(
            zc[i], Rc[i], zj[i], Rj[i], dt[i], group_velocity=vg[i], **kw, **group
        )
        np.testing.assert_allclose(x[i], x_ref, rtol=1e-9, atol=1e-9 * np.abs(x_ref).max())
        np.testing.assert_allclose(P[i], P_ref, rtol=1e-8, atol=1e-9 * np.abs(P_ref).max())
        assert loglik[i] == pytest.approx(ll_ref, rel=1e-10, abs=1e-10)
    # Without any group velocity the result is the two-component mixture, bit for bit.
    none = np.full((n, 2), np.nan)
    a = two_point_estimate(zc, Rc, zj, Rj, dt, group_velocity=none, **kw, **group)
    b = two_point_estimate(zc, Rc, zj, Rj, dt, **kw)
    for u, w in zip(a, b, strict=True):
        np.testing.assert_array_equal(u, w)


def test_a_group_velocity_prunes_the_pair_with_a_neighbours_detection():
    """A candidate beside a fast confirmed track (its group velocity (300, 0) m/s) and, one
    second later, its own detection and a neighbour's 250 m to the side: as a fast target
    alone both pairs are alike and both start tracks; with the group's velocity its own is
    far likelier, and the other is pruned."""
    cand = candidates_at(np.zeros((1, 2)))
    z = np.array([[302.0, 5.0], [300.0, 250.0]])
    R = np.tile(100.0 * np.eye(2), (2, 1, 1))
    kw = dict(clutter_density=1e-6, **PAIRING)
    free = np.ones(2, dtype=bool)
    alone = pair_candidates(cand, z, R, free, 1.0, **kw)
    assert sorted(alone.detection.tolist()) == [0, 1]
    grouped = replace(cand, group_velocity=np.array([[300.0, 0.0]]))
    with_group = pair_candidates(
        grouped, z, R, free, 1.0, group_fraction=0.5, group_velocity_std=10.0, **kw
    )
    assert with_group.detection.tolist() == [0]
    assert with_group.score[0] > alone.score[alone.detection == 0][0] + 3.0
    np.testing.assert_allclose(with_group.x[0, 2:], [300.0, 0.0], atol=15.0)
    assert np.sqrt(with_group.P[0, 2, 2]) < 15.0


def test_a_new_candidate_takes_the_velocity_of_the_nearest_fast_confirmed_track():
    """A detection that opens a candidate within group_radius of a confirmed track at least
    group_min_speed fast gets that track's velocity; far away, or beside a slow track, none."""
    tr = IndividualTracker(TrackerConfig())
    v = np.array([-200.0, 300.0])
    parked = np.array([-20000.0, 0.0])
    for k in range(8):
        res = tr.step(scan_at(float(k), [[5000.0, 800.0] + v * k, parked], sigma=20.0))
    assert len(res.confirmed()) == 2
    fast = next(t for t in res.confirmed() if np.hypot(*t.velocity) > 100.0)
    # Three new detections: 400 m from the fast track, 5 km from it, 300 m from the parked one.
    near = np.asarray(fast.position) + v + [400.0, 0.0]
    far = np.asarray(fast.position) + v + [5000.0, 0.0]
    tr.step(scan_at(8.0, [[5000.0, 800.0] + v * 8, parked, near, far, parked + 300.0], sigma=20.0))
    cand = tr.candidates
    fresh = cand.time == 8.0
    by_place = {
        tuple(np.round(z)): g
        for z, g in zip(cand.z[fresh], cand.group_velocity[fresh], strict=True)
    }
    np.testing.assert_allclose(by_place[tuple(np.round(near))], fast.velocity, atol=30.0)
    assert np.isnan(by_place[tuple(np.round(far))]).all()
    assert np.isnan(by_place[tuple(np.round(parked + 300.0))]).all()


@pytest.mark.parametrize("dense", [False, True])
@pytest.mark.parametrize("floor", [-math.inf, -6.9, 0.0, "per_detection"])
def test_small_problems_score_every_pair_with_the_same_result_as_the_search(
    monkeypatch, dense, floor
):
    """Up to BRUTE_FORCE_CELLS pairs every pair is scored; the kept pairs, their order,
    states and scores are exactly those of the search that larger problems use."""
    rng = np.random.default_rng(11 if dense else 12)
    span = 3e3 if dense else 60e3
    kept = 0
    for _ in range(6):
        n_c, n_z = rng.integers(1, 60), rng.integers(1, 60)
        t = 10.0
        cand = Candidates(
            z=rng.uniform(-span, span, (n_c, 2)),
            R=_random_covariances(rng, n_c, 15.0),
            time=t - rng.choice([0.0, 1.0, 2.0, 4.0, 9.0], n_c),  # some not offered (Δt = 0)
            score=rng.uniform(-5.0, 3.0, n_c),
            detection_ids=np.empty(n_c, dtype=object),
            origin=np.arange(n_c),
            group_velocity=np.full((n_c, 2), np.nan),
            offered=np.zeros(n_c, dtype=np.int64),
            serial=np.arange(n_c),
        )
        z = rng.uniform(-span, span, (n_z, 2))
        near = rng.integers(0, n_c, n_z // 2)
        z[: near.size] = cand.z[near] + rng.normal(0.0, 300.0, (near.size, 2))
        R = _random_covariances(rng, n_z, 15.0)
        free = rng.random(n_z) < 0.8
        min_score = rng.uniform(-8.0, 2.0, n_z) if floor == "per_detection" else floor
        kwargs = dict(PAIRING, clutter_density=1e-5 if dense else 1e-9, min_score=min_score)
        small = pair_candidates(cand, z, R, free, t, **kwargs)
        monkeypatch.setattr(initiation, "BRUTE_FORCE_CELLS", 0)
        searched = pair_candidates(cand, z, R, free, t, **kwargs)
        monkeypatch.undo()
        for field in ("candidate", "detection", "x", "P", "score"):
            np.testing.assert_array_equal(getattr(small, field), getattr(searched, field))
        kept += small.size
    assert kept > 0 or floor == 0.0


ALLOWANCE = dict(pd=0.9, clutter_density=1e-6, max_speed=700.0, slow_fraction=0.8, floor=-6.9)


def test_a_fresh_candidate_in_sparse_surroundings_may_fall_short_by_a_third_hit():
    """h = ln(P_D / (2π √|6 R_c| λ)) − 1 for a candidate at its first scan whose fast pairs
    cannot pass the floor (Δt = 4 s: ln(P_D ḡ_f / λ) = −4.9) and around which fewer
    detections lie than a fifth of what λ predicts within its reach (2.8 km: 24.6); else 0."""
    cand = candidates_at([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]], variance=900.0)
    cand = replace(cand, score=np.full(3, -2.3))
    fresh = np.array([True, False, True])
    z = np.array([[1000.0, 0.0], [50_000.0, 0.0]])
    h = initiation.next_hit_allowance(cand, fresh, z, np.ones(2, bool), 4.0, **ALLOWANCE)
    expected = math.log(0.9 / (2 * math.pi * 6 * 900.0 * 1e-6)) - 1.0
    np.testing.assert_allclose(h, [expected, 0.0, expected])
    # a detection-rich neighbourhood: as dense as assumed, no allowance
    dense = np.random.default_rng(0).uniform(-2000.0, 2000.0, (60, 2))
    h = initiation.next_hit_allowance(cand, fresh, dense, np.ones(60, bool), 4.0, **ALLOWANCE)
    assert (h == 0.0).all()
    # a line of aircraft on one airway, 1 km apart: few in reach although they span no area
    line = np.column_stack([1000.0 * np.arange(10), np.zeros(10)])
    h = initiation.next_hit_allowance(cand, fresh, line, np.ones(10, bool), 4.0, **ALLOWANCE)
    np.testing.assert_allclose(h, [expected, 0.0, expected])
    # at a short revisit its fast pairs pass by themselves: no allowance needed
    h = initiation.next_hit_allowance(cand, fresh, z, np.ones(2, bool), 1.0, **ALLOWANCE)
    assert (h == 0.0).all()


@pytest.mark.parametrize("period", [4.0, 8.0])
def test_fast_targets_at_a_long_revisit_start_without_a_stated_clutter_density(period):
    """Three aircraft at 250-450 m/s, 400 m apart, one radar every 4 or 8 s, 30 m noise, no
    clutter density in the scans (the configured 1e-6 per m² applies): each gets a confirmed
    track. Before, every pair scored below the deletion threshold (the fast prior spread
    over π (v_max Δt)²) and no track ever started."""
    rng = np.random.default_rng(5)
    v = np.array([[0.0, 250.0], [0.0, 350.0], [0.0, 450.0]])
    p0 = np.array([[20000.0, 5000.0], [20400.0, 5100.0], [20800.0, 5200.0]])
    tr = IndividualTracker(TrackerConfig())
    for k in range(16):
        pts = p0 + v * period * k + rng.normal(0.0, 30.0, (3, 2))
        res = tr.step(replace(scan_at(period * k, pts, sigma=30.0), clutter_density=None))
    conf = res.confirmed()
    truth = p0 + v * period * 15
    assert len(conf) == 3
    for t in conf:
        assert np.hypot(*(truth - np.array(t.position)).T).min() < 100.0


def test_the_allowance_never_lets_a_pair_below_the_tentative_track_it_must_beat():
    """A pair on a detection a tentative track took must outscore that track, allowance or
    not; the allowance lowers only the deletion threshold."""
    cand = candidates_at([[0.0, 0.0]])
    z = np.array([[100.0, 0.0]])
    R = np.tile(100.0 * np.eye(2), (1, 1, 1))
    kw = dict(PAIRING, clutter_density=1e-6, min_score=np.array([50.0]))
    assert pair_candidates(cand, z, R, np.ones(1, bool), 1.0, **kw).size == 0
    allowed = dict(kw, allowance=np.array([100.0]))
    assert pair_candidates(cand, z, R, np.ones(1, bool), 1.0, **allowed).size == 1
    rival = dict(allowed, rivals=np.array([50.0]))
    assert pair_candidates(cand, z, R, np.ones(1, bool), 1.0, **rival).size == 0
