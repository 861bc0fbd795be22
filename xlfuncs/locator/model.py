"""The linear model of the records (docs/recordings.md sections 1-2, docs/diagnose.md section 1):
probes resolved, point records aligned (Kabsch), the design of the candidate effects, and the
record covariance C from the Forbes 2025 point-cloud model -- length records C = G V_X G^T in
kernel form (eqs. 28-29), point records V_X itself (dense, or the structured operator of
:mod:`xlfuncs.locator.structured`); and the groups of records (section 3.2)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import memory
from .. import pointcloud as pc
from .. import record_covariance as rc
from ..errors import ModelError
from ..model.workpiece import Workpiece
from . import effects as fx
from . import structured_lengths as sl
from .recordings import LengthRecords, PointRecords, RecordingsError

# ---------------------------------------------------------------------------------------------
# the model of the simulation, the probes, the design
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Model:
    """What the recordings are compared with: the task's ``[parameters]`` and ``[[probes]]``
    (``probes_given`` False when the task has no ``[[probes]]``: every probe then uses the
    task-wide parameters and the offsets of the records, or zero), and the artefact's temperature
    (``workpiece``, the task's ``[workpiece]``: the factor W of docs/workpiece.md, acting with each
    record's ``temperature_C``, or the task's T where the records have none)."""

    params: pc.Parameters
    probes: tuple[pc.Probe, ...] = (pc.Probe("P1"),)
    probes_given: bool = False
    workpiece: Workpiece | None = None


def _probe_label(p: np.ndarray, model: Model) -> str:
    for pr in model.probes:
        if np.max(np.abs(np.asarray(pr.offset_mm) - p)) <= 1e-6 and model.probes_given:
            return pr.id
    return "p(" + ",".join(f"{v:g}" for v in p) + ")"


def resolve_probes(rec, model: Model):
    """Probe id of every probing (per end for lengths), probe ids in file order, the Probe
    objects (offset + per-probe sigmas) and whether offsets are known.

    Returns ``(ids_per_end, probe_ids, probes, offsets_given)`` where ``ids_per_end`` is a list
    of tuples (one per end for lengths, one for points)."""
    if isinstance(rec, LengthRecords):
        label_cols = (rec.probe1, rec.probe2) if rec.probe1 is not None else None
        P_cols = (rec.P1_mm, rec.P2_mm) if rec.P1_mm is not None else None
        colnames = ("probe1", "probe2")
    else:
        label_cols = (rec.probe,) if rec.probe is not None else None
        P_cols = (rec.P_mm,) if rec.P_mm is not None else None
        colnames = ("probe",)
    n = rec.n
    if label_cols is not None:
        ids_per_end = [tuple(c) for c in label_cols]
    elif P_cols is not None:
        ids_per_end = [tuple(_probe_label(P[a], model) for a in range(n)) for P in P_cols]
    else:
        if model.probes_given and len(model.probes) > 1:
            raise RecordingsError(
                "the task defines several probes but the records name none: add the column"
                + ("s probe1,probe2" if len(colnames) == 2 else " probe"), rec.lines[0])
        ids_per_end = [(model.probes[0].id,) * n for _ in colnames]
    order: list[str] = []
    for a in range(n):
        for ids in ids_per_end:
            if ids[a] not in order:
                order.append(ids[a])
    task = {p.id: p for p in model.probes}
    if model.probes_given and label_cols is not None:
        for a in range(n):
            for ids, col in zip(ids_per_end, colnames):
                if ids[a] not in task:
                    raise RecordingsError(f"unknown probe {ids[a]!r} (the task defines "
                                          f"{', '.join(p.id for p in model.probes)})", rec.lines[a], col)
    probes = []
    for pid in order:
        if P_cols is not None:
            a, e = next((a, e) for a in range(n) for e, ids in enumerate(ids_per_end) if ids[a] == pid)
            off = tuple(float(v) for v in P_cols[e][a])
        elif pid in task:
            off = tuple(task[pid].offset_mm)
        else:
            off = (0.0, 0.0, 0.0)
        base = task.get(pid, pc.Probe(pid))
        probes.append(pc.Probe(pid, off, base.sigma_PQ_um, base.sigma_P0_um, base.sigma_P_um, base.lambda_P))
    offsets_given = P_cols is not None or model.probes_given
    try:
        for p in probes:
            p.resolved(model.params)
    except ModelError as e:
        raise ModelError(f"[[probes]]: {e}") from None
    return ids_per_end, tuple(order), tuple(probes), offsets_given


@dataclass
class Prepared:
    """Records turned into the linear model r = A theta + X beta + e, e ~ N(0, C)."""

    rec: LengthRecords | PointRecords
    design: fx.Design
    cloud: pc.PointCloud
    r_um: np.ndarray                 # residual vector (n_obs)
    C: np.ndarray                    # covariance (µm²)
    A: np.ndarray                    # baseline columns (n_obs x p0), alignment of point records
    A_labels: list[str]
    obs_record: np.ndarray           # record index of every observation row
    obs_axis: np.ndarray             # axis of every row (points), -1 for lengths
    ends: tuple[np.ndarray, np.ndarray] | None = None   # unique-point index of the two ends
    R0: np.ndarray | None = None     # initial alignment (Kabsch): Y = R0 x_nom + t0
    t0: np.ndarray | None = None


def _unique_probings(rec: LengthRecords, k1: np.ndarray, k2: np.ndarray):
    """Ends with identical coordinates, normal and probe are one probing (docs/recordings.md section 6).
    Probings are numbered in the order of first use (first ends of all records, then second ends)."""
    n = rec.n
    N1 = rec.N1 if rec.N1 is not None else np.zeros_like(rec.X1_mm)
    N2 = rec.N2 if rec.N2 is not None else np.zeros_like(rec.X2_mm)
    rows = np.vstack([np.column_stack([rec.X1_mm, N1, k1]), np.column_stack([rec.X2_mm, N2, k2])])
    rows = np.ascontiguousarray(rows + 0.0)             # -0.0 and 0.0 are the same coordinate
    keys = rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).ravel()
    _u, first, inv = np.unique(keys, return_index=True, return_inverse=True)   # equal bytes = equal row
    inv = inv.reshape(-1)
    order = np.argsort(first, kind="stable")            # unique rows by first use
    q_of = np.empty(len(first), dtype=int)
    q_of[order] = np.arange(len(first))
    idx = q_of[inv].reshape(2, n)
    src = first[order]
    X, N, K = rows[src, :3], rows[src, 3:6], rows[src, 6].astype(int)
    pair = np.sort(idx, axis=0).astype(np.int64)
    _p, pfirst, pinv = np.unique(pair[0] * len(first) + pair[1], return_index=True, return_inverse=True)
    b_of = pfirst[pinv.reshape(-1)]
    bad = np.flatnonzero((np.abs(rec.measured_mm - rec.measured_mm[b_of]) > 1e-9)
                         | (np.abs(rec.reference_mm - rec.reference_mm[b_of]) > 1e-9))
    if bad.size:
        a = int(bad[0])
        b = int(b_of[a])
        raise RecordingsError(
            f"records {rec.ids[b]!r} (line {rec.lines[b]}) and {rec.ids[a]!r} have the same two "
            "probings (identical coordinates, normals and probes: one probing each, spec "
            "section 6) but different lengths; give the indicated coordinates of every repeat",
            rec.lines[a], "x1")
    twice = np.flatnonzero(b_of != np.arange(n))
    if twice.size:
        a = int(twice[0])
        b = int(b_of[a])
        raise RecordingsError(
            f"records {rec.ids[b]!r} (line {rec.lines[b]}) and {rec.ids[a]!r} are one measurement: the same "
            "two probings (identical coordinates, normals and probes, spec section 6) and the same length; "
            "a line given twice? Each record is a measurement of its own (repeats: give each its own "
            "indicated coordinates)", rec.lines[a], "x1")
    return X, N, K, idx[0], idx[1]


def kabsch(X_nom: np.ndarray, X: np.ndarray, planar: bool) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid transform with X ~ R X_nom + t (rotation about z only for 2-D data)."""
    a0, b0 = X_nom.mean(axis=0), X.mean(axis=0)
    A, B = X_nom - a0, X - b0
    if planar:
        s = np.sum(A[:, 0] * B[:, 1] - A[:, 1] * B[:, 0])
        c = np.sum(A[:, 0] * B[:, 0] + A[:, 1] * B[:, 1])
        th = math.atan2(s, c)
        R = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0.0, 0.0, 1.0]])
    else:
        H = A.T @ B
        U, _, Vt = np.linalg.svd(H)
        dsign = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
        R = Vt.T @ np.diag([1.0, 1.0, dsign]) @ U.T
    t = b0 - R @ a0
    return R, t


