"""The low-rank evaluation of the GP factors (xlfuncs.lowrank): V_A of ET, ER and P through a
Nyström factor of pivoted-Cholesky pivots, with a rigorous bound of what it neglects; the exact
blocked path (xlfuncs.blocked) is the reference."""

import json

import numpy as np
import pytest

from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import features as ft
from cmmwb.xlfuncs import lowrank as lr
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.errors import ModelError

from tests.helpers.clouds import PARAMS, PROBES, rel_err, sphere_cloud

GP = ("ET", "ER", "P")


def cylinder_cloud(m: int, seed: int = 2) -> pc.PointCloud:
    rng = np.random.default_rng(seed)
    th = rng.uniform(0, 2 * np.pi, m)
    h = rng.uniform(-40, 40, m)
    N = np.column_stack([np.cos(th), np.sin(th), 0 * th])
    X = np.column_stack([200 + 20 * np.cos(th), 150 + 20 * np.sin(th), 50 + h])
    X = X + rng.normal(scale=1e-3, size=(m, 3))
    return pc.PointCloud(X, N, np.arange(m) % 2, PROBES[:2])


def both(element, cloud, **kw):
    f = ft.fit(element, cloud.X_mm, normals=cloud.N)
    G = ft.G_A_X(f)
    exact = bl.V_A_components(G, cloud, PARAMS)
    approx = lr.Approximation()
    low = bl.V_A_components(G, cloud, PARAMS, method="lowrank", approximation=approx, **kw)
    return exact, low, approx


@pytest.fixture(scope="module", params=["sphere", "cylinder"])
def case(request):
    cloud = sphere_cloud(3000) if request.param == "sphere" else cylinder_cloud(3000)
    return both(request.param, cloud)


def test_every_factor_equals_the_exact_V_A_to_1e_minus_6(case):
    exact, low, _ = case
    for f in pc.FACTORS:
        assert rel_err(low[f], exact[f]) <= 1e-6, f


def test_the_explicit_factors_are_not_approximated(case):
    exact, low, approx = case
    for f in ("R", "PQ", "S"):
        assert rel_err(low[f], exact[f]) <= 1e-13, f
        assert f not in approx.rank


def test_the_stated_bound_covers_the_actual_error(case):
    exact, low, approx = case
    for f in GP:
        err = np.abs(exact[f] - low[f])
        assert np.all(err <= approx.bound_abs[f] + 1e-12 * np.max(np.abs(exact[f]))), f
        assert approx.bound_rel[f] <= 1e-6, f


def test_a_coarse_tolerance_is_less_accurate_and_still_within_its_bound():
    exact, low, approx = both("sphere", sphere_cloud(2000), pivot_tol=1e-3)
    for f in GP:
        err = np.abs(exact[f] - low[f])
        assert np.all(err <= approx.bound_abs[f] + 1e-12 * np.max(np.abs(exact[f]))), f
    # the neglected part is positive semidefinite: the approximation never exceeds the exact
    # variances
    for f in GP:
        assert np.all(np.diag(low[f]) <= np.diag(exact[f]) * (1 + 1e-12)), f
    assert max(approx.bound_rel.values()) > 1e-6


def test_pivots_stop_at_the_tolerance_and_reproduce_the_kernel():
    rng = np.random.default_rng(5)
    Z = rng.uniform(0, 50, (400, 3))
    piv = lr.pivots(Z, 1 / 200.0**2, tol=1e-12)
    fac = lr.KernelFactor.at(Z, piv, 1 / 200.0**2)
    L = fac.rows(Z)
    K = np.exp(-((Z[:, None, :] - Z[None, :, :]) ** 2).sum(-1) / 200.0**2)
    R = K - L.T @ L
    assert len(piv) < 100          # of 400 points: the kernel is numerically low rank
    assert np.trace(R) >= -1e-12
    assert np.linalg.norm(R, 2) <= np.trace(R) + 1e-12
    assert np.max(np.diag(R)) <= 1e-10


def test_the_feature_uncertainty_carries_the_approximation_as_json():
    cloud = sphere_cloud(1500)
    f = ft.fit("sphere", cloud.X_mm, normals=cloud.N)
    unc = bl.propagate_cloud(f, cloud, PARAMS, method="lowrank")
    ex = bl.propagate_cloud(f, cloud, PARAMS)
    assert ex.approximation is None
    d = json.loads(json.dumps(unc.approximation.as_dict()))
    assert d["method"] == "nystrom-pivoted-cholesky"
    assert set(d["rank"]) == set(GP) and len(d["rank"]["P"]) == 2
    assert np.allclose(unc.u(), ex.u(), rtol=1e-7, atol=0)


def test_an_unknown_method_is_a_model_error():
    cloud = sphere_cloud(50)
    f = ft.fit("sphere", cloud.X_mm, normals=cloud.N)
    with pytest.raises(ModelError, match="unknown V_A method"):
        bl.propagate_cloud(f, cloud, PARAMS, method="fast")


def test_the_feature_job_reports_the_approximation_and_exact_is_one_setting_away(tmp_path, monkeypatch):
    """Above LOWRANK_MIN_POINTS (lowered here) the feature results carry "approximation";
    CMMWB_VA_METHOD=exact gives the exact numbers, which agree to the stated bound."""
    from cmmwb.generator.cli import build_task
    from cmmwb.generator.feature import job as feature_job

    from tests.helpers.tasks import write_bore_task

    monkeypatch.setattr(feature_job, "DENSE_MAX_POINTS", 50)
    monkeypatch.setattr(feature_job, "LOWRANK_MIN_POINTS", 100)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    low, _ = build_task(write_bore_task(tmp_path / "a"), tmp_path / "a" / "out", plots=False)
    monkeypatch.setenv("CMMWB_VA_METHOD", "exact")
    ex, _ = build_task(write_bore_task(tmp_path / "b"), tmp_path / "b" / "out", plots=False)
    a = low["feature"]["approximation"]
    assert a["method"] == "nystrom-pivoted-cholesky" and max(a["relative_error_bound"].values()) <= 1e-6
    assert "approximation" not in ex["feature"]
    for n, u in ex["feature"]["u"].items():
        assert abs(low["feature"]["u"][n] - u) <= 1e-6 * u, n
