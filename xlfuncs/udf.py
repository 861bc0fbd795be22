"""The cmmwb Excel add-in: xlwings user-defined functions over the numerical core.

For workbooks beyond the native-formula limit (``generator.pointcloud.large_book``) Excel users on Windows
can recompute the heavy Gaussian-process blocks live, with the core of this package, instead of
reading the values written at build time.  Install and use: ``docs/addins.md``
(UDF Modules = ``cmmwb.xlfuncs.udf``).  The LibreOffice Calc add-in (``generator/lo_addin``) calls
these same functions.  On other platforms the xlwings decorators do nothing and the
functions are plain Python (the tests call them with the cell values of the ranges).

Arguments are cell ranges in the layout of the generated workbooks:

``points``   rows of the ``Points`` sheet, columns A:H -- ``id, x_mm, y_mm, z_mm, nx, ny, nz,
             probe`` (the probe id; may be left out, 7 columns, when there is one probe);
``probes``   the probes table of ``Inputs`` -- ``probe, px_mm, py_mm, pz_mm, sigma_PQ_um,
             sigma_P0_um, sigma_P_um, lambda_P`` (per-probe values as the cells show them);
``params``   the hyper-parameters of ``Inputs``: either the 12 values of the machine's (or the 14
             of :class:`xlfuncs.pointcloud.Parameters`, with u(alpha) and u(T) of the part) in
             their order (column B) or the two columns name, value (A:B), in any order, unknown
             names ignored; name/value rows may carry the part's thermal state
             (``workpiece_alpha_ppm_per_K`` ..., docs/workpiece.md): the factor W then acts;
``ids``      a column of point ids (e.g. the ``from`` column of ``Budget``);
``factor``   ``"R"``, ``"PQ"``, ``"S"``, ``"ET"``, ``"ER"``, ``"P"``, ``"W"`` or ``"X"`` (their sum).

Results in µm² (variance blocks), µm (uncertainties), mm (distances); fitted features in their
parameters' units (mm, rad).  Every function cites the equation it evaluates.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Sequence

import numpy as np

try:
    import xlwings as xw
except ImportError:  # LibreOffice's Python (the Calc add-in, docs/addins.md) has no xlwings
    class _PassThrough:
        """The xlwings decorators as no-ops: the functions stay plain Python."""

        @staticmethod
        def func(f=None, **_kw):
            return f if f is not None else (lambda g: g)

        @staticmethod
        def arg(*_a, **_kw):
            return lambda g: g

    xw = _PassThrough()

from . import blocked as bl
from . import features as ft
from . import pointcloud as pc
from .errors import ModelError
from .model import workpiece as wpc
from .model.hyperparameters import HYPER, NAMES, PROBE_OVERRIDES, in_table

__all__ = [
    "cmm_v_block", "cmm_v_et", "cmm_v_er", "cmm_v_p", "cmm_pair_block", "cmm_pair_blocks",
    "cmm_distance", "cmm_distances", "cmm_feature", "cmm_feature_va", "cmm_version",
    "UDFS", "parse_points", "parse_probes", "parse_params",
]

#: the hyper-parameters every params range gives (the machine's); the part's u(alpha), u(T) are optional
PARAM_NAMES = in_table("parameters")
DISTANCE_COLUMNS = ("d_mm", "u_um", *(f"u_{f}_um" for f in pc.FACTORS))
#: row-major order of the 3 x 3 pair blocks when laid out in one row
BLOCK_COLUMNS = ("xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz")


# ---------------------------------------------------------------------------------------------
# turning cell values into core objects
# ---------------------------------------------------------------------------------------------

def _rows(value: Any, what: str) -> list[list]:
    """A range as a list of rows (a single cell or a 1-D list becomes one row)."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        return [[value]]
    if value and not isinstance(value[0], (list, tuple, np.ndarray)):
        return [list(value)]
    return [list(r) for r in value]


def _number(v: Any, what: str) -> float:
    if isinstance(v, bool) or v is None or isinstance(v, str):
        raise ModelError(f"{what}: expected a number, got {v!r}")
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise ModelError(f"{what}: expected a number, got {v!r}") from None
    if not math.isfinite(x):
        raise ModelError(f"{what}: {x!r} is not a finite number")
    return x