#: records with more observations than this use the structured covariance (defined in
#: :mod:`xlfuncs.memory`, which the command line reads without importing the locator)
STRUCTURED_MIN_OBS = memory.STRUCTURED_MIN_OBS


def uses_structured(rec: LengthRecords | PointRecords, model: Model, structured: bool | None = None) -> bool:
    """Whether :func:`prepare` takes the structured covariance for these records (length
    records: unless their probings do not allow it, see
    :func:`xlfuncs.locator.structured_lengths.structure_check`, then dense)."""
    if structured is not None:
        return bool(structured)
    dims = 1 if isinstance(rec, LengthRecords) else 2 if rec.planar else 3
    return rec.n * dims > STRUCTURED_MIN_OBS and model.params.sigma_R_um > 0


def prepare(rec: LengthRecords | PointRecords, model: Model, structured: bool | None = None) -> Prepared:
    """The linear model of the records.  ``structured``: the covariance as the operator of
    :mod:`xlfuncs.locator.structured` (point records) or :mod:`xlfuncs.locator.structured_lengths` (length
    records) (True), dense (False), or dense up to ``STRUCTURED_MIN_OBS`` observations (None)."""
    ids_per_end, probe_ids, probes, offsets_given = resolve_probes(rec, model)
    index = {p: k for k, p in enumerate(probe_ids)}
    offsets = np.array([p.offset_mm for p in probes], dtype=float).reshape(-1, 3)
    T, t = rec.temperature_C, rec.time_s
    if isinstance(rec, LengthRecords):
        k1 = np.array([index[p] for p in ids_per_end[0]], dtype=int)
        k2 = np.array([index[p] for p in ids_per_end[1]], dtype=int)
        X, N, K, I, J = _unique_probings(rec, k1, k2)
        t_probing = None
        if model.workpiece is not None and T is not None:
            # a probing's temperature: that of the last record using it (as the simulator draws it)
            last = np.full(len(X), -1)
            np.maximum.at(last, I, np.arange(rec.n))
            np.maximum.at(last, J, np.arange(rec.n))
            t_probing = T[last]
        cloud = pc.PointCloud(X, N, K, probes, tuple(f"Q{q + 1}" for q in range(len(X))),
                              workpiece=model.workpiece, temperature_C=t_probing)
        P1, P2 = offsets[k1], offsets[k2]
        delta = rec.X2_mm - rec.X1_mm
        na = delta / np.linalg.norm(delta, axis=1)[:, None]
        design = fx.Design("length", probe_ids, offsets_given, T=T, t=t, na=na,
                           U1=rec.X1_mm - P1, U2=rec.X2_mm - P2, N1=rec.N1, N2=rec.N2, k1=k1, k2=k2,
                           P1=P1, P2=P2, ref=rec.reference_mm, extent_mm=float(np.max(rec.reference_mm)))
        if uses_structured(rec, model, structured):
            why = sl.structure_check(I, J, cloud.m)
            if why is None:
                C = sl.LengthCovariance(cloud, model.params, I, J)
            elif structured:
                raise ModelError(why + "; use the dense covariance (diagnose --exact, calibrate --covariance dense)")
            else:
                C = length_covariance(cloud, model.params, I, J)
        else:
            C = length_covariance(cloud, model.params, I, J)
        n = rec.n
        return Prepared(rec, design, cloud, rec.residual_um.copy(), C, np.zeros((n, 0)), [],
                        np.arange(n), -np.ones(n, dtype=int), ends=(I, J))
    k = np.array([index[p] for p in ids_per_end[0]], dtype=int)
    planar = rec.planar
    dims = 2 if planar else 3
    R0, t0 = kabsch(rec.X_nom_mm, rec.X_mm, planar)
    Y = rec.X_nom_mm @ R0.T + t0
    P = offsets[k]
    c = Y.mean(axis=0)
    N = rec.N if rec.N is not None else np.zeros_like(rec.X_mm)
    design = fx.Design("point", probe_ids, offsets_given, T=T, t=t, Y=Y, U=Y - P, N=rec.N, k=k, P=P,
                       c=c, dims=dims,
                       extent_mm=float(np.max(np.linalg.norm(Y - c, axis=1))) or 1.0)
    cloud = pc.PointCloud(rec.X_mm, N, k, probes, tuple(rec.ids), workpiece=model.workpiece,
                          temperature_C=T if model.workpiece is not None else None)
    if uses_structured(rec, model, structured):
        from .structured import StructuredCovariance

        C = StructuredCovariance(cloud, model.params, dims)
    else:
        V = pc.V_X(cloud, model.params)
        keep = np.array([3 * i + a for i in range(rec.n) for a in range(dims)])
        C = V[np.ix_(keep, keep)]
    r = ((rec.X_mm - Y)[:, :dims] * 1000.0).reshape(-1)
    A, labels = fx.alignment_columns(design)
    return Prepared(rec, design, cloud, r, C, A, labels, np.repeat(np.arange(rec.n), dims),
                    np.tile(np.arange(dims), rec.n), R0=R0, t0=t0)


