"""The ``feature`` task file read and validated into a :class:`generator.feature.task.Task`
(``load``, the kind's contract :class:`generator.taskkind.TaskKind`): ``[feature]`` (element type,
circle plane, axis hint, reference point, weights w_i of Forbes 2022 eq. (11), va_method), the
points (``[points]``, :mod:`generator.taskcloud`) or their sampling strategy (``[sampling]``), and
the a-priori ``[planning]`` of the analytic approximations for partial features (Forbes 2022
Tables 1-8).  Every problem is one :class:`~generator.errors.InputError` naming file and key.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import features as ft
from cmmwb.xlfuncs import partial as pa
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.limits import MAX_COORDINATE_MM, coordinate_problem

from ..errors import InputError, model_errors_named
from ..taskcloud import points_source, read_parameters, read_point_cloud, read_probes
from ..taskfile import COMMON_TABLES, check_keys, number, string, table, task_kind_and_name, text_list, vector3
from ..taskworkpiece import apply_workpiece
from .task import Planning, Task

CIRCLE_PLANE_CHOICES = ("xy", "yz", "zx", "space")
CIRCLE_PLANE_NORMALS = {"xy": (0, 0, 1), "yz": (1, 0, 0), "zx": (0, 1, 0)}

#: [sampling]/[planning] geometry keys and their types
GEOMETRY_KEYS = {
    "r0_mm": "positive", "arc_deg": "positive", "gamma_deg": "positive",
    "beta_deg": "positive", "half_height_mm": "positive", "half_length_mm": "positive",
    "half_width_x_mm": "positive", "half_width_y_mm": "positive", "phi_deg": "number",
    "theta_deg": "pair", "phi_range_deg": "pair",
    "elevations_deg": "numbers", "points_per_ring": "counts",
}
COUNT_KEYS = ("n_points", "n_x", "n_y", "n_theta", "n_phi", "n_z")
BOOL_KEYS = ("north_pole", "south_pole")
SAMPLING_KEYS = set(GEOMETRY_KEYS) | set(COUNT_KEYS) | set(BOOL_KEYS) | {
    "pattern", "center_mm", "axis", "ref_dir", "probe"}
PLANNING_PATTERNS = ("circle_arc", "sphere_cap", "sphere_band", "sphere_segment",
                     "sphere_patch", "sphere_full", "plane_rectangle", "line_segment",
                     "cylinder_patch", "cone_patch")
PLANNING_GEOMETRY = {
    "circle_arc": ("arc_deg", "r0_mm"),
    "sphere_cap": ("gamma_deg",),
    "sphere_band": ("beta_deg",),
    "sphere_segment": ("arc_deg",),
    "sphere_patch": ("theta_deg", "phi_range_deg"),
    "sphere_full": (),
    "plane_rectangle": ("half_width_x_mm", "half_width_y_mm"),
    "line_segment": ("half_length_mm",),
    "cylinder_patch": ("arc_deg", "half_height_mm"),
    "cone_patch": ("arc_deg", "half_height_mm", "r0_mm", "phi_deg"),
}
PLANNING_ELEMENT = {"sphere_full": "sphere", **{k: v["element"] for k, v in pa.PATTERNS.items()}}

VA_METHODS = ("auto", "exact", "lowrank")


# -- reading the task --------------------------------------------------------------------------

def _integer(path, tbl, section, key, default=None, minimum=1) -> int:
    value = tbl.get(key, default)
    where = f"[{section}] {key}"
    if value is None:
        raise InputError("missing key", file=path, where=where)
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"must be a whole number, got {value!r}", file=path, where=where)
    if value < minimum:
        raise InputError(f"must be >= {minimum}, got {value}", file=path, where=where)
    return int(value)


def _geometry(path, tbl, section) -> dict:
    g = {}
    for key, kind in GEOMETRY_KEYS.items():
        if key not in tbl:
            continue
        where = f"[{section}] {key}"
        if kind == "positive":
            g[key] = number(path, tbl, section, key, positive=True)
        elif kind == "number":
            g[key] = number(path, tbl, section, key)
        elif kind == "pair":
            v = tbl[key]
            if (not isinstance(v, list) or len(v) != 2 or
                    not all(isinstance(x, (int, float)) and not isinstance(x, bool) and
                            math.isfinite(x) for x in v) or not v[0] < v[1]):
                raise InputError("must be [from, to] with from < to (degrees)", file=path,
                                 where=where)
            g[key] = [float(x) for x in v]
        else:
            v = tbl[key]
            ok = isinstance(v, list) and v and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                for x in v)
            if kind == "counts":
                ok = ok and all(isinstance(x, int) and x >= 1 for x in v)
            if not ok:
                raise InputError("must be a list of " + ("whole numbers >= 1" if kind == "counts"
                                                         else "numbers"), file=path, where=where)
            g[key] = list(v)
    return g


def _unit_vector(path, tbl, section, key):
    v = vector3(path, tbl, f"[{section}]", key)
    if math.hypot(*v) == 0:
        raise InputError("must not be the zero vector", file=path, where=f"[{section}] {key}")
    return v


def load(path: Path, doc: dict) -> Task:
    path = Path(path)
    kind, name = task_kind_and_name(path, doc)
    check_keys(path, doc, "task file", {"task", "feature", "points", "sampling", "planning",
                                        "parameters", "probes"} | COMMON_TABLES)
    t = table(path, doc, "task")
    check_keys(path, t, "task", {"kind", "name", "notes"})
    notes = text_list(path, t, "task", "notes")

    f = table(path, doc, "feature")
    check_keys(path, f, "feature", {"type", "circle_plane", "axis_hint", "reference_mm",
                                    "weights", "max_iter", "va_method"})
    element = string(path, f, "feature", "type")
    if element not in ft.ELEMENTS:
        raise InputError(f"unknown feature type {element!r}; expected one of "
                         f"{', '.join(ft.ELEMENTS)}", file=path, where="[feature] type")
    circle_plane: str | None = None
    if element == "circle":
        cp = string(path, f, "feature", "circle_plane", "xy")
        if cp not in CIRCLE_PLANE_CHOICES:
            raise InputError(f"must be one of {', '.join(CIRCLE_PLANE_CHOICES)}, got {cp!r}",
                             file=path, where="[feature] circle_plane")
        circle_plane = None if cp == "space" else cp
    elif "circle_plane" in f:
        raise InputError("only a circle has a circle_plane", file=path,
                         where="[feature] circle_plane")
    axis_hint = _unit_vector(path, f, "feature", "axis_hint") if "axis_hint" in f else None
    reference = vector3(path, f, "[feature]", "reference_mm") if "reference_mm" in f else None
    max_iter = _integer(path, f, "feature", "max_iter", 100)
    method = string(path, f, "feature", "va_method", "auto")
    if method not in VA_METHODS:
        raise InputError(f"must be one of {', '.join(VA_METHODS)}, got {method!r}", file=path,
                         where="[feature] va_method")

    has_points, has_sampling = "points" in doc, "sampling" in doc
    if has_points == has_sampling:
        raise InputError("give the points either as [points] file = ... or as a [sampling] "
                         "strategy (exactly one of them)", file=path,
                         where="[points]" if has_points else "[sampling]")
    sampling = None
    if has_points:
        cloud, params, _ = read_point_cloud(path, doc)
        source = "[points]"
    else:
        params = read_parameters(path, doc)
        probes = read_probes(path, doc)
        sampling, cloud = _read_sampling(path, doc, element, circle_plane, params, probes)
        cloud, params = apply_workpiece(path, doc, cloud, params)
        source = "[sampling]"
        far = float(np.max(np.abs(cloud.X_mm))) if cloud.m else 0.0
        if coordinate_problem(far) is not None:   # sizes so large that float64 loses the nanometre
            raise InputError(f"the sampled points reach {far:g} mm from the origin, outside the plausible "
                             f"machine range +-{MAX_COORDINATE_MM:g} mm (float64 would lose the nanometre)",
                             file=path, where="[sampling]")

    weights = np.ones(cloud.m)
    if "weights" in f:
        w = f["weights"]
        if not isinstance(w, dict):
            raise InputError("must be a table {point id = weight}", file=path,
                             where="[feature] weights")
        index = {lab: i for i, lab in enumerate(cloud.labels)}
        for lab in w:
            if lab not in index:
                raise InputError(f"unknown point {lab!r}", file=path,
                                 where=f"[feature] weights.{lab}")
            weights[index[lab]] = _weight(path, w, lab)

    planning = _read_planning(path, doc, element, circle_plane, sampling, cloud.m) \
        if "planning" in doc else None
    return Task(path, name, element, circle_plane, cloud, params, weights, axis_hint, reference,
                max_iter, source, sampling, planning, list(notes), method,
                points_source=points_source(doc) if has_points else
                "the nominal points of the sampling plan [sampling]")


def _weight(path, w: dict, lab: str) -> float:
    value = w[lab]
    where = f"[feature] weights.{lab}"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not math.isfinite(float(value)):
        raise InputError(f"must be a finite number, got {value!r}", file=path, where=where)
    if value < 0:
        raise InputError(f"must be >= 0, got {value:g}", file=path, where=where)
    return float(value)


def _read_sampling(path, doc, element, circle_plane, params, probes):
    s = table(path, doc, "sampling")
    check_keys(path, s, "sampling", SAMPLING_KEYS)
    pattern = string(path, s, "sampling", "pattern")
    if pattern not in pa.PATTERNS:
        raise InputError(f"unknown pattern {pattern!r}; expected one of "
                         f"{', '.join(pa.PATTERNS)}", file=path, where="[sampling] pattern")
    if pa.PATTERNS[pattern]["element"] != element:
        raise InputError(f"pattern {pattern!r} samples a {pa.PATTERNS[pattern]['element']}, "
                         f"the feature is a {element}", file=path, where="[sampling] pattern")
    g = _geometry(path, s, "sampling")
    for key in COUNT_KEYS:
        if key in s:
            g[key] = _integer(path, s, "sampling", key, minimum=1)
    for key in BOOL_KEYS:
        if key in s:
            if not isinstance(s[key], bool):
                raise InputError("must be true or false", file=path, where=f"[sampling] {key}")
            g[key] = s[key]
    kw = {}
    for key in ("center_mm", "axis", "ref_dir"):
        if key in s:
            kw[key] = (vector3(path, s, "[sampling]", key) if key == "center_mm"
                       else _unit_vector(path, s, "sampling", key))
    if circle_plane is not None and element == "circle":
        want = np.array(CIRCLE_PLANE_NORMALS[circle_plane], float)
        ax = np.array(kw.get("axis", (0, 0, 1)), float)
        if abs(abs(ax @ want) / np.linalg.norm(ax) - 1) > 1e-12:
            raise InputError(f"a circle in the {circle_plane} plane needs axis = "
                             f"{list(CIRCLE_PLANE_NORMALS[circle_plane])}", file=path,
                             where="[sampling] axis")
    spec_keys = pa.PATTERNS[pattern]["keys"]
    for key in spec_keys:
        if key not in g:
            raise InputError(f"pattern {pattern!r} needs {key}", file=path,
                             where=f"[sampling] {key}")
    g_core = dict(g)
    for key in g:
        if key not in spec_keys and key not in BOOL_KEYS:
            raise InputError(f"not a key of pattern {pattern!r} (expected "
                             f"{', '.join(spec_keys)})", file=path, where=f"[sampling] {key}")
    probe_id = string(path, s, "sampling", "probe", probes[0].id)
    ids = [p.id for p in probes]
    if probe_id not in ids:
        raise InputError(f"unknown probe {probe_id!r} (the task defines {', '.join(ids)})",
                         file=path, where="[sampling] probe")
    with model_errors_named(file=path, where="[sampling]"):
        smp = pa.sample(pattern, **kw, **g_core)
        for p in probes:
            p.resolved(params)
        cloud = pc.PointCloud(smp.X_mm, smp.N, np.full(smp.m, ids.index(probe_id)), probes,
                              smp.labels)
    info = {"pattern": pattern, **{k: v for k, v in kw.items()}, **g, "probe": probe_id}
    return info, cloud


def _read_planning(path, doc, element, circle_plane, sampling, m) -> Planning:
    p = table(path, doc, "planning")
    allowed = {"pattern", "sweep", "values", "m_points", *GEOMETRY_KEYS}
    check_keys(path, p, "planning", allowed)
    default = sampling["pattern"] if sampling else None
    pattern = string(path, p, "planning", "pattern", default)
    if pattern not in PLANNING_PATTERNS:
        raise InputError(f"no analytic approximation for {pattern!r}; expected one of "
                         f"{', '.join(PLANNING_PATTERNS)}", file=path, where="[planning] pattern")
    if PLANNING_ELEMENT[pattern] != element:
        raise InputError(f"pattern {pattern!r} approximates a {PLANNING_ELEMENT[pattern]}, the "
                         f"feature is a {element}", file=path, where="[planning] pattern")
    needed = PLANNING_GEOMETRY[pattern]
    g = {}
    base = {k: v for k, v in (sampling or {}).items() if k in needed} if sampling and \
        sampling["pattern"] == pattern else {}
    g.update(base)
    g.update({k: v for k, v in _geometry(path, p, "planning").items()})
    for key in g:
        if key not in needed:
            raise InputError(f"not a key of pattern {pattern!r} (expected "
                             f"{', '.join(needed) or 'none'})", file=path,
                             where=f"[planning] {key}")
    sweep = None
    values: list[float] = []
    if "sweep" in p:
        sweep = string(path, p, "planning", "sweep")
        if sweep not in needed or GEOMETRY_KEYS[sweep] not in ("positive", "number"):
            raise InputError(f"must name a number key of pattern {pattern!r} "
                             f"({', '.join(k for k in needed if GEOMETRY_KEYS[k] != 'pair')})",
                             file=path, where="[planning] sweep")
        raw = p.get("values")
        if (not isinstance(raw, list) or not raw or
                not all(isinstance(x, (int, float)) and not isinstance(x, bool) and
                        math.isfinite(x) for x in raw)):
            raise InputError("must be a non-empty list of numbers", file=path,
                             where="[planning] values")
        values = [float(x) for x in raw]
        g.pop(sweep, None)
    elif "values" in p:
        raise InputError("values need a sweep key", file=path, where="[planning] values")
    for key in needed:
        if key != sweep and key not in g and not (pattern == "circle_arc" and key == "r0_mm"):
            raise InputError(f"pattern {pattern!r} needs {key}", file=path,
                             where=f"[planning] {key}")
    m_points = _integer(path, p, "planning", "m_points", m)
    plan = Planning(pattern, sweep, values, g, m_points,
                    space=(element == "circle" and circle_plane is None))
    safe_rows(path, plan)  # bad geometry is an input error now, not at compute time
    return plan


def safe_rows(path, plan: Planning):
    with model_errors_named(file=path, where="[planning]"):
        return plan.rows()