def _text(v: Any) -> str:
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v).strip()


def _named_rows(params: Any) -> dict[str, Any] | None:
    """name -> value of name/value rows (None when ``params`` is a column of values)."""
    rows = [r for r in _rows(params, "params") if any(c not in (None, "") for c in r)]
    if rows and len(rows[0]) >= 2 and isinstance(rows[0][0], str):
        return {_text(r[0]): r[1] for r in rows}
    return None


def parse_params(params: Any) -> pc.Parameters:
    """Hyper-parameters from 12 or 14 values (Parameters order) or from name/value rows (the part's
    u(alpha), u(T) as ``u_alpha_ppm_per_K`` or ``workpiece_u_alpha_ppm_per_K``, optional)."""
    named = _named_rows(params)
    if named is not None:
        vals = {}
        for name, v in named.items():
            key = name.removeprefix(wpc.PREFIX)      # the workbook names the part's u's workpiece_<name>
            if key in NAMES and (key == name or HYPER[key].table == "workpiece"):
                vals[key] = _number(v, name)
        missing = [n for n in PARAM_NAMES if n not in vals]
        if missing:
            raise ModelError(f"params: missing {', '.join(missing)}")
        return pc.Parameters(**vals)
    flat = [c for r in _rows(params, "params") if any(c not in (None, "") for c in r) for c in r]
    if len(flat) not in (len(PARAM_NAMES), len(NAMES)):
        raise ModelError(f"params: expected the {len(PARAM_NAMES)} hyper-parameters "
                         f"({', '.join(PARAM_NAMES)}), got {len(flat)} cells")
    return pc.Parameters(**{n: _number(v, n) for n, v in zip(NAMES, flat)})


def parse_workpiece(params: Any):
    """The part's thermal state from the name/value rows of ``params`` (``workpiece_...``,
    docs/workpiece.md), or None (no such rows: no factor W)."""
    named = _named_rows(params)
    if named is None:
        return None
    cells = {k: _number(v, k) for k, v in named.items()
             if k.startswith(wpc.PREFIX) and k[len(wpc.PREFIX):] in wpc.STATE_CELLS}
    return wpc.from_cells(cells)


def _with_part(cloud: pc.PointCloud, params: Any) -> pc.PointCloud:
    """The cloud with the part's thermal state of ``params`` (the factor W), if it has one."""
    wp = parse_workpiece(params)
    return cloud if wp is None else replace(cloud, workpiece=wp)


def parse_probes(probes: Any) -> tuple[pc.Probe, ...]:
    """Probes from rows ``id, px, py, pz, sigma_PQ_um, sigma_P0_um, sigma_P_um, lambda_P``."""
    out = []
    for r in _rows(probes, "probes"):
        if all(c in (None, "") for c in r):
            continue
        if len(r) < 8:
            raise ModelError("probes: expected 8 columns (probe, px_mm, py_mm, pz_mm, sigma_PQ_um, "
                             f"sigma_P0_um, sigma_P_um, lambda_P), got {len(r)}")
        pid = _text(r[0])
        off = tuple(_number(r[1 + a], f"probe {pid} p{'xyz'[a]}_mm") for a in range(3))
        sig = [_number(r[4 + q], f"probe {pid} {n}") for q, n in enumerate(PROBE_OVERRIDES)]
        out.append(pc.Probe(pid, off, *sig))
    if not out:
        raise ModelError("probes: no probe given")
    return tuple(out)


