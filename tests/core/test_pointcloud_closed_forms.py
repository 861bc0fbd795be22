"""The closed forms of Forbes 2025 section 6 against the full V_X construction of eq. (28).

Each test switches on one influence factor, builds the dense 3m x 3m V_X and evaluates the
quadratic forms of eq. (29) (distances) and section 6 (differences of distances) literally."""

import numpy as np
import pytest

from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.errors import DegenerateGeometryError, ModelError
from cmmwb.xlfuncs.model import skew

rng = np.random.default_rng(20250101)


def cloud(m=6, probes=1, spread=400.0):
    X = rng.uniform(-spread, spread, (m, 3))
    N = rng.normal(size=(m, 3))
    N /= np.linalg.norm(N, axis=1)[:, None]
    P = tuple(pc.Probe(f"P{k + 1}", tuple(rng.uniform(-40, 40, 3))) for k in range(probes))
    return pc.PointCloud(X, N, np.arange(m) % probes, P)


def unit(v):
    return v / np.linalg.norm(v)


def only(**kw):
    return pc.Parameters(**kw)


def dense_u(c, p, i, j, factor):
    return pc.distance_u_dense(pc.V_X_components(c, p)[factor], c.X_mm, i, j)


def test_6_1_repeatability():
    c, p = cloud(), only(sigma_R_um=0.3)
    V = pc.V_X(c, p)
    assert pc.distance_u_dense(V, c.X_mm, 0, 3) == pytest.approx(np.sqrt(2) * 0.3, rel=1e-12)
    assert pc.distance_difference_u(V, c.X_mm, (0, 1), (2, 3)) == pytest.approx(2 * 0.3, rel=1e-12)


def test_6_2_probe_qualification_two_probes():
    c = cloud(m=4, probes=2)  # points 0, 2 on P1; 1, 3 on P2
    p = only(sigma_PQ_um=0.25)
    V = pc.V_X(c, p)
    assert pc.distance_u_dense(V, c.X_mm, 0, 2) == pytest.approx(0.0, abs=1e-12)  # same probe
    assert pc.distance_u_dense(V, c.X_mm, 0, 1) == pytest.approx(np.sqrt(2) * 0.25, rel=1e-12)
    # k(i) = k(r), k(j) = k(s): (2 - 2 n_ij.n_rs)(s_i^2 + s_j^2)
    n01, n23 = unit(c.X_mm[1] - c.X_mm[0]), unit(c.X_mm[3] - c.X_mm[2])
    expect = np.sqrt((2 - 2 * n01 @ n23) * 2 * 0.25**2)
    assert pc.distance_difference_u(V, c.X_mm, (0, 1), (2, 3)) == pytest.approx(expect, rel=1e-10)


def test_6_3_scale_and_squareness_eq_31():
    c = cloud()
    p = only(sigma_S_ppm=0.7, sigma_Sa_ppm=1.1, sigma_Q_ppm=0.4)
    u = c.ram_mm
    for i, j in [(0, 1), (2, 5)]:
        x, y, z = u[j] - u[i]
        d2 = x * x + y * y + z * z
        # eq. (31) with the ram-coordinate differences (the sensitivities act on x - p)
        var = ((0.7e-3) ** 2 * d2 + (1.1e-3) ** 2 * (x**4 + y**4 + z**4) / d2
               + (0.4e-3) ** 2 * (x * x * y * y + x * x * z * z + y * y * z * z) / d2)
        # eq. (31) assumes the distance direction equals the ram difference direction (one probe)
        assert dense_u(c, p, i, j, "S") == pytest.approx(np.sqrt(var), rel=1e-10)


def test_6_3_erratum_tau_squared_over_two():
    """With sigma_Q^2 = 2 sigma_Sa^2 = tau^2 the variance is (sigma_S^2 + tau^2/2) d^2, not
    (sigma_S^2 + tau^2) d^2 as printed in section 6.3 (see docs/errata.md)."""
    tau = 1.0
    c = cloud()
    p = only(sigma_S_ppm=0.5, sigma_Sa_ppm=tau / np.sqrt(2), sigma_Q_ppm=tau)
    for i, j in [(0, 1), (1, 4), (3, 5)]:
        d = np.linalg.norm(c.X_mm[j] - c.X_mm[i])
        assert dense_u(c, p, i, j, "S") == pytest.approx(1e-3 * d * np.sqrt(0.5**2 + tau**2 / 2), rel=1e-10)


