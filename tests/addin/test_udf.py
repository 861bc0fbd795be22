"""The Excel add-in functions (cmmwb.xlfuncs.udf) are plain Python here: called with the cell values
Excel would pass (lists of rows, text ids, numbers), they give the numbers of the core."""


import numpy as np
import pytest

from cmmwb.generator.pointcloud import job
from cmmwb.generator.taskfile import read_toml
from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import features as ft
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs import udf
from cmmwb.xlfuncs.errors import ModelError

from tests.helpers import EXAMPLES
from tests.helpers.clouds import PARAMS, PROBES, random_cloud, rel_err, sphere_cloud


def point_rows(cloud: pc.PointCloud, idx=None) -> list[list]:
    """Rows as on Points!A:H: id, x, y, z, nx, ny, nz, probe id."""
    idx = range(cloud.m) if idx is None else idx
    return [[cloud.labels[i], *map(float, cloud.X_mm[i]), *map(float, cloud.N[i]),
             cloud.probes[cloud.probe_index[i]].id] for i in idx]


def probe_rows(probes, params) -> list[list]:
    """Rows as on the Inputs probes table (per-probe values resolved, as the cells show them)."""
    rows = []
    for p in probes:
        r = p.resolved(params)
        rows.append([p.id, *map(float, p.offset_mm), r.sigma_PQ_um, r.sigma_P0_um, r.sigma_P_um, r.lambda_P])
    return rows


def param_values(params) -> list[list]:
    """Inputs!B2:B13 (one column of values)."""
    return [[getattr(params, n)] for n in pc.Parameters.__dataclass_fields__]


def param_names_and_values(params) -> list[list]:
    """Inputs!A2:B13 (the machine's 12), here in reverse order: the name column makes the order
    irrelevant."""
    return [[n, getattr(params, n)] for n in reversed(udf.PARAM_NAMES)]


CLOUD = random_cloud(20)
PTS = point_rows(CLOUD)
PRB = probe_rows(PROBES, PARAMS)


@pytest.mark.parametrize("factor", [*pc.FACTORS, "X"])
def test_v_block_is_the_block_of_V_X(factor):
    V = pc.V_X_components(CLOUD, PARAMS)
    V["X"] = sum(V[f] for f in pc.FACTORS)
    rows, cols = [2, 5, 6], list(range(8, 20))
    got = udf.cmm_v_block(factor, point_rows(CLOUD, rows), point_rows(CLOUD, cols), PRB,
                          param_values(PARAMS))
    r = (3 * np.array(rows)[:, None] + np.arange(3)).reshape(-1)
    c = (3 * np.array(cols)[:, None] + np.arange(3)).reshape(-1)
    assert rel_err(np.asarray(got), V[factor][np.ix_(r, c)]) <= 1e-14


def test_the_gp_shortcuts_are_v_block_of_their_factor():
    args = (point_rows(CLOUD, range(5)), point_rows(CLOUD, range(5, 12)), PRB, param_names_and_values(PARAMS))
    for name, f in (("cmm_v_et", "ET"), ("cmm_v_er", "ER"), ("cmm_v_p", "P")):
        assert np.array_equal(getattr(udf, name)(*args), udf.cmm_v_block(f, *args))


def test_pair_blocks_one_row_per_distance():
    pairs = [(0, 1), (3, 17), (19, 4)]
    B = bl.pair_blocks(CLOUD, PARAMS, pairs)
    ids_from = [[CLOUD.labels[i]] for i, _ in pairs]
    ids_to = [[CLOUD.labels[j]] for _, j in pairs]
    for f in pc.FACTORS:
        got = udf.cmm_pair_blocks(f, PTS, ids_from, ids_to, PRB, param_values(PARAMS))
        assert np.array_equal(got, B[f].reshape(3, 9))
        one = udf.cmm_pair_block(f, [PTS[3]], [PTS[17]], PRB, param_values(PARAMS))
        assert rel_err(np.asarray(one), B[f][1]) <= 1e-14
    total = udf.cmm_pair_blocks("x", PTS, ids_from, ids_to, PRB, param_values(PARAMS))
    assert rel_err(total, sum(B[f] for f in pc.FACTORS).reshape(3, 9)) <= 1e-15


def test_distances_of_the_step_gauge_equal_the_json_of_the_core():
    path = EXAMPLES / "stepgauge_II_MPE1.toml"
    task = job.load(path, read_toml(path))
    res = job.compute(task)
    cloud = task.cloud
    pts = point_rows(cloud)
    ids_from = [[d["from"]] for d in res["distances"]]
    ids_to = [[d["to"]] for d in res["distances"]]
    got = udf.cmm_distances(pts, ids_from, ids_to, probe_rows(cloud.probes, task.params),
                            param_values(task.params))
    for row, d in zip(got, res["distances"]):
        exp = [d["d_mm"], d["u_um"], *(d["components_um"][f] for f in pc.FACTORS)]
        assert np.allclose(row, exp, rtol=1e-12, atol=1e-15)
    i = cloud.labels.index(res["distances"][5]["from"])
    j = cloud.labels.index(res["distances"][5]["to"])
    one = udf.cmm_distance([pts[i]], [pts[j]], probe_rows(cloud.probes, task.params),
                           param_values(task.params))
    assert np.array_equal(one[0], got[5])