def parse_points(points: Any, probes: Sequence[pc.Probe]) -> pc.PointCloud:
    """Points from rows ``id, x, y, z, nx, ny, nz, probe`` (the probe column may be left out
    when there is a single probe)."""
    index = {p.id: k for k, p in enumerate(probes)}
    labels, X, N, k = [], [], [], []
    for r in _rows(points, "points"):
        if all(c in (None, "") for c in r):
            continue
        if len(r) not in (7, 8):
            raise ModelError(f"points: expected the columns id, x_mm, y_mm, z_mm, nx, ny, nz, probe "
                             f"(7 or 8 columns), got {len(r)}")
        lab = _text(r[0])
        X.append([_number(r[1 + a], f"point {lab} {'xyz'[a]}") for a in range(3)])
        N.append([_number(r[4 + a], f"point {lab} n{'xyz'[a]}") for a in range(3)])
        if len(r) == 8:
            pid = _text(r[7])
            if pid not in index:
                raise ModelError(f"point {lab}: unknown probe {pid!r}")
            k.append(index[pid])
        elif len(probes) == 1:
            k.append(0)
        else:
            raise ModelError(f"point {lab}: no probe column, and there are {len(probes)} probes")
        labels.append(lab)
    if not labels:
        raise ModelError("points: no point given")
    return pc.PointCloud(np.array(X), np.array(N), np.array(k, dtype=int), tuple(probes), tuple(labels))


def _ids(ids: Any, what: str) -> list[str]:
    return [_text(c) for r in _rows(ids, what) for c in r if c not in (None, "")]


def _factor(factor: Any) -> str:
    f = _text(factor).upper()
    if f not in (*pc.FACTORS, "X"):
        raise ModelError(f"factor must be one of {', '.join(pc.FACTORS)} or X, got {factor!r}")
    return f


def _cloud_of(points, probes) -> pc.PointCloud:
    return parse_points(points, parse_probes(probes))


def _pairs(cloud: pc.PointCloud, from_ids, to_ids) -> np.ndarray:
    a, b = _ids(from_ids, "from"), _ids(to_ids, "to")
    if len(a) != len(b):
        raise ModelError(f"from ({len(a)}) and to ({len(b)}) must list the same number of points")
    index = {lab: i for i, lab in enumerate(cloud.labels)}
    for lab in a + b:
        if lab not in index:
            raise ModelError(f"unknown point {lab!r} (not in the points range)")
    return np.array([[index[x], index[y]] for x, y in zip(a, b)], dtype=int).reshape(-1, 2)


# ---------------------------------------------------------------------------------------------
# the functions Excel sees
# ---------------------------------------------------------------------------------------------

