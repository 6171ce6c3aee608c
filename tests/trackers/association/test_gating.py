import numpy as np
import pytest
from scipy.stats import multivariate_normal

from trackers.association.gating import (
    expected_false_alarms,
    gate,
    inverse_2x2,
    log_gaussian_2d,
    max_eigenvalue_2x2,
)


def brute_force_pairs(z_pred, P_pred, z, R, gamma):
    out = set()
    for i in range(len(z_pred)):
        for j in range(len(z)):
            nu = z[j] - z_pred[i]
            d2 = nu @ np.linalg.solve(P_pred[i] + R[j], nu)
            if d2 <= gamma:
                out.add((i, j))
    return out


def random_spd(rng, n, scale):
    A = rng.normal(size=(n, 2, 2)) * scale
    return A @ A.transpose(0, 2, 1) + np.eye(2) * scale**2 * 0.1


def test_max_eigenvalue_matches_numpy():
    rng = np.random.default_rng(1)
    A = random_spd(rng, 50, 3.0)
    np.testing.assert_allclose(max_eigenvalue_2x2(A), np.linalg.eigvalsh(A)[:, -1], rtol=1e-12)


def test_inverse_and_log_density_match_scipy():
    rng = np.random.default_rng(2)
    S = random_spd(rng, 20, 2.0)
    nu = rng.normal(size=(20, 2))
    inv, det = inverse_2x2(S)
    np.testing.assert_allclose(inv, np.linalg.inv(S), rtol=1e-10)
    np.testing.assert_allclose(det, np.linalg.det(S), rtol=1e-10)
    d2, logpdf = log_gaussian_2d(nu, S)
    expected = [multivariate_normal(np.zeros(2), S[k]).logpdf(nu[k]) for k in range(20)]
    np.testing.assert_allclose(logpdf, expected, rtol=1e-10)
    np.testing.assert_allclose(d2, [nu[k] @ np.linalg.solve(S[k], nu[k]) for k in range(20)])


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_gate_finds_exactly_the_brute_force_pairs(seed):
    rng = np.random.default_rng(seed)
    z_pred = rng.uniform(-200, 200, size=(40, 2))
    P_pred = random_spd(rng, 40, rng.uniform(2, 30))
    z = rng.uniform(-200, 200, size=(60, 2))
    R = random_spd(rng, 60, 5.0)
    gamma = 9.21
    pairs = gate(z_pred, P_pred, z, R, gamma)
    got = set(zip(pairs.track.tolist(), pairs.detection.tolist(), strict=True))
    assert got == brute_force_pairs(z_pred, P_pred, z, R, gamma)
    assert len(got) > 0
    for i, j, d2 in zip(pairs.track, pairs.detection, pairs.d2, strict=True):
        nu = z[j] - z_pred[i]
        assert d2 == pytest.approx(nu @ np.linalg.solve(P_pred[i] + R[j], nu))


def test_gate_uses_each_detection_covariance():
    # A detection 30 m away is outside the gate with R = I but inside with R = 400 I.
    z_pred = np.array([[0.0, 0.0]])
    P_pred = np.eye(2)[None]
    z = np.array([[30.0, 0.0], [30.0, 0.0]])
    R = np.stack([np.eye(2), 400 * np.eye(2)])
    pairs = gate(z_pred, P_pred, z, R, gamma=9.21)
    assert pairs.detection.tolist() == [1]


def test_gate_empty_inputs():
    assert (
        gate(
            np.zeros((0, 2)),
            np.zeros((0, 2, 2)),
            np.ones((3, 2)),
            np.tile(np.eye(2), (3, 1, 1)),
            9.0,
        ).size
        == 0
    )
    assert (
        gate(
            np.ones((3, 2)),
            np.tile(np.eye(2), (3, 1, 1)),
            np.zeros((0, 2)),
            np.zeros((0, 2, 2)),
            9.0,
        ).size
        == 0
    )


def test_expected_false_alarms_is_the_density_times_the_gate_area():
    """A gate of γ = 18.4 on S = diag(100², 50²) is an ellipse of semi-axes √γ·100 and
    √γ·50: area π γ · 5000 m², so 1e-6 per m² expects 0.289 false alarms; per density too."""
    det = np.array([100.0**2 * 50.0**2])
    assert expected_false_alarms(1e-6, det, 18.4)[0] == pytest.approx(np.pi * 18.4 * 5e-3)
    lam = np.array([1e-6, 2e-6])
    np.testing.assert_allclose(
        expected_false_alarms(lam, np.repeat(det, 2), 18.4), lam * np.pi * 18.4 * 5000.0
    )
