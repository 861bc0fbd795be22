"""Forbes 2022 fits and sensitivities (`xlfuncs.features`), propagated from the Forbes 2025 V_X.

The central check: for random point sets of every element type, V_A = G_A|X V_X G_A|X^T with
the full six-factor V_X agrees with a Monte Carlo of the complete nonlinear fit (20,000 draws
from N(0, V_X), each refitted) within the Monte Carlo sampling error.  The refit here is
deliberately independent of the core: geometric distance functions written out below, a
minimal parametrisation and finite-difference Gauss-Newton -- it shares no Jacobian, normal
or update rule with `xlfuncs.features`.
"""

import math

import numpy as np
import pytest

from cmmwb.xlfuncs import features, partial, pointcloud
from cmmwb.xlfuncs.errors import ConvergenceError, DegenerateGeometryError, ModelError
from cmmwb.xlfuncs.model import Workpiece


def random_rotation(rng):
    q = rng.normal(size=4)
    a, b, c, d = q / np.linalg.norm(q)
    return np.array([
        [a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)],
        [2 * (b * c + a * d), a * a - b * b + c * c - d * d, 2 * (c * d - a * b)],
        [2 * (b * d - a * c), 2 * (c * d + a * b), a * a - b * b - c * c + d * d]])


# ---- random point sets on patches of every element ------------------------------------------

def random_points(element, rng, m, space=False):
    """Nominal points (exactly on the element) and outward normals, in a random pose.
    Returns X, N, the true global parameter values by name, and kwargs for features.fit."""
    Q = random_rotation(rng)
    c = rng.uniform(-300, 300, size=3)
    t = rng.uniform(-1, 1, size=m)
    th = rng.uniform(-1, 1, size=m) * rng.uniform(0.5, 1.0) * math.pi
    kw = {}
    if element == "line":
        a = rng.uniform(20, 80)
        P = np.column_stack([np.zeros(m), np.zeros(m), a * t])
        N = np.tile([1.0, 0, 0], (m, 1))
        truth = {"r0_mm": None}
    elif element == "plane":
        P = np.column_stack([rng.uniform(-40, 40, m), rng.uniform(-15, 15, m), np.zeros(m)])
        N = np.tile([0, 0, 1.0], (m, 1))
        truth = {}
    elif element == "circle":
        r = rng.uniform(5, 50)
        P = np.column_stack([r * np.cos(th), r * np.sin(th), np.zeros(m)])
        N = np.column_stack([np.cos(th), np.sin(th), np.zeros(m)])
        truth = {"r0_mm": r}
        if not space:
            Q = random_rotation(rng) if False else np.eye(3)[:, [1, 2, 0]]  # circle in yz
            kw = {"circle_plane": "yz"}
        else:
            kw = {"circle_plane": None}
    elif element == "sphere":
        r = rng.uniform(5, 30)
        ph = np.arcsin(rng.uniform(0.0, 1.0, m))  # upper hemisphere, uniform by area
        n = np.column_stack([np.cos(th) * np.cos(ph), np.sin(th) * np.cos(ph), np.sin(ph)])
        P, N = r * n, n
        truth = {"r0_mm": r}
    elif element == "cylinder":
        r, a = rng.uniform(10, 50), rng.uniform(10, 60)
        P = np.column_stack([r * np.cos(th), r * np.sin(th), a * t])
        N = np.column_stack([np.cos(th), np.sin(th), np.zeros(m)])
        truth = {"r0_mm": r}
    elif element == "cone":
        r, a, phi = rng.uniform(30, 60), rng.uniform(10, 25), rng.uniform(0.2, 0.9)
        z = a * t
        rho = r - math.tan(phi) * z
        P = np.column_stack([rho * np.cos(th), rho * np.sin(th), z])
        N = np.column_stack([math.cos(phi) * np.cos(th), math.cos(phi) * np.sin(th),
                             np.full(m, math.sin(phi))])
        truth = {"r0_mm": r, "phi_rad": phi}
        kw = {"reference_mm": c}
    X = P @ Q.T + c
    return X, N @ Q.T, truth, kw