@pytest.mark.parametrize("element", ["sphere", "plane"])
def test_fitted_feature_and_its_V_A(element):
    cloud = sphere_cloud(60)
    if element == "plane":
        X = cloud.X_mm.copy()
        X[:, 2] = 0.001 * np.sin(X[:, 0])
        N = np.tile([0.0, 0.0, 1.0], (cloud.m, 1))
        cloud = pc.PointCloud(X, N, cloud.probe_index, cloud.probes)
    f = ft.fit(element, cloud.X_mm, normals=cloud.N)
    dense = ft.propagate(f, pc.V_X_components(cloud, PARAMS))
    args = (point_rows(cloud), probe_rows(cloud.probes, PARAMS), param_values(PARAMS))
    table = udf.cmm_feature(element, *args)
    assert [r[0] for r in table] == list(f.names)
    assert np.allclose([r[1] for r in table], f.values, rtol=1e-12, atol=1e-12)
    assert np.allclose([r[2] for r in table], dense.u(), rtol=1e-10, atol=0)
    for k, fac in enumerate(pc.FACTORS):
        assert np.allclose([r[3 + k] for r in table], dense.u(fac), rtol=1e-10, atol=1e-18), fac
        assert rel_err(udf.cmm_feature_va(element, *args, fac), dense.V[fac]) <= 1e-10
    assert rel_err(udf.cmm_feature_va(element, *args), dense.V["total"]) <= 1e-10


def test_fit_options_of_the_feature_task():
    # weights, axis hint and reference point as in a feature task: the same fit and V_A
    rng = np.random.default_rng(4)
    th, z = rng.uniform(0, 2 * np.pi, 50), rng.uniform(-20, 20, 50)
    N = np.column_stack([np.cos(th), np.sin(th), 0 * th])
    X = np.column_stack([15 * np.cos(th), 15 * np.sin(th), z]) + rng.normal(scale=2e-3, size=(50, 3))
    cloud = pc.PointCloud(X, N, np.arange(50) % 2, PROBES[:2])
    w = np.where(np.arange(50) % 5 == 0, 0.5, 1.0)
    f = ft.fit("cylinder", X, normals=N, weights=w, axis_hint=(0, 0, -1), reference_mm=(0, 0, 10))
    dense = ft.propagate(f, pc.V_X_components(cloud, PARAMS))
    args = (point_rows(cloud), probe_rows(cloud.probes, PARAMS), param_values(PARAMS))
    opts = dict(weights=[[x] for x in w], axis_hint=[[0, 0, -1]], reference_mm=[[0], [0], [10]])
    table = udf.cmm_feature("cylinder", *args, **opts)
    assert np.allclose([r[1] for r in table], f.values, rtol=0, atol=1e-12)   # dir_z = -1, z_A = 10
    assert rel_err(udf.cmm_feature_va("cylinder", *args, "X", None, **opts), dense.V["total"]) <= 1e-10
    with pytest.raises(ModelError, match="one weight per point"):
        udf.cmm_feature("cylinder", *args, weights=[[1.0]] * 3)


def test_cell_values_as_excel_passes_them():
    # numeric point ids arrive as floats, one probe needs no probe column, a single row may
    # arrive as a flat list
    pts = [[1.0, 0, 0, 0, 1, 0, 0], [2.0, 100.0, 0, 0, -1, 0, 0]]
    prb = [["P1", 0, 0, -50, 0.2, 0.1, 0.1, 0.5]]
    got = udf.cmm_distances(pts, [[1.0]], [[2.0]], prb, param_values(PARAMS))
    one = udf.cmm_distance(pts[0], pts[1], prb, param_values(PARAMS))
    assert got[0][0] == 100.0 and np.array_equal(got[0], one[0])


@pytest.mark.parametrize("call,message", [
    (lambda: udf.cmm_distance([PTS[0]], [PTS[1][:6]], PRB, param_values(PARAMS)), "7 or 8 columns"),
    (lambda: udf.cmm_distance([PTS[0]], [[*PTS[1][:7], "P9"]], PRB, param_values(PARAMS)), "unknown probe 'P9'"),
    (lambda: udf.cmm_distance([PTS[0]], [[PTS[1][0], "abc", *PTS[1][2:]]], PRB, param_values(PARAMS)),
     "point X2 x: expected a number"),
    (lambda: udf.cmm_distance([PTS[0]], [PTS[0]], PRB, param_values(PARAMS)), "same place"),
    (lambda: udf.cmm_v_block("Q", PTS, PTS, PRB, param_values(PARAMS)), "factor must be one of"),
    (lambda: udf.cmm_distances(PTS, [["X1"]], [["nowhere"]], PRB, param_values(PARAMS)), "unknown point 'nowhere'"),
    (lambda: udf.cmm_distance([PTS[0]], [PTS[1]], PRB, param_values(PARAMS)[:11]), "expected the 12"),
    (lambda: udf.cmm_distance([PTS[0]], [PTS[1]], PRB, param_names_and_values(PARAMS)[1:]), "missing"),
])
def test_bad_cells_give_one_clear_message(call, message):
    with pytest.raises(ModelError, match=message):
        call()


def test_every_add_in_function_is_registered_for_excel():
    assert set(udf.UDFS) == {n for n in udf.__all__ if n.startswith("cmm_")}
    assert all(callable(fn) and fn.__doc__ for fn in udf.UDFS.values())
    assert udf.cmm_version().startswith("cmmwb")