@xw.func
def cmm_version() -> str:
    """Version of the cmmwb core that the add-in runs."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return f"cmmwb {version('cmmwb')}"
    except PackageNotFoundError:  # pragma: no cover - source checkout
        return "cmmwb (not installed)"


@xw.func
@xw.arg("points_rows", ndim=2, doc="Points rows i (id, x, y, z, nx, ny, nz, probe)")
@xw.arg("points_cols", ndim=2, doc="Points rows j (id, x, y, z, nx, ny, nz, probe)")
@xw.arg("probes", ndim=2, doc="Inputs probes table (probe, px, py, pz, sigma_PQ, sigma_P0, sigma_P, lambda_P)")
@xw.arg("params", ndim=2, doc="Inputs hyper-parameters (values, or name/value columns)")
def cmm_v_block(factor, points_rows, points_cols, probes, params):
    """Block of the point-cloud variance V_X,factor (µm²) of Forbes 2025 eq. (28): rows of
    the points in points_rows, columns of the points in points_cols (3 per point, x y z)."""
    f = _factor(factor)
    prb = parse_probes(probes)
    P = parse_params(params)
    A, B = parse_points(points_rows, prb), parse_points(points_cols, prb)
    both = _with_part(pc.PointCloud(np.vstack([A.X_mm, B.X_mm]), np.vstack([A.N, B.N]),
                                    np.concatenate([A.probe_index, B.probe_index]), prb), params)
    blk = bl.V_X_block(both, P, np.arange(A.m), np.arange(A.m, A.m + B.m))
    return blk[f]


@xw.func
@xw.arg("points_rows", ndim=2)
@xw.arg("points_cols", ndim=2)
@xw.arg("probes", ndim=2)
@xw.arg("params", ndim=2)
def cmm_v_et(points_rows, points_cols, probes, params):
    """V_ET block (µm²): location-error Gaussian process, Forbes 2025 eq. (21)."""
    return cmm_v_block("ET", points_rows, points_cols, probes, params)


@xw.func
@xw.arg("points_rows", ndim=2)
@xw.arg("points_cols", ndim=2)
@xw.arg("probes", ndim=2)
@xw.arg("params", ndim=2)
def cmm_v_er(points_rows, points_cols, probes, params):
    """V_ER block (µm²): rotation-error Gaussian process, Forbes 2025 eqs. (24)-(25)."""
    return cmm_v_block("ER", points_rows, points_cols, probes, params)


@xw.func
@xw.arg("points_rows", ndim=2)
@xw.arg("points_cols", ndim=2)
@xw.arg("probes", ndim=2)
@xw.arg("params", ndim=2)
def cmm_v_p(points_rows, points_cols, probes, params):
    """V_P block (µm²): probing effects, Forbes 2025 eqs. (26)-(27)."""
    return cmm_v_block("P", points_rows, points_cols, probes, params)


@xw.func
@xw.arg("point_i", ndim=2)
@xw.arg("point_j", ndim=2)
@xw.arg("probes", ndim=2)
@xw.arg("params", ndim=2)
def cmm_pair_block(factor, point_i, point_j, probes, params):
    """3 x 3 block V_ii + V_jj - V_ij - V_ji of V_X,factor (µm²) for the distance between two
    points: u_factor(d_ij)^2 = n_ij^T (this block) n_ij, Forbes 2025 eq. (29)."""
    f = _factor(factor)
    prb = parse_probes(probes)
    P = parse_params(params)
    A, B = parse_points(point_i, prb), parse_points(point_j, prb)
    if A.m != 1 or B.m != 1:
        raise ModelError("point_i and point_j must be one row each")
    both = _with_part(pc.PointCloud(np.vstack([A.X_mm, B.X_mm]), np.vstack([A.N, B.N]),
                                    np.concatenate([A.probe_index, B.probe_index]), prb), params)
    blocks = bl.pair_blocks(both, P, [[0, 1]])
    return (sum(blocks.values()) if f == "X" else blocks[f])[0]


@xw.func
@xw.arg("points", ndim=2, doc="Points!A:H rows of every point used")
@xw.arg("from_ids", ndim=2, doc="column of 'from' point ids")
@xw.arg("to_ids", ndim=2, doc="column of 'to' point ids")
@xw.arg("probes", ndim=2)
@xw.arg("params", ndim=2)
def cmm_pair_blocks(factor, points, from_ids, to_ids, probes, params):
    """One row per distance: the 3 x 3 block V_ii + V_jj - V_ij - V_ji of V_X,factor (µm²) in
    row-major order (xx, xy, xz, yx, ..., zz), Forbes 2025 eq. (29)."""
    f = _factor(factor)
    cloud = _with_part(_cloud_of(points, probes), params)
    P = parse_params(params)
    pairs = _pairs(cloud, from_ids, to_ids)
    blocks = bl.pair_blocks(cloud, P, pairs)
    B = sum(blocks.values()) if f == "X" else blocks[f]
    return B.reshape(len(pairs), 9)


@xw.func
@xw.arg("point_i", ndim=2)
@xw.arg("point_j", ndim=2)
@xw.arg("probes", ndim=2)
@xw.arg("params", ndim=2)
def cmm_distance(point_i, point_j, probes, params):
    """One row: d_mm, u_um and the components u_R_um ... u_P_um, u_W_um of the distance between
    two points, Forbes 2025 eqs. (29)-(30) (W: docs/workpiece.md)."""
    prb = parse_probes(probes)
    P = parse_params(params)
    A, B = parse_points(point_i, prb), parse_points(point_j, prb)
    if A.m != 1 or B.m != 1:
        raise ModelError("point_i and point_j must be one row each")
    both = _with_part(pc.PointCloud(np.vstack([A.X_mm, B.X_mm]), np.vstack([A.N, B.N]),
                                    np.concatenate([A.probe_index, B.probe_index]), prb,
                                    (A.labels[0], B.labels[0])), params)
    r = pc.distance_components(both, P, np.array([[0, 1]]))
    return np.array([[r[k][0] for k in DISTANCE_COLUMNS]])


@xw.func
@xw.arg("points", ndim=2)
@xw.arg("from_ids", ndim=2)
@xw.arg("to_ids", ndim=2)
@xw.arg("probes", ndim=2)
@xw.arg("params", ndim=2)
def cmm_distances(points, from_ids, to_ids, probes, params):
    """One row per distance (from, to): d_mm, u_um, u_R_um, u_PQ_um, u_S_um, u_ET_um, u_ER_um,
    u_P_um, u_W_um, Forbes 2025 eqs. (29)-(30), evaluated without forming V_X."""
    cloud = _with_part(_cloud_of(points, probes), params)
    P = parse_params(params)
    r = pc.distance_components(cloud, P, _pairs(cloud, from_ids, to_ids))
    return np.column_stack([r[k] for k in DISTANCE_COLUMNS])


def _vector3(value, what: str):
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    flat = [c for r in _rows(value, what) for c in r if c not in (None, "")]
    if not flat:
        return None
    if len(flat) != 3:
        raise ModelError(f"{what}: expected 3 numbers, got {len(flat)}")
    return np.array([_number(c, what) for c in flat])


def _fit(element, cloud: pc.PointCloud, circle_plane, weights=None, axis_hint=None, reference_mm=None):
    """The least-squares element of xlfuncs.features.fit with the workbook's options."""
    el = _text(element).lower()
    cp = None if circle_plane in (None, "") else _text(circle_plane).lower()
    w = None
    if weights is not None and not (isinstance(weights, str) and not weights.strip()):
        w = np.array([_number(c, "weights") for r in _rows(weights, "weights") for c in r])
        if w.size != cloud.m:
            raise ModelError(f"weights: need one weight per point ({cloud.m}), got {w.size}")
    kw = dict(normals=cloud.N, weights=w, axis_hint=_vector3(axis_hint, "axis_hint"),
              reference_mm=_vector3(reference_mm, "reference_mm"))
    if el == "circle":
        return ft.fit("circle", cloud.X_mm, circle_plane=None if cp in (None, "space") else cp, **kw)
    return ft.fit(el, cloud.X_mm, **kw)