#: the part's temperature (the factor W): aluminium at 23.5 °C, held 150-200 mm away from the features
PART = Workpiece(23.1, 23.5, fixture_mm=(-150.0, 80.0, -40.0))


def cloud_for(X, N, rng):
    """Two probes with offsets, points assigned at random; the part's W."""
    probes = (pointcloud.Probe("P1", (0.0, 0.0, -60.0)),
              pointcloud.Probe("P2", (40.0, -10.0, -45.0), sigma_PQ_um=0.4))
    k = rng.integers(0, 2, size=X.shape[0])
    return pointcloud.PointCloud(X, N, k, probes, workpiece=PART)


#: every factor contributes visibly on 10-100 mm features
PARAMS = pointcloud.Parameters(
    sigma_R_um=0.6, sigma_S_ppm=8.0, sigma_Sa_ppm=6.0, sigma_Q_ppm=6.0, sigma_PQ_um=0.5,
    sigma_ET_um=1.0, lambda_ET_mm=60.0, sigma_ER_urad=15.0, lambda_ER_mm=150.0,
    sigma_P0_um=0.3, sigma_P_um=0.5, lambda_P=0.8, u_alpha_ppm_per_K=1.0, u_T_K=0.3)


# ---- an independent refit for the Monte Carlo -----------------------------------------------

def _unit(b):
    return b / np.linalg.norm(b, axis=-1, keepdims=True)


def residuals(kind, p, Y):
    """Orthogonal distances of points Y (M, m, 3) from elements p (M, n), written from the
    geometric definitions (frame coordinates; vectors for the line and circle in space)."""
    one = np.ones(p.shape[0])
    if kind == "sphere":
        return np.linalg.norm(Y - p[:, None, :3], axis=-1) - p[:, 3:4]
    if kind == "circle":
        return np.linalg.norm(Y[..., :2] - p[:, None, :2], axis=-1) - p[:, 2:3]
    if kind == "plane":
        return (Y[..., 2] - p[:, 0:1] - p[:, 1:2] * Y[..., 0] - p[:, 2:3] * Y[..., 1]) / \
            np.sqrt(1 + p[:, 1:2] ** 2 + p[:, 2:3] ** 2)
    if kind == "circle_space":
        a, b, r = p[:, None, :3], _unit(np.column_stack([p[:, 3], p[:, 4], one]))[:, None], \
            p[:, 5:6]
    else:
        a = np.column_stack([p[:, 0], p[:, 1], 0 * one])[:, None]
        b = _unit(np.column_stack([p[:, 2], p[:, 3], one]))[:, None]
    v = Y - a
    h = (v * b).sum(-1)
    perp = v - h[..., None] * b
    if kind == "line":
        return perp.reshape(p.shape[0], -1)
    rho = np.linalg.norm(perp, axis=-1)
    if kind == "cylinder":
        return rho - p[:, 4:5]
    if kind == "cone":
        phi = p[:, 5:6]
        return np.cos(phi) * (rho - p[:, 4:5]) + np.sin(phi) * h
    if kind == "circle_space":
        return np.concatenate([h, rho - r], axis=1)
    raise ValueError(kind)


def refit(kind, p0, Y, w):
    """Batched Gauss-Newton with central-difference Jacobians, started at p0."""
    M = Y.shape[0]
    p = np.tile(p0, (M, 1))
    reps = None
    for it in range(30):
        r = residuals(kind, p, Y)
        reps = reps or r.shape[1] // w.size
        wr = np.repeat(w, reps) if kind in ("line",) else np.tile(w, reps)
        r = r * wr
        J = np.empty(r.shape + (p.shape[1],))
        for j in range(p.shape[1]):
            h = 1e-6 * max(1.0, abs(p0[j]))
            e = np.zeros(p.shape[1])
            e[j] = h
            J[..., j] = (residuals(kind, p + e, Y) - residuals(kind, p - e, Y)) * wr / (2 * h)
        step = -np.linalg.solve(np.einsum("mqi,mqj->mij", J, J),
                                np.einsum("mqi,mq->mi", J, r)[..., None])[..., 0]
        p = p + step
        # stop at 1e-10 of the element size: the perturbations are ~1e-3 mm, the rounding
        # floor of 300 mm coordinates ~1e-12 mm
        if np.max(np.abs(step)) < 1e-10 * max(1.0, np.max(np.abs(p0))):
            return p
    raise AssertionError(f"Monte Carlo refit of {kind} did not converge")