# ---------------------------------------------------------------------------------------------
# covariance of length records: C = G V_X G^T in kernel form (Forbes 2025 eqs. 28-29)
# ---------------------------------------------------------------------------------------------

def length_covariance(cloud: pc.PointCloud, params: pc.Parameters, I: np.ndarray, J: np.ndarray,
                      *, components: bool = False, d_log_lambda: bool = False):
    """Covariance (µm²) of the lengths d_a = ||x_J[a] - x_I[a]|| of the unique points of
    ``cloud``: Cov(d_a, d_b) = g_a^T V_X g_b with g_a = -n_a at I[a] and +n_a at J[a]
    (eqs. 28-29), per factor if ``components``; ``d_log_lambda`` (with ``components``): the
    closed-form dC/d(log lambda) of the hyper-parameter fit (:mod:`xlfuncs.calibrate`).

    :func:`xlfuncs.record_covariance.record_covariance`, the one implementation (kernel form, row blocks
    of records, memory O(n^2) whatever m)."""
    return rc.record_covariance(cloud, params, I, J, components=components, d_log_lambda=d_log_lambda)


def group_labels(prep: Prepared) -> dict[str, list[str]]:
    """Labels of every record under each grouping of docs/recordings.md section 3.2."""
    rec, D = prep.rec, prep.design
    out: dict[str, list[str]] = {}
    if rec.group is not None:
        out["group"] = [g or "(none)" for g in rec.group]
    if len(D.probe_ids) > 1:
        if D.kind == "length":
            out["probe"] = [D.probe_ids[a] if a == b else f"{D.probe_ids[a]}-{D.probe_ids[b]}"
                            for a, b in zip(D.k1, D.k2)]
        else:
            out["probe"] = [D.probe_ids[k] for k in D.k]
    if D.kind == "length":
        if D.N1 is not None:
            o = np.einsum("ij,ij->i", D.na, D.N1) * np.einsum("ij,ij->i", D.na, D.N2)
            out["probing"] = ["bidirectional" if v < -0.25 else "unidirectional" if v > 0.25 else "other"
                              for v in o]
        out["direction"] = direction_labels(D.na)
    for key, v, unit, scale in (("temperature", D.T, "°C", 1.0), ("time", D.t, "h", 1 / 3600.0)):
        if v is not None and np.ptp(v) > 1e-9:
            out[key] = band_labels(v * scale, unit)
    return {k: v for k, v in out.items() if len(set(v)) > 1}