@xw.func
@xw.arg("points", ndim=2)
@xw.arg("probes", ndim=2)
@xw.arg("params", ndim=2)
def cmm_feature(element, points, probes, params, circle_plane=None, weights=None, axis_hint=None,
                reference_mm=None):
    """Least-squares element (line, plane, circle, sphere, cylinder, cone) fitted to the points
    (Forbes 2022) with its uncertainty under the point-cloud model (Forbes 2025 section 5.6):
    one row per reported parameter -- name, value, u, u_R, u_PQ, u_S, u_ET, u_ER, u_P, u_W (the
    parameter's unit: mm, rad or 1).  Optional: circle_plane (xy, yz, zx, space), weights (one
    per point), axis_hint and reference_mm (3 cells each), as in the feature task file.
    V_X is never formed (xlfuncs.blocked)."""
    cloud = _with_part(_cloud_of(points, probes), params)
    P = parse_params(params)
    f = _fit(element, cloud, circle_plane, weights, axis_hint, reference_mm)
    unc = bl.propagate_cloud(f, cloud, P)
    rows = []
    for q, name in enumerate(f.names):
        rows.append([name, float(f.values[q]), float(unc.u()[q]),
                     *(float(unc.u(fac)[q]) for fac in pc.FACTORS)])
    return rows


@xw.func
@xw.arg("points", ndim=2)
@xw.arg("probes", ndim=2)
@xw.arg("params", ndim=2)
def cmm_feature_va(element, points, probes, params, factor="X", circle_plane=None, weights=None,
                   axis_hint=None, reference_mm=None):
    """Covariance V_A (reported parameters, in their units squared) of the element fitted to
    the points, for one influence factor or ``"X"`` for the total: G_A|X V_X,f G_A|X^T
    (Forbes 2025 section 5.6; Forbes 2022 eqs. (8), (12)), computed in blocks.  Optional
    arguments as :func:`cmm_feature`."""
    f_ = _factor(factor)
    cloud = _with_part(_cloud_of(points, probes), params)
    P = parse_params(params)
    f = _fit(element, cloud, circle_plane, weights, axis_hint, reference_mm)
    unc = bl.propagate_cloud(f, cloud, P)
    return unc.V["total" if f_ == "X" else f_]


#: every add-in function, by the name Excel uses (case-insensitive)
UDFS = {name: globals()[name] for name in __all__ if name.startswith("cmm_")}