def start_and_globals(f):
    """p0 for `refit` in the fit's frame, and a map from refitted p to the reported global
    parameters (locating point on the frame's z = 0 plane, i.e. the plane through x_A
    orthogonal to the fitted axis)."""
    o, R, kind = f.origin_mm, f.R, f.kind
    sh = list(f.shape)
    if kind == "sphere":
        return np.array([*o, sh[0]]), lambda p: p
    if kind == "circle":
        cols, _ = features.CIRCLE_PLANES[f.circle_plane]
        return np.array([o[cols[0]], o[cols[1]], sh[0]]), lambda p: p

    def direction(bx, by):
        return _unit(np.column_stack([bx, by, np.ones_like(bx)])) @ R.T

    if kind == "plane":
        def g(p):
            return np.column_stack([o + np.outer(p[:, 0], R[:, 2]), direction(-p[:, 1], -p[:, 2])])
        return np.zeros(3), g
    if kind == "circle_space":
        def g(p):
            return np.column_stack([o + p[:, :3] @ R.T, direction(p[:, 3], p[:, 4]), p[:, 5]])
        return np.array([0, 0, 0, 0, 0, sh[0]], float), g

    def g(p):
        loc = o + np.column_stack([p[:, 0], p[:, 1], 0 * p[:, 0]]) @ R.T
        return np.column_stack([loc, direction(p[:, 2], p[:, 3]), p[:, 4:]])
    return np.array([0, 0, 0, 0] + sh, float), g


def monte_carlo(f, V_X_um2, rng, M=20_000):
    lam, U = np.linalg.eigh(V_X_um2)
    L = U * np.sqrt(np.clip(lam, 0, None))
    E = (rng.standard_normal((M, L.shape[0])) @ L.T * 1e-3).reshape(M, f.m, 3)  # mm
    Y = ((f.X_mm + E) - f.origin_mm) @ f.R if f.kind not in ("sphere", "circle") else f.X_mm + E
    if f.kind == "circle":
        cols, _ = features.CIRCLE_PLANES[f.circle_plane]
        Y = Y[..., list(cols)]
    p0, to_global = start_and_globals(f)
    return to_global(refit(f.kind, p0, Y, f.weights))


CASES = [("line", {}), ("plane", {}), ("circle", {}), ("circle", {"space": True}),
         ("sphere", {}), ("cylinder", {}), ("cone", {})]


@pytest.mark.parametrize("element,opts", CASES,
                         ids=[e + ("_space" if o else "") for e, o in CASES])
def test_V_A_agrees_with_monte_carlo_of_the_full_fit(element, opts):
    rng = np.random.default_rng(20220309 + len(element) + 7 * bool(opts))
    m = {"line": 12, "plane": 14, "circle": 12, "sphere": 16, "cylinder": 20, "cone": 24}[element]
    X, N, truth, kw = random_points(element, rng, m, **opts)
    weights = rng.uniform(0.5, 1.5, size=m)
    f = features.fit(element, X, normals=N, weights=weights, **kw)
    cloud = cloud_for(X, N, rng)
    comps = pointcloud.V_X_components(cloud, PARAMS)
    for fac in pointcloud.FACTORS:  # every factor is in play
        assert np.trace(comps[fac]) > 0.01 * np.trace(sum(comps.values())), fac
    unc = features.propagate(f, comps)
    V = unc.V["total"]
    M = 20_000
    A = monte_carlo(f, sum(comps.values()), rng, M)
    C = np.cov(A, rowvar=False)
    # sampling error of each sample covariance entry: sqrt((V_jj V_kk + V_jk^2) / M)
    se = np.sqrt((np.outer(np.diag(V), np.diag(V)) + V ** 2) / M)
    scale = np.sqrt(np.outer(np.diag(V), np.diag(V)))
    live = scale > 1e-12 * scale.max()  # a direction's component along itself has u = 0
    z = np.abs(C - V)[live] / se[live]
    assert z.max() < 5.0, f"{element}: worst covariance entry is {z.max():.1f} sampling errors off"
    u_mc, u = np.sqrt(np.diag(C)), unc.u()
    ok = np.diag(live)
    assert np.all(np.abs(u_mc[ok] / u[ok] - 1) < 5 / math.sqrt(2 * M))
    # the structural zeros are zeros in the Monte Carlo too
    assert np.all(np.sqrt(np.diag(C))[~ok] < 1e-6 * u.max())