def direction_label(v: np.ndarray) -> str:
    """'+x', '+x+y', '+x-y+z' ...: the axes with |component| > 0.2, first sign made positive."""
    comps = [(a, np.sign(v[a])) for a in range(3) if abs(v[a]) > 0.2]
    if not comps:
        return "other"
    s0 = comps[0][1]
    return "".join(("+" if s * s0 > 0 else "-") + fx.AXES[a] for a, s in comps)


def direction_labels(V: np.ndarray) -> list[str]:
    """:func:`direction_label` of every row of V (vectorized: one label per sign pattern)."""
    big = np.abs(V) > 0.2
    sgn = np.sign(V)
    first = np.argmax(big, axis=1)
    s0 = sgn[np.arange(len(V)), first]
    code = np.where(big, np.where(sgn * s0[:, None] > 0, 1, 2), 0) @ np.array([9, 3, 1])
    names = {}
    for c in np.unique(code):
        digits = (c // 9, (c // 3) % 3, c % 3)
        names[int(c)] = ("".join(("+" if d == 1 else "-") + fx.AXES[a] for a, d in enumerate(digits) if d)
                         or "other")
    return [names[int(c)] for c in code]


def band_labels(v: np.ndarray, unit: str) -> list[str]:
    """Three bands (tertiles) of a quantity, labelled by their ranges."""
    edges = np.unique(np.quantile(v, [1 / 3, 2 / 3]))
    idx = np.searchsorted(edges, v, side="right")
    labels = []
    for b in range(len(edges) + 1):
        sel = v[idx == b]
        labels.append(f"{sel.min():.2f}–{sel.max():.2f} {unit}" if sel.size else "")
    return [labels[i] for i in idx]


def is_structured(prep: Prepared) -> bool:
    return not isinstance(prep.C, np.ndarray)
