"""The blocked computations on a Dask cluster give the numbers of the local path, bit for bit
(xlfuncs.distributed; optional extra `cmmwb[dask]`)."""

import numpy as np
import pytest

from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import features as ft
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs import record_covariance as rc

distributed = pytest.importorskip("distributed")
from cmmwb.xlfuncs.distributed import DaskBackend, get_backend  # noqa: E402

from tests.helpers.clouds import PARAMS, random_cloud, sphere_cloud  # noqa: E402


@pytest.fixture(scope="module")
def cluster():
    """A local Dask cluster of two worker processes, reached through its scheduler address as a
    remote cluster would be."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as c:
        yield c


def test_distances_on_a_dask_cluster_equal_the_local_path(cluster):
    cloud = random_cloud(200)
    pairs = pc.all_pairs(cloud.m)[::3]
    with DaskBackend(cluster.scheduler_address) as backend:
        all_pairs = bl.distance_components(cloud, PARAMS, backend=backend, block=2000)
        some = bl.distance_components(cloud, PARAMS, pairs, backend=backend, block=1000)
    local = pc.distance_components(cloud, PARAMS)
    assert all(np.array_equal(all_pairs[k], local[k]) for k in local)
    local = pc.distance_components(cloud, PARAMS, pairs)
    assert all(np.array_equal(some[k], local[k]) for k in local)


def test_fitted_feature_V_A_on_a_dask_cluster_equals_the_local_path(cluster):
    cloud = sphere_cloud(800)
    f = ft.fit("sphere", cloud.X_mm, normals=cloud.N)
    with DaskBackend(cluster.scheduler_address) as backend:
        remote = bl.propagate_cloud(f, cloud, PARAMS, backend=backend, block=20_000)
    local = bl.propagate_cloud(f, cloud, PARAMS, block=20_000)
    for fac in (*pc.FACTORS, "total"):
        assert np.array_equal(remote.V_local[fac], local.V_local[fac]), fac


def test_low_rank_V_A_on_a_dask_cluster_equals_the_local_path(cluster):
    cloud = sphere_cloud(3000)
    f = ft.fit("sphere", cloud.X_mm, normals=cloud.N)
    with DaskBackend(cluster.scheduler_address) as backend:
        remote = bl.propagate_cloud(f, cloud, PARAMS, backend=backend, method="lowrank")
    local = bl.propagate_cloud(f, cloud, PARAMS, method="lowrank")
    assert remote.approximation.rank == local.approximation.rank
    for fac in (*pc.FACTORS, "total"):
        scale = np.max(np.abs(local.V_local[fac]))
        assert np.max(np.abs(remote.V_local[fac] - local.V_local[fac])) <= 1e-12 * scale, fac


def test_record_covariance_on_a_dask_cluster_equals_the_local_path(cluster):
    cloud = random_cloud(60)
    I, J = np.arange(0, 30), np.arange(30, 60)
    with DaskBackend(cluster.scheduler_address) as backend:
        remote = rc.record_covariance(cloud, PARAMS, I, J, backend=backend, block=200)
    assert np.array_equal(remote, rc.record_covariance(cloud, PARAMS, I, J, block=200))


def test_the_environment_chooses_the_backend(monkeypatch, cluster):
    monkeypatch.delenv("CMMWB_SCHEDULER", raising=False)
    assert get_backend() is None                       # local threads
    monkeypatch.setenv("CMMWB_SCHEDULER", cluster.scheduler_address)
    backend = get_backend()
    try:
        assert isinstance(backend, DaskBackend) and backend.address == cluster.scheduler_address
    finally:
        backend.close()


def test_diagnose_of_length_records_on_a_dask_cluster_equals_the_local_path(cluster):
    """The passes of the structured length covariance (xlfuncs.locator.structured_lengths) as Dask tasks
    on two worker processes: chi-square, candidates, estimates and u as on one process."""
    from cmmwb.xlfuncs.locator import diagnose as dg
    from cmmwb.xlfuncs.locator import simulate as sm

    from tests.helpers.clouds import MPE1, PAIR

    rec = sm.simulate(sm.iso10360(PAIR, repeats=2), MPE1, {"scale": 3.0}, seed=3)
    model = dg.Model(MPE1, PAIR, True)
    local = dg.diagnose(rec, model, structured=True)
    with DaskBackend(cluster.scheduler_address) as backend:
        remote = dg.diagnose(rec, model, structured=True, backend=backend)
    assert remote.chosen == local.chosen == ["scale"]
    for a, b in ((remote.chi2_before, local.chi2_before), (remote.chi2_after, local.chi2_after),
                 (remote.beta, local.beta), (np.diag(remote.cov_beta), np.diag(local.cov_beta)),
                 (remote.u_obs, local.u_obs), ([g["chi2"] for g in remote.groups], [g["chi2"] for g in local.groups])):
        assert np.max(np.abs(np.asarray(a) - np.asarray(b))) <= 1e-12 * np.max(np.abs(np.asarray(b)))