# ---- fits recover the element -----------------------------------------------------------------

@pytest.mark.parametrize("element,opts", CASES,
                         ids=[e + ("_space" if o else "") for e, o in CASES])
def test_fit_recovers_the_nominal_element(element, opts):
    rng = np.random.default_rng(7)
    X, N, truth, kw = random_points(element, rng, 40, **opts)
    f = features.fit(element, X, normals=N, **kw)
    assert np.max(np.abs(f.residuals_mm)) < 1e-9
    got = f.values_dict()
    for name, value in truth.items():
        if value is not None:
            assert abs(got[name]) == pytest.approx(value, rel=1e-10)
    # the direction is a unit vector and the locating point lies on the element
    if f.kind in ("line", "cylinder", "cone", "plane", "circle_space"):
        assert np.linalg.norm(f.R[:, 2]) == pytest.approx(1.0)


def test_fit_from_noisy_data_needs_no_hint_for_a_short_wide_cylinder():
    """A cylinder twice as wide as it is high: the principal direction of the points is
    across the axis; the start from the normals finds the axis."""
    rng = np.random.default_rng(3)
    s = partial.sample("cylinder_patch", center_mm=[10, 20, 30], axis=[0.2, -0.3, 1],
                       r0_mm=50.0, arc_deg=360.0, half_height_mm=10.0, n_theta=16, n_z=3)
    X = s.X_mm + rng.normal(scale=0.002, size=s.X_mm.shape)
    f = features.fit("cylinder", X, normals=s.N)
    assert f.values_dict()["r0_mm"] == pytest.approx(50.0, abs=0.01)
    v = np.array([0.2, -0.3, 1.0]) / np.linalg.norm([0.2, -0.3, 1.0])
    assert abs(f.R[:, 2] @ v) == pytest.approx(1.0, abs=1e-6)


# ---- the formulas of the paper ----------------------------------------------------------------

def test_sigma_R_identity_gives_sigma_squared_inverse_H():
    """Forbes 2022 eq. (10): V_X = sigma_R^2 I  =>  V_A = sigma_R^2 (J^T J)^{-1} (N^T N = I)."""
    rng = np.random.default_rng(11)
    for element, opts in CASES:
        X, N, _, kw = random_points(element, rng, 30, **opts)
        f = features.fit(element, X, normals=N, **kw)
        sigma_um = 0.7
        unc = features.propagate(f, sigma_um ** 2 * np.eye(3 * f.m))
        expected = (sigma_um * 1e-3) ** 2 * np.linalg.inv(f.H)
        np.testing.assert_allclose(unc.V_local["total"], expected, rtol=1e-9,
                                   atol=1e-12 * np.abs(expected).max(), err_msg=element)


