"""JCGM 101 Monte Carlo of the Forbes 2025 model (xlfuncs.montecarlo): drawing the influence
factors -- Gaussian-process draws included -- reproduces V_X, and on the step gauge and on
fitted features the Monte Carlo u agrees with the direct (law of propagation) u."""

import numpy as np
import pytest

from cmmwb.generator.pointcloud import job
from cmmwb.generator.taskfile import read_toml
from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import features as ft
from cmmwb.xlfuncs import montecarlo as mc
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.errors import ModelError

from tests.helpers import EXAMPLES
from tests.helpers.clouds import PARAMS, PROBES, random_cloud, rel_err, sphere_cloud


def test_the_drawn_factors_follow_V_X_exactly():
    # delta_f = A_f z_f with A_f A_f^T = V_X,f: the draws have the covariance of eq. (28)
    cloud = random_cloud(30)
    sampler = mc.PointCloudSampler(cloud, PARAMS)
    V = pc.V_X_components(cloud, PARAMS)
    for f in pc.FACTORS:
        assert rel_err(sampler.covariance(f), V[f]) <= 1e-12, f
    # Gaussian kernels are numerically of low rank: on a 25 mm sphere (lambda_ET = 150 mm) the
    # GP draws of 200 points need fewer than a third of the 3m effects
    compact = mc.PointCloudSampler(sphere_cloud(200), PARAMS)
    assert compact.maps["ET"].shape[1] < 200


def test_sample_covariance_of_the_draws():
    cloud = random_cloud(4)
    draws = mc.PointCloudSampler(cloud, PARAMS).draw(40_000, np.random.default_rng(7))
    V = pc.V_X(cloud, PARAMS)
    delta = sum(draws.values()).reshape(40_000, -1)
    C = delta.T @ delta / 40_000
    se = np.sqrt((np.outer(np.diag(V), np.diag(V)) + V**2) / 40_000)   # standard error of each entry
    assert np.max(np.abs(C - V) / se) < 5


@pytest.mark.parametrize("u,delta", [(0.63, 0.005), (1.234, 0.05), (0.0123, 0.0005), (0.0, 0.0), (99.0, 0.5)])
def test_numerical_tolerance_for_two_significant_digits(u, delta):
    assert mc.numerical_tolerance(np.array([u]), 2)[0] == pytest.approx(delta)


def test_step_gauge_direct_and_monte_carlo_agree_to_two_digits():
    path = EXAMPLES / "stepgauge_II_MPE1.toml"
    task = job.load(path, read_toml(path))
    pairs = task.pairs[::10]
    direct = pc.distance_components(task.cloud, task.params, pairs)
    r = mc.distances(task.cloud, task.params, pairs, n_dig=2, batch=5000,
                     rng=np.random.default_rng(11))
    assert r.converged and r.draws >= 10_000 and np.all(2 * r.s_u <= r.tolerance)
    assert np.all(np.abs(r.u - direct["u_um"]) <= 2 * r.tolerance)
    for f in pc.FACTORS:
        ref = direct[f"u_{f}_um"]
        # each factor drawn alone: the components of eq. (30), to the statistical precision
        assert np.all(np.abs(r.components[f] - ref) <= 5 * ref / np.sqrt(2 * r.draws) + 1e-9), f


def test_refit_of_exactly_moved_points_moves_the_element_exactly():
    cloud = sphere_cloud(40)
    fit = ft.fit("sphere", cloud.X_mm, normals=cloud.N)
    t = np.array([0.001, -0.002, 0.0005])
    got = mc.refit_batch(fit, np.stack([fit.X_mm, fit.X_mm + t]))
    assert np.allclose(got[0], fit.local_values, rtol=0, atol=1e-9)   # ft.fit stops at ~1e-11 mm
    assert np.allclose(got[1] - got[0], [*t, 0.0], rtol=0, atol=1e-12)


def test_fitted_sphere_direct_and_monte_carlo_agree():
    cloud = sphere_cloud(40)
    fit = ft.fit("sphere", cloud.X_mm, normals=cloud.N)
    direct = bl.propagate_cloud(fit, cloud, PARAMS)
    r = mc.feature(fit, cloud, PARAMS, n_dig=2, batch=5000, rng=np.random.default_rng(3))
    assert r.converged and r.names == list(fit.local_names)
    assert np.all(np.abs(r.u - direct.u_local()) <= 2 * r.tolerance)


def test_fitted_cylinder_direct_and_monte_carlo_agree():
    rng = np.random.default_rng(4)
    th, z = rng.uniform(0, 2 * np.pi, 60), rng.uniform(-20, 20, 60)
    N = np.column_stack([np.cos(th), np.sin(th), 0 * th])
    X = np.column_stack([15 * np.cos(th), 15 * np.sin(th), z]) + rng.normal(scale=2e-3, size=(60, 3))
    cloud = pc.PointCloud(X, N, np.arange(60) % 2, PROBES[:2])
    fit = ft.fit("cylinder", X, normals=N)
    direct = bl.propagate_cloud(fit, cloud, PARAMS)
    r = mc.feature(fit, cloud, PARAMS, n_dig=1, batch=4000, rng=np.random.default_rng(5))
    assert r.converged
    assert np.all(np.abs(r.u - direct.u_local()) <= 2 * r.tolerance)
    assert np.allclose(r.u, direct.u_local(), rtol=0.05)


def test_what_monte_carlo_does_not_handle_is_a_model_error():
    cloud = sphere_cloud(40)
    with pytest.raises(ModelError, match="handles plane, sphere, cylinder, line, circle, not circle_space"):
        mc.feature(ft.fit("circle", cloud.X_mm, circle_plane=None), cloud, PARAMS)
    with pytest.raises(ModelError, match="up to 3000 points"):
        mc.PointCloudSampler(sphere_cloud(3001), PARAMS)