def test_6_3_diameters_along_axes_and_at_45_degrees():
    X = np.array([[-50, 0, 0], [50, 0, 0], [0, -50, 0], [0, 50, 0.0]])
    c = pc.PointCloud(X, np.tile([0, 0, 1.0], (4, 1)), np.zeros(4, int), (pc.Probe("P1"),))
    p = only(sigma_Sa_ppm=1.0, sigma_Q_ppm=1.0)
    V = pc.V_X(c, p)
    assert pc.distance_difference_u(V, X, (0, 1), (2, 3)) == pytest.approx(np.sqrt(2) * 100 * 1e-3, rel=1e-10)
    R = np.array([[np.cos(np.pi / 4), -np.sin(np.pi / 4), 0], [np.sin(np.pi / 4), np.cos(np.pi / 4), 0], [0, 0, 1]])
    c45 = pc.PointCloud(X @ R.T, c.N, c.probe_index, c.probes)
    V45 = pc.V_X(c45, p)
    assert pc.distance_difference_u(V45, c45.X_mm, (0, 1), (2, 3)) == pytest.approx(100 * 1e-3, rel=1e-10)


def test_6_4_location_errors():
    c, p = cloud(), only(sigma_ET_um=0.4, lambda_ET_mm=300)
    for i, j in [(0, 1), (2, 4)]:
        du = np.linalg.norm(c.ram_mm[j] - c.ram_mm[i])
        assert dense_u(c, p, i, j, "ET") == pytest.approx(np.sqrt(2 * 0.16 * (1 - np.exp(-du**2 / 300**2))), rel=1e-10)
    # difference of distances, one probe: 2 s^2 (2 - e_ij - e_rs + c (e_jr + e_is - e_ir - e_js))
    V = pc.V_X_components(c, p)["ET"]
    i, j, r, s = 0, 1, 2, 3
    e = lambda a, b: np.exp(-np.sum((c.ram_mm[a] - c.ram_mm[b]) ** 2) / 300**2)  # noqa: E731
    cc = unit(c.X_mm[j] - c.X_mm[i]) @ unit(c.X_mm[s] - c.X_mm[r])
    expect = 2 * 0.16 * (2 - e(i, j) - e(r, s) + cc * (e(j, r) + e(i, s) - e(i, r) - e(j, s)))
    assert pc.distance_difference_u(V, c.X_mm, (i, j), (r, s)) ** 2 == pytest.approx(expect, rel=1e-10)


def test_6_5_rotation_errors_two_probes():
    c = cloud(m=4, probes=2)
    p = only(sigma_ER_urad=5.0, lambda_ER_mm=250)
    i, j = 0, 1
    n = unit(c.X_mm[j] - c.X_mm[i])
    P = c.offsets_mm
    mi, mj = skew(P[i])[0].T @ n, skew(P[j])[0].T @ n
    rho = np.exp(-np.sum((c.ram_mm[j] - c.ram_mm[i]) ** 2) / 250**2)
    var = (5e-3) ** 2 * (mi @ mi + mj @ mj - 2 * (mi @ mj) * rho)
    assert dense_u(c, p, i, j, "ER") == pytest.approx(np.sqrt(var), rel=1e-10)