def test_weights_equal_to_inverse_sigma_give_the_maximum_likelihood_variance():
    """Eq. (12) with w_i = 1/sigma_i and V_X = diag(sigma_i^2 I_3): V_A = (J^T W J)^{-1}."""
    rng = np.random.default_rng(12)
    X, N, _, kw = random_points("cylinder", rng, 25)
    sig_um = rng.uniform(0.2, 2.0, size=25)
    f = features.fit("cylinder", X, normals=N, weights=1 / sig_um, **kw)
    unc = features.propagate(f, np.diag(np.repeat(sig_um ** 2, 3)))
    expected = 1e-6 * np.linalg.inv(f.H)
    np.testing.assert_allclose(unc.V_local["total"], expected, rtol=1e-9,
                               atol=1e-12 * np.abs(expected).max())


def test_a_zero_weight_removes_the_point():
    rng = np.random.default_rng(13)
    X, N, _, kw = random_points("sphere", rng, 12)
    w = np.ones(12)
    w[4] = 0.0
    fw = features.fit("sphere", X, weights=w)
    fr = features.fit("sphere", np.delete(X, 4, axis=0))
    G = features.G_A_X(fw)
    assert np.all(G[:, 12:15] == 0)
    np.testing.assert_allclose(np.delete(G.reshape(4, 12, 3), 4, axis=1).reshape(4, -1),
                               features.G_A_X(fr), rtol=1e-12, atol=1e-15)


def test_sphere_sensitivity_matrix_is_eq_17():
    """G_A|X = H^{-1} [n_i n_i^T ; n_i^T] blocks (eq. (17), with J = -[n^T, 1])."""
    s = partial.sample("sphere_cap", r0_mm=12.0, gamma_deg=110.0, n_theta=7, n_phi=3)
    f = features.fit("sphere", s.X_mm)
    n = s.N
    B = np.vstack([np.hstack([np.outer(ni, ni) for ni in n]), n.reshape(1, -1)])
    np.testing.assert_allclose(features.G_A_X(f), np.linalg.inv(f.H) @ B, atol=1e-14)


def test_jacobian_is_the_derivative_of_the_distance():
    """Each column of J is the derivative of the residuals for a small change of the local
    parameter applied through the frame update (central differences)."""
    rng = np.random.default_rng(14)
    for element, opts in CASES:
        X, N, _, kw = random_points(element, rng, 15, **opts)
        X = X + rng.normal(scale=0.05, size=X.shape)  # off the surface: residuals not zero
        f = features.fit(element, X, normals=N, **kw)
        for j in range(f.n):
            h = 1e-6
            e = np.zeros(f.n)
            e[j] = h
            res = []
            for sgn in (1, -1):
                o, R, sh = features.update_one(f.kind, f.origin_mm, f.R, f.shape, sgn * e)
                d, _, _ = features.local_model(f.kind, (X - o) @ R, sh)
                res.append(d.reshape(-1))
            np.testing.assert_allclose((res[0] - res[1]) / (2 * h), f.J[:, j], atol=2e-7,
                                       err_msg=f"{element} column {f.local_names[j]}")


def test_per_factor_components_add_up_to_the_total():
    """Forbes 2025 section 5.6: V_A = sum over factors of G V_X,f G^T; u^2 = sum u_f^2."""
    rng = np.random.default_rng(15)
    X, N, _, kw = random_points("cone", rng, 30)
    f = features.fit("cone", X, normals=N, **kw)
    comps = pointcloud.V_X_components(cloud_for(X, N, rng), PARAMS)
    unc = features.propagate(f, comps)
    assert unc.factors == pointcloud.FACTORS
    u2 = sum(unc.u(fac) ** 2 for fac in pointcloud.FACTORS)
    np.testing.assert_allclose(u2, unc.u() ** 2, rtol=1e-12)
    total = features.propagate(f, sum(comps.values()))
    np.testing.assert_allclose(total.V["total"], unc.V["total"], rtol=1e-10, atol=1e-20)


def test_units_are_mm_and_rad():
    """1 µm repeatability on a 10-point full circle of radius 10 mm: u(r0) = 1e-3/sqrt(10) mm."""
    s = partial.sample("circle_arc", r0_mm=10.0, arc_deg=360.0, n_points=10)
    f = features.fit("circle", s.X_mm)
    unc = features.propagate(f, {"R": np.eye(30)})
    u = dict(zip(f.names, unc.u()))
    assert u["r0_mm"] == pytest.approx(1e-3 / math.sqrt(10), rel=1e-12)
    assert u["x0_mm"] == pytest.approx(1e-3 * math.sqrt(2 / 10), rel=1e-12)


