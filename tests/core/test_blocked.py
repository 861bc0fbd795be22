"""The blocked evaluation of the Forbes 2025 point-cloud model (xlfuncs.blocked) gives the
numbers of the dense V_X of eq. (28) -- sub-blocks, pair blocks, V_A = G V_X G^T per factor,
covariances of length records -- without forming V_X, in memory that grows linearly in m."""

import io
import tracemalloc

import numpy as np
import pytest

from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import features as ft
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs import record_covariance as rc
from cmmwb.xlfuncs.errors import DegenerateGeometryError, ModelError
from cmmwb.xlfuncs.locator import diagnose as dg

from tests.helpers.clouds import PARAMS, PROBES, random_cloud, rel_err, sphere_cloud
from tests.helpers.model_reference import length_covariance_dense

FACTORS = pc.FACTORS
REL = 1e-10


def test_any_block_of_V_X_equals_the_dense_matrix():
    cloud = random_cloud(30)
    V = pc.V_X_components(cloud, PARAMS)
    I, J = np.array([3, 7, 7, 20]), np.arange(10, 30)
    blk = bl.V_X_block(cloud, PARAMS, I, J)
    rows = (3 * I[:, None] + np.arange(3)).reshape(-1)
    cols = (3 * J[:, None] + np.arange(3)).reshape(-1)
    for f in FACTORS:
        assert rel_err(blk[f], V[f][np.ix_(rows, cols)]) <= 1e-14, f
    assert rel_err(blk["X"], sum(V[f] for f in FACTORS)[np.ix_(rows, cols)]) <= 1e-14


def test_V_X_dense_in_row_blocks_equals_V_X():
    cloud = random_cloud(25)
    assert rel_err(bl.V_X_dense(cloud, PARAMS, rows_per_block=4), pc.V_X(cloud, PARAMS)) <= 1e-15


def test_pair_blocks_give_the_distance_components_of_eq_29():
    cloud = random_cloud(30)
    pairs = pc.all_pairs(cloud.m)
    B = bl.pair_blocks(cloud, PARAMS, pairs)
    ref = pc.distance_components(cloud, PARAMS, pairs)
    V = pc.V_X_components(cloud, PARAMS)
    n = cloud.X_mm[pairs[:, 1]] - cloud.X_mm[pairs[:, 0]]
    n /= np.linalg.norm(n, axis=1)[:, None]
    for f in FACTORS:
        var = np.einsum("na,nab,nb->n", n, B[f], n)
        assert np.allclose(np.sqrt(np.maximum(var, 0)), ref[f"u_{f}_um"], rtol=1e-9, atol=1e-12), f
        # and the block itself is V_ii + V_jj - V_ij - V_ji of the dense matrix
        i, j = pairs[17]
        s = lambda a, b: V[f][3 * a:3 * a + 3, 3 * b:3 * b + 3]  # noqa: E731
        assert rel_err(B[f][17], s(i, i) + s(j, j) - s(i, j) - s(j, i)) <= 1e-12, f


@pytest.mark.parametrize("block", [200, bl.BLOCK_ENTRIES])
def test_V_A_per_factor_equals_G_V_X_G_T(block):
    cloud = random_cloud(40)
    G = np.random.default_rng(9).normal(size=(5, 3 * cloud.m))
    V = pc.V_X_components(cloud, PARAMS)
    VA = bl.V_A_components(G, cloud, PARAMS, block=block)
    for f in FACTORS:
        ref = G @ V[f] @ G.T
        assert rel_err(VA[f], ref) <= REL, f
        assert np.allclose(np.diag(VA[f]), np.diag(ref), rtol=REL, atol=0), f


@pytest.mark.parametrize("element", ["sphere", "cylinder"])
def test_fitted_feature_V_A_equals_the_dense_propagation(element):
    cloud = sphere_cloud(60)
    if element == "cylinder":
        rng = np.random.default_rng(4)
        th, z = rng.uniform(0, 2 * np.pi, 60), rng.uniform(-20, 20, 60)
        N = np.column_stack([np.cos(th), np.sin(th), 0 * th])
        X = np.column_stack([15 * np.cos(th), 15 * np.sin(th), z]) + rng.normal(scale=2e-3, size=(60, 3))
        cloud = pc.PointCloud(X, N, np.arange(60) % 2, PROBES[:2])
    f = ft.fit(element, cloud.X_mm, normals=cloud.N)
    dense = ft.propagate(f, pc.V_X_components(cloud, PARAMS))
    fast = bl.propagate_cloud(f, cloud, PARAMS, block=500)
    for fac in (*FACTORS, "total"):
        assert rel_err(fast.V_local[fac], dense.V_local[fac]) <= REL, fac
        assert np.allclose(fast.u(fac), dense.u(fac), rtol=REL, atol=0), fac


def test_switched_off_factors_contribute_nothing():
    base = random_cloud(12)
    cloud = pc.PointCloud(base.X_mm, base.N, base.probe_index,
                          tuple(pc.Probe(p.id, p.offset_mm) for p in PROBES))  # no per-probe sigmas
    params = pc.Parameters(sigma_R_um=0.2)
    G = np.random.default_rng(1).normal(size=(3, 3 * cloud.m))
    VA = bl.V_A_components(G, cloud, params)
    assert all(np.all(VA[f] == 0) for f in ("PQ", "S", "ET", "ER", "P"))
    assert rel_err(VA["R"], 0.04 * G @ G.T) <= 1e-15