def test_6_6_probing_uni_and_bidirectional_eq_32():
    X = np.array([[0, 0, 0], [10, 0, 0], [20, 0, 0.0]])
    N = np.array([[-1, 0, 0], [1, 0, 0], [-1, 0, 0.0]])
    c = pc.PointCloud(X, N, np.zeros(3, int), (pc.Probe("P1"),))
    p = only(sigma_P0_um=0.1, sigma_P_um=0.2, lambda_P=0.5)
    assert dense_u(c, p, 0, 1, "P") == pytest.approx(np.sqrt(4 * 0.01 + 2 * 0.04 * (1 + np.exp(-16))) , rel=1e-12)
    assert dense_u(c, p, 0, 2, "P") == pytest.approx(0.0, abs=1e-12)
    # different probes are independent: s0i^2 + s0j^2 + si^2 + sj^2
    c2 = pc.PointCloud(X, N, np.array([0, 1, 0]), (pc.Probe("P1"), pc.Probe("P2", sigma_P0_um=0.3)))
    assert dense_u(c2, p, 0, 1, "P") == pytest.approx(np.sqrt(0.01 + 0.09 + 0.04 + 0.04), rel=1e-12)


@pytest.mark.parametrize("probes", [1, 2, 3])
def test_blocked_distances_equal_dense_quadratic_form(probes):
    """The pairwise evaluation without V_X equals eq. (29) on the dense V_X, every factor."""
    c = cloud(m=9, probes=probes)
    p = pc.Parameters(0.2, 0.7, 0.8, 0.9, 0.2, 0.3, 150, 4.0, 350, 0.1, 0.15, 0.5)
    r = pc.distance_components(c, p, block=7)  # small blocks exercise the block loop
    V = pc.V_X_components(c, p)
    # Variances are compared: a component that is exactly zero in theory (PQ of a one-probe
    # distance) comes out as 0 or as rounding noise of the size eps * u^2, whose square root
    # (1e-9 µm) is no measure of agreement.  Absolute tolerance: 1e-12 of the largest u^2.
    floor = 1e-12 * max(r["u_um"]) ** 2
    for q, (i, j) in enumerate(pc.all_pairs(c.m)):
        for f in pc.FACTORS:
            dense = pc.distance_u_dense(V[f], c.X_mm, i, j)
            assert r[f"u_{f}_um"][q] ** 2 == pytest.approx(dense ** 2, rel=1e-10, abs=floor)
        assert r["u_um"][q] == pytest.approx(pc.distance_u_dense(sum(V.values()), c.X_mm, i, j), rel=1e-10)


def test_summary_formula_33_bounds_the_full_model_along_an_axis():
    """Eq. (33) with the longest probe P is an upper bound of the full model for distances along
    an axis measured with one probe orthogonal to the line."""
    X = np.column_stack([np.linspace(0, 900, 10), np.zeros(10), np.zeros(10)])
    c = pc.PointCloud(X, np.tile([1.0, 0, 0], (10, 1)), np.zeros(10, int), (pc.Probe("P1", (0, 0, -50.0)),))
    p = pc.Parameters(0.2, 0.7, 0.7, 0.7, 0.2, 0.2, 200, 4.0, 400, 0.1, 0.1, 0.5)
    r = pc.distance_components(c, p)
    s = pc.summary_components_um(r["d_mm"], p, 50.0)
    assert np.all(r["u_um"] <= s["u"] + 1e-12)


def test_coincident_points_are_named():
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0.0]])
    c = pc.PointCloud(X, np.tile([1.0, 0, 0], (3, 1)), np.zeros(3, int), (pc.Probe("P1"),), ("A", "B", "C"))
    with pytest.raises(DegenerateGeometryError, match="A and C"):
        pc.distance_components(c, only(sigma_R_um=1))


def test_negative_or_missing_length_scale_is_refused():
    with pytest.raises(ModelError, match="sigma_R_um"):
        pc.Parameters(sigma_R_um=-1)
    with pytest.raises(ModelError, match="lambda_ET_mm"):
        pc.Parameters(sigma_ET_um=0.2)
    with pytest.raises(ModelError, match="lambda_ET_mm must be at least"):
        pc.Parameters(sigma_ET_um=0.2, lambda_ET_mm=1e-217)  # its square would underflow to 0
    with pytest.raises(ModelError, match="sigma_R_um = 1e\\+200 is beyond any CMM"):
        pc.Parameters(sigma_R_um=1e200)