# ---- clear errors ---------------------------------------------------------------------------

def test_too_few_points_names_the_element_and_the_count():
    with pytest.raises(ModelError, match=r"cylinder fit needs at least 5 points .* got 4"):
        features.fit("cylinder", np.eye(4, 3))
    with pytest.raises(ModelError, match=r"cone fit needs at least 6 points"):
        features.fit("cone", np.zeros((5, 3)))
    w = np.array([1, 1, 1, 0.0])
    with pytest.raises(ModelError, match=r"sphere fit needs at least 4 points with positive "
                                         r"weight, got 3"):
        features.fit("sphere", np.eye(4, 3) + 1, weights=w)


def test_points_on_a_line_do_not_determine_a_plane():
    X = np.column_stack([np.linspace(0, 50, 8), 2 * np.linspace(0, 50, 8), np.full(8, 3.0)])
    with pytest.raises(DegenerateGeometryError, match=r"plane fit: the points do not determine "
                                                      r"rot_.*rank-deficient.*one line"):
        features.fit("plane", X)


def test_points_on_one_circle_do_not_determine_a_sphere():
    s = partial.sample("circle_arc", r0_mm=10.0, arc_deg=360.0, n_points=12)
    with pytest.raises(DegenerateGeometryError, match="sphere"):
        features.fit("sphere", s.X_mm)


def test_points_on_one_circle_do_not_determine_a_cylinder():
    s = partial.sample("circle_arc", r0_mm=10.0, arc_deg=360.0, n_points=12)
    with pytest.raises(DegenerateGeometryError, match=r"cylinder fit: the points do not "
                                                      r"determine rot_"):
        features.fit("cylinder", s.X_mm, normals=s.N)


def test_a_cylinder_fitted_to_flat_points_is_refused_with_a_named_error():
    """Flat points determine no cylinder: the radius runs away.  Whether Gauss-Newton first meets a
    rank-deficient Jacobian or runs out of iterations depends on rounding (the BLAS kernel of the
    CPU); either way the answer is a named error, never a fitted cylinder."""
    rng = np.random.default_rng(5)
    X = np.column_stack([rng.uniform(-20, 20, 30), rng.uniform(-20, 20, 30),
                         rng.normal(scale=1e-4, size=30)])
    with pytest.raises((ConvergenceError, DegenerateGeometryError),
                       match=r"cylinder fit( did not converge|: the points do not determine)"):
        features.fit("cylinder", X, axis_hint=[1, 0, 0])


def test_iteration_limit_is_reported():
    rng = np.random.default_rng(6)
    X, N, _, kw = random_points("cone", rng, 20)
    X = X + rng.normal(scale=0.5, size=X.shape)
    with pytest.raises(ConvergenceError, match=r"cone fit did not converge in 1 Gauss-Newton"):
        features.fit("cone", X, normals=N, max_iter=1)


def test_bad_inputs_are_named():
    with pytest.raises(ModelError, match="unknown feature type 'torus'"):
        features.fit("torus", np.zeros((5, 3)))
    X = np.eye(4, 3)
    X[1, 2] = np.nan
    with pytest.raises(ModelError, match="finite"):
        features.fit("sphere", X)
    with pytest.raises(ModelError, match="circle plane"):
        features.fit("circle", np.eye(4, 3), circle_plane="xz")
    f = features.fit("sphere", partial.sample("sphere_cap", r0_mm=5.0, gamma_deg=90,
                                              n_theta=4, n_phi=2).X_mm)
    with pytest.raises(ModelError, match=r"V_X component ET: expected a 24 x 24"):
        features.propagate(f, {"ET": np.eye(12)})