def test_memory_grows_linearly_not_with_the_3m_x_3m_matrix():
    # m = 4000: one dense V_X factor would be 12000^2 doubles = 1.15 GB
    cloud = sphere_cloud(4000)
    f = ft.fit("sphere", cloud.X_mm, normals=cloud.N)
    G = ft.G_A_X(f)
    tracemalloc.start()
    bl.V_A_components(G, cloud, PARAMS, block=1 << 18, backend=bl.ThreadBackend(1))
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 40e6, f"peak {peak / 1e6:.0f} MB"


def test_record_covariance_equals_the_mismatch_locator_and_the_dense_reference():
    cloud = random_cloud(40)
    rng = np.random.default_rng(5)
    I = rng.integers(0, 40, 25)
    J = (I + rng.integers(1, 39, 25)) % 40
    fast = rc.record_covariance(cloud, PARAMS, I, J, components=True, block=60)
    ref = dg.length_covariance(cloud, PARAMS, I, J, components=True)
    for f in FACTORS:
        assert rel_err(fast[f], ref[f]) <= REL, f
    total = rc.record_covariance(cloud, PARAMS, I, J)
    assert rel_err(total, length_covariance_dense(cloud, PARAMS, I, J)) <= REL



def test_record_covariance_with_short_length_scales_and_zero_factors_on_both_forms():
    # most kernel entries below exp(-708) (set to 0 unevaluated), PQ/S/R zero: the gathered form
    # (no block) and the row blocks are the same sums, and the dense reference
    cloud = random_cloud(40)
    rng = np.random.default_rng(6)
    I = rng.integers(0, 40, 30)
    J = (I + rng.integers(1, 39, 30)) % 40
    short = pc.Parameters(sigma_ET_um=0.3, lambda_ET_mm=10, sigma_ER_urad=4.0, lambda_ER_mm=20,
                          sigma_P0_um=0.1, sigma_P_um=0.15, lambda_P=0.03)
    for d_log in (False, True):
        gathered = rc.record_covariance(cloud, short, I, J, components=True, d_log_lambda=d_log)
        rows = rc.record_covariance(cloud, short, I, J, components=True, d_log_lambda=d_log, block=70)
        for f in FACTORS:
            assert rel_err(gathered[f], rows[f]) <= REL, (f, d_log)
        assert not np.any(gathered["R"]) and not np.any(gathered["S"])
    assert rel_err(rc.record_covariance(cloud, short, I, J), length_covariance_dense(cloud, short, I, J)) <= REL

def test_distances_on_a_backend_are_the_local_numbers():
    cloud = random_cloud(50)
    backend = bl.ThreadBackend(2)
    local = pc.distance_components(cloud, PARAMS)
    blocked = bl.distance_components(cloud, PARAMS, backend=backend, block=100)
    assert all(np.array_equal(blocked[k], local[k]) for k in local)
    pairs = pc.all_pairs(cloud.m)[::7]
    local = pc.distance_components(cloud, PARAMS, pairs)
    blocked = bl.distance_components(cloud, PARAMS, pairs, backend=backend, block=20)
    assert all(np.array_equal(blocked[k], local[k]) for k in local)


def test_coincident_points_name_the_points_on_every_path():
    cloud = random_cloud(10)
    X = cloud.X_mm.copy()
    X[6] = X[2]
    bad = pc.PointCloud(X, cloud.N, cloud.probe_index, PROBES)
    for backend in (None, bl.ThreadBackend(2)):
        with pytest.raises(DegenerateGeometryError, match="X3 and X7"):
            bl.distance_components(bad, PARAMS, backend=backend, block=5)


def test_bad_arguments_are_model_errors():
    cloud = random_cloud(5)
    with pytest.raises(ModelError, match="3m = 15 columns"):
        bl.V_A_components(np.ones((2, 14)), cloud, PARAMS)
    with pytest.raises(ModelError, match="unknown influence factor"):
        bl.V_X_block(cloud, PARAMS, [0], [1], factors=("XX",))
    with pytest.raises(ModelError, match="out of range"):
        bl.pair_blocks(cloud, PARAMS, [[0, 5]])


def test_progress_reaches_the_total_and_the_bar_is_quiet_for_quick_runs():
    cloud = random_cloud(60)
    G = np.ones((2, 3 * cloud.m))
    calls = []
    bl.V_A_components(G, cloud, PARAMS, block=300, progress=lambda d, t: calls.append((d, t)))
    assert len(calls) > 5 and calls[-1][0] == pytest.approx(calls[-1][1])
    assert all(a[0] <= b[0] for a, b in zip(calls, calls[1:]))
    quiet = io.StringIO()
    bl.V_A_components(G, cloud, PARAMS, progress=bl.ProgressBar("V_A", stream=quiet))
    assert quiet.getvalue() == ""
    shown = io.StringIO()
    bar = bl.ProgressBar("V_A", stream=shown, delay_s=0.0)
    bar(1, 4)
    bar(4, 4)
    assert "100%" in shown.getvalue() and shown.getvalue().endswith("\n")