@pytest.mark.parametrize("tilt", [1e-5, 1e-7, 1e-13])
def test_the_frame_of_an_axis_near_minus_z_carries_the_axis_to_rounding(tilt):
    """A datum plane measured from above has its normal near -z.  The smallest rotation taking
    e_z to it (Rodrigues, 1 + c in the denominator) must still have R e_z = axis to rounding: a
    cancelled 1 + c tilted the frame by 4e-11 rad at a tilt of 1e-5 (differently on every BLAS
    kernel), and axes within 1e-12 of -z were taken as -z itself (an error up to 1.4e-6 rad)."""
    v = np.array([tilt, -0.013 * tilt, -1.0])
    v /= np.linalg.norm(v)
    R = partial.frame_from_axis(v)
    assert np.max(np.abs(R[:, 2] - v)) <= 1e-15
    assert np.max(np.abs(R.T @ R - np.eye(3))) <= 1e-15
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-15)


def test_a_plane_fit_with_its_normal_near_minus_z_is_the_svd_plane():
    """The least-squares plane of points whose normal is 1.1e-5 rad from -z, with 4 µm of form:
    the fitted normal equals the singular vector of the centred points to 1e-15 (the frame of
    the fit no longer moves it)."""
    rng = np.random.default_rng(7)
    xy = rng.uniform(0.0, 100.0, (20, 2))
    z = 1.1e-5 * xy[:, 0] + rng.normal(0.0, 0.004, 20)
    X = np.column_stack([xy, z])
    N = np.tile([0.0, 0.0, -1.0], (20, 1))
    fit = features.fit("plane", X, normals=N)
    _, _, vt = np.linalg.svd(X - X.mean(axis=0))
    assert np.linalg.norm(np.cross(fit.R[:, 2], vt[2])) <= 1e-15


#: 16 points on a ring gauge of 100 mm bore as a CMM drawn from MPE1 measured them
#: (xlfuncs.validation_sets, seed 6; residuals about 0.15 um): Gauss-Newton reached the optimum,
#: then its last step (1e-9 mm) lowered the sum of squares by ~1e-18 mm^2, less than rounding moves
#: it; the line search rejected that step 100 times and the fit reported no convergence
RING_POINTS = [
    [49.9997347687945, -0.0007334640926046632, 0.00042002874518232147],
    [46.19418822250725, 19.132689782542002, -0.0001858447006810593],
    [35.35568045154298, 35.35386526970717, -0.0002765990663107232],
    [19.134309862454984, 46.192772475415495, -0.0003325474928743688],
    [0.0004643877543912822, 49.99889817187341, -0.00019765231941448747],
    [-19.133529473199474, 46.19292649149952, -0.0005248283326579894],
    [-35.35486131376081, 35.35491743429793, -9.227212073881219e-05],
    [-46.19369153919615, 19.133241377117542, -0.0003191696034150482],
    [-49.99950762095648, -0.0003993964509163561, -1.3876546134383716e-05],
    [-46.193776902088985, -19.135035563475356, -0.00034143057553137623],
    [-35.355138108781375, -35.355767432606456, -0.00028821310804971745],
    [-19.133887650787756, -46.19448155715594, 4.118375002803987e-06],
    [0.00037475183671631385, -50.00069238756896, -0.0001384164469868665],
    [19.134085479607847, -46.19474631593306, -0.00024360032936954212],
    [35.35542794300386, -35.35608841870669, -0.00029560852836141294],
    [46.19420791480229, -19.13510594819968, -0.00016689829956817448]]


def test_a_step_below_rounding_of_the_sum_of_squares_does_not_stall_the_fit():
    X = np.array(RING_POINTS)
    for shift in ([0.0, 0.0, 0.0], [650.0, 500.0, 80.0]):
        f = features.fit("circle", X + shift, circle_plane="xy")
        assert f.iterations <= 10
        assert abs(f.values_dict()["r0_mm"] - 50.0) < 2e-3
        # the optimum: the Gauss-Newton step from it is below the stopping rule
        assert np.max(np.abs(f.gauss_newton_step())) < 1e-9
