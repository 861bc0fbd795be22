"""The ``feature`` task: uncertainty of least-squares fitted features (Forbes 2022) under the
full point-cloud V_X of Forbes 2025, decomposed per influence factor (Forbes 2025 section 5.6),
and a-priori planning with the analytic approximations for partial features (Tables 1-8).

Task file::

    [task]      kind = "feature", name, notes
    [feature]   type (line | plane | circle | sphere | cylinder | cone), circle_plane,
                axis_hint, reference_mm, weights = {point id = w}, max_iter,
                va_method (auto | exact | lowrank: how V_A of large clouds is computed)
    [points]    file = "points.csv"          (id,x,y,z,nx,ny,nz,probe)   -- or --
    [sampling]  pattern = "cylinder_patch", geometry keys, counts, center_mm, axis, ref_dir, probe
    [planning]  pattern, sweep, values, geometry keys, m_points   (optional)
    [parameters], [[probes]]                  the point-cloud model (Forbes 2025 Table 3 names)

Reading the task file: :mod:`generator.feature.loader`.
Workbook: see :mod:`generator.feature.book`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import features as ft
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.distributed import get_backend

from .. import __version__
from ..errors import InputError, model_errors_named
from ..quantities import Cells, Quantity, ToleranceKeys
from ..taskkind import no_type_a, no_verdicts
from ..workbook.book import RESULTS, BookAdditions
from ..workbook.xlref import cell
from .loader import load as load
from .loader import safe_rows
from .task import KIND, Task, fit_state

EXAMPLES = [
    "feature_cylinder_bore.toml",
    "feature_table1_circle_arc.toml",
    "feature_table2_sphere_cap.toml",
    "feature_table3_sphere_band.toml",
    "feature_table4_sphere_segment.toml",
    "feature_table5_cylinder_patch.toml",
    "feature_table6_cone_angle.toml",
    "feature_table7_cone_arc.toml",
    "feature_table8_sphere_six.toml",
    "feature_table8_sphere_five.toml",
    "feature_table8_sphere_nine.toml",
    "feature_plane_face.toml",
]
#: the task-kind contract (generator.taskkind): the starter task samples its points ([sampling]),
#: no table beside it; no type A inputs
NEW_TASK_FILES: dict[str, str] = {}
add_type_a = no_type_a
verdicts = no_verdicts


# -- computing -----------------------------------------------------------------------------

#: up to this many points V_A = G V_X G^T uses the dense V_X (what the workbook shows); beyond,
#: the blocked evaluation that never forms V_X (equal to 1e-10, tests/core/test_blocked.py)
DENSE_MAX_POINTS = 300
#: beyond this many points the GP factors (ET, ER, P) of V_A go through the controlled low-rank
#: factor of xlfuncs.lowrank (time linear in m; results carry "approximation" with its error
#: bound); "exact" (task key [feature] va_method, cmmwb build --exact, or CMMWB_VA_METHOD)
#: forces the exact O(m^2) blocked sum, "lowrank" the factor at any size
LOWRANK_MIN_POINTS = 100_000
VA_METHOD_ENV = "CMMWB_VA_METHOD"


def force_exact(task: Task) -> None:
    """``cmmwb build --exact``: V_A by the exact method whatever the task or environment say."""
    task.va_method = "exact"


def va_method(m: int, requested: str = "auto") -> str:
    """"exact" or "lowrank" for V_A of m points: ``requested`` (the task's ``[feature]
    va_method`` or ``build --exact``) unless "auto", then the environment variable
    CMMWB_VA_METHOD unless unset or "auto", then by size (see LOWRANK_MIN_POINTS)."""
    import os

    if requested in ("exact", "lowrank"):
        return requested
    choice = os.environ.get(VA_METHOD_ENV, "").strip().lower()
    if choice in ("exact", "lowrank"):
        return choice
    if choice not in ("", "auto"):
        raise InputError(f"{VA_METHOD_ENV} must be exact, lowrank or auto, got {choice!r}")
    return "lowrank" if m > LOWRANK_MIN_POINTS else "exact"


def propagation_method(m: int, requested: str = "auto") -> str:
    """The core function :func:`fitted` uses for V_A = G V_X G^T of m points, as the workbook
    notes name it (the grey V_A values above the native-formula limit)."""
    if m <= DENSE_MAX_POINTS:
        return ("xlfuncs.features.propagate of the dense V_X of xlfuncs.pointcloud.V_X_components "
                f"({3 * m} x {3 * m})")
    if va_method(m, requested) == "lowrank":
        return ("xlfuncs.blocked.propagate_cloud with the low-rank GP factors of xlfuncs.lowrank "
                "(error bound in the results' approximation)")
    return "xlfuncs.blocked.propagate_cloud (G V_X G^T in row blocks, V_X never formed)"


def fitted(task: Task):
    """The fit and the per-factor V_A (cached on the task)."""
    if task._fit is None:
        with model_errors_named(file=task.path, where=task.source):
            f = ft.fit(task.element, task.cloud.X_mm, weights=task.weights,
                       normals=task.cloud.N, axis_hint=task.axis_hint,
                       circle_plane=task.circle_plane if task.element == "circle" else "xy",
                       reference_mm=task.reference_mm, max_iter=task.max_iter)
        with model_errors_named(file=task.path, where="[parameters]"):
            if task.cloud.m <= DENSE_MAX_POINTS:
                task._unc = ft.propagate(f, pc.V_X_components(task.cloud, task.params))
            else:  # V_X would not fit in memory: G V_X G^T in row blocks (xlfuncs.blocked)
                task._unc = bl.propagate_cloud(f, task.cloud, task.params, backend=get_backend(),
                                               progress=bl.ProgressBar(f"V_A of {task.cloud.m} points"),
                                               method=va_method(task.cloud.m, task.va_method))
        task._fit = f
    return task._fit, task._unc


def _cov(V):
    return [[float(x) for x in row] for row in V]


def compute(task: Task) -> dict:
    f, unc = fitted(task)
    names = list(f.names)
    step_norm = float(np.linalg.norm(f.gauss_newton_step()))
    feature = {
        "type": task.element,
        "parameters": {n: float(v) for n, v in zip(names, f.values)},
        "u": {n: float(u) for n, u in zip(names, unc.u())},
        "covariance": _cov(unc.V["total"]),
        "parameter_names": names,
        "components": {fac: {n: float(u) for n, u in zip(names, unc.u(fac))}
                       for fac in pc.FACTORS},
        "units": {n: _unit(n) for n in names},
        "circle_plane": ("space" if task.element == "circle" and task.circle_plane is None
                         else task.circle_plane),
        "local": {
            "parameter_names": list(f.local_names),
            "values": {n: float(v) for n, v in zip(f.local_names, f.local_values)},
            "u": {n: float(u) for n, u in zip(f.local_names, unc.u_local())},
            "covariance": _cov(unc.V_local["total"]),
            "components": {fac: {n: float(u) for n, u in zip(f.local_names, unc.u_local(fac))}
                           for fac in pc.FACTORS},
            "frame": {"origin_mm": [float(x) for x in f.origin_mm],
                      "R": _cov(f.R)},
            "note": "paper parametrisation (Forbes 2022) in the solution frame: element in "
                    "standard position, rot_x/rot_y small rotations about the frame axes",
        },
        "fit": {"m": f.m, "iterations": f.iterations, "rms_residual_mm": f.rms_mm,
                "source": task.source, "gauss_newton_step_norm": step_norm,
                "state": fit_state(step_norm)},
    }
    if unc.approximation is not None:
        feature["approximation"] = unc.approximation.as_dict()
    out = {"name": task.name, "kind": KIND, "version": __version__, "feature": feature}
    if task.sampling is not None:
        out["sampling"] = {k: (list(v) if isinstance(v, tuple) else v)
                           for k, v in task.sampling.items()}
    if task.planning is not None:
        out["planning"] = planning_results(task)
    return out


def _unit(name: str) -> str:
    return "mm" if name.endswith("_mm") else "rad" if name.endswith("_rad") else "1"


def planning_results(task: Task) -> dict:
    plan = task.planning
    sigma_mm = task.params.sigma_R_um * 1e-3
    rows = []
    names: list[str] = []
    for v, ap in safe_rows(task.path, plan):
        names = list(ap.parameter_names)
        s = ap.s
        u = sigma_mm * s / math.sqrt(plan.m_points)
        row = {"s": dict(zip(names, map(float, s))), "u": dict(zip(names, map(float, u)))}
        if plan.sweep:
            row = {plan.sweep: v, **row}
        rows.append(row)
    return {"pattern": plan.pattern, "sweep": plan.sweep, "geometry": plan.geometry,
            "m_points": plan.m_points, "sigma_R_um": task.params.sigma_R_um,
            "parameter_names": names,
            "note": "Forbes 2022 eq. (15): (1/m) J^T J ~ H of the patch; s = sqrt(diag H^-1); "
                    "u = sigma_R s / sqrt(m) for V_X = sigma_R^2 I",
            "rows": rows}


# -- outputs ---------------------------------------------------------------------------------

def write_book(task: Task, results: dict, path: Path, additions: BookAdditions | None = None) -> None:
    from .book import write_feature_book

    fit = fitted(task)
    write_feature_book(task, results, path, fit, propagation_method(fit[0].m, task.va_method), additions=additions)


def write_plots(task: Task, results: dict, out_dir: Path) -> list[Path]:
    from ..workbook.plots import factor_share_plot, log_scale, pyplot

    plt = pyplot()
    fe = results["feature"]
    live = [n for n in fe["parameter_names"] if fe["u"][n] > 0]
    # share of the variance u_f^2 / u^2 of each parameter (Forbes 2025 section 5.6)
    shares = {fac: [(fe["components"][fac][n] / fe["u"][n]) ** 2 for n in live] for fac in pc.FACTORS}
    files = [factor_share_plot(live, shares, f"{results['name']}: {fe['type']} fitted to {fe['fit']['m']} points",
                               out_dir / f"{task.name}_factors.png")]
    if "planning" in results and results["planning"]["sweep"]:
        pl = results["planning"]
        fig, ax = plt.subplots(figsize=(7, 4.2), dpi=110)
        x = [r[pl["sweep"]] for r in pl["rows"]]
        for n in pl["parameter_names"]:
            ax.plot(x, [r["s"][n] for r in pl["rows"]], "o-", ms=3, label=f"s({n})")
        log_scale(ax, "y")
        ax.set_xlabel(pl["sweep"])
        ax.set_ylabel("s(a) = sqrt(diag V)")
        ax.set_title(f"{results['name']}: {pl['pattern']} (Forbes 2022)")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        fig.tight_layout()
        p = out_dir / f"{task.name}_planning.png"
        fig.savefig(p)
        plt.close(fig)
        files.append(p)
    return files


# -- the records of the results (generator.quantities) -----------------------------------------

#: a [[decision.tolerances]] entry names a length parameter of the fit; the results give u only:
#: U = k·u with the [decision] k
TOLERANCE_KEYS = ToleranceKeys(("parameter",), help='parameter = a length parameter of the fit, e.g. "r0_mm"',
                               k_from_decision=True, hint=" ; only length parameters (_mm) take a tolerance")
U_SOURCE = ("the point-cloud model V_X of six influence factors propagated to the fitted parameters "
            "(V_A = G V_X G^T, Forbes 2022 eq. (12), Forbes 2025)")


def quantities(task: Task, results: dict, k: float = 2.0) -> list[Quantity]:
    """One record per length (mm) and angle (rad) parameter of the fit (its Results row: value
    and u in the parameter's unit), U = k·u with ``k`` (the ``[decision] k``, default 2).
    Unit-vector components (unit 1) have no record: they are directions, read on Results."""
    fe = results["feature"]
    fitted_to = (f"the least-squares {fe['type']} fitted to {task.points_source}"
                 + (" (the nominal geometry, not a measurement)" if task.sampling is not None else ""))
    out = []
    for i, n in enumerate(fe["parameter_names"]):
        r = i + 2
        length = n.endswith("_mm")
        if not (length or n.endswith("_rad")):
            continue
        scale = 1000.0 if length else 1.0
        out.append(Quantity(label=n, value=fe["parameters"][n], unit="mm" if length else "rad",
                            u=fe["u"][n] * scale, u_unit="µm" if length else "rad", k=float(k),
                            U_unit="µm" if length else "rad", ident={"parameter": n},
                            value_source=fitted_to, u_source=U_SOURCE, own_U=False,
                            cells=Cells(RESULTS, r, cell(r, 2, RESULTS), cell(r, 3, RESULTS), u_scale=scale)))
    return out


def read_book(cells, rt, points_file: str) -> None:
    """The way back (``cmmwb read``): :func:`generator.feature.reader.read_feature`."""
    from .reader import read_feature

    read_feature(cells, rt, points_file)


def summary(results: dict) -> list[str]:
    fe = results["feature"]
    names = fe["parameter_names"]
    key = next((n for n in ("r0_mm", "z_A_mm", "x0_mm") if n in names), names[0])
    scale = 1e3 if key.endswith("_mm") else 1e6
    unit = "µm" if key.endswith("_mm") else "µrad"
    comps = {fac: fe["components"][fac][key] for fac in pc.FACTORS}
    top = max(comps, key=comps.get)
    lines = [f"{fe['type']} fitted to {fe['fit']['m']} points: {key} = {fe['parameters'][key]:.4f}, "
             f"u = {fe['u'][key] * scale:.3f} {unit} (largest factor {top}: "
             f"{comps[top] * scale:.3f} {unit})"]
    if "planning" in results:
        pl = results["planning"]
        rows = pl["rows"]
        if pl["sweep"]:
            lines.append(f"planning ({pl['pattern']}): {len(rows)} rows of s(a) over "
                         f"{pl['sweep']} = {rows[0][pl['sweep']]:g} .. {rows[-1][pl['sweep']]:g}")
        else:
            s = ", ".join(f"{k} {v:.2f}" for k, v in rows[0]["s"].items())
            lines.append(f"planning ({pl['pattern']}): s = {s}")
    return lines


NEW_TASK = '''# cmmwb feature task (Forbes 2022 + Forbes 2025): uncertainty of a least-squares fitted
# element under the six-factor point-cloud model, per influence factor.
# Units: coordinates mm, uncertainties µm in [parameters]; results: lengths mm, angles rad.
# Build with:  cmmwb build THIS.toml --out DIR

[task]
kind = "feature"
name = "my_feature"             # file stem of the outputs

[feature]
type = "cylinder"               # line | plane | circle | sphere | cylinder | cone
# circle_plane = "xy"           # circle only: xy | yz | zx (2D fit, section 4) or "space"
# axis_hint = [0, 0, 1]         # rough axis/normal: starting estimate and sign of the result
# reference_mm = [0, 0, 0]      # locating point = point of the axis nearest to this point
#                               # (default: centroid of the points); a cone's r0 is taken there
# weights = { X3 = 0.5, X7 = 0 } # w_i of Forbes 2022 eq. (11) by point id (default 1)
# va_method = "auto"            # V_A of large clouds: auto (exact up to 100,000 points, then the
#                               # low-rank GP factors with an error bound in the JSON) | exact | lowrank

# The points: either a file ...
# [points]
# file = "points.csv"           # id,x,y,z,nx,ny,nz,probe  (mm; n = outward unit normal)

# ... or a sampling strategy that builds the nominal points (midpoint grid, uniform by area)
[sampling]
pattern = "cylinder_patch"      # line_segment | plane_rectangle | circle_arc | sphere_cap |
                                # sphere_band | sphere_segment | sphere_patch | sphere_rings |
                                # cylinder_patch | cone_patch
center_mm = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]          # element axis (plane normal, sphere pole, line direction)
r0_mm = 25.0
arc_deg = 360.0                 # full arc angle 2 alpha
half_height_mm = 20.0           # a: points in -a <= z <= a
n_theta = 24                    # points per ring
n_z = 5                         # rings
probe = "P1"

# Optional: planning without data, the analytic approximation (Forbes 2022 Tables 1-8)
[planning]
sweep = "arc_deg"               # one row per value; other geometry keys from [sampling]
values = [360, 270, 180, 120, 60, 20]

[parameters]                    # Forbes 2025 Table 3 names; absent ones are 0
sigma_R_um = 0.20
sigma_S_ppm = 0.7
sigma_Sa_ppm = 0.7
sigma_Q_ppm = 0.7
sigma_PQ_um = 0.20
sigma_ET_um = 0.2
lambda_ET_mm = 200
sigma_ER_urad = 4.0
lambda_ER_mm = 400
sigma_P0_um = 0.10
sigma_P_um = 0.10
lambda_P = 0.5

[[probes]]
id = "P1"
offset_mm = [0.0, 0.0, -50.0]

# Optional: the part's temperature, the factor W (docs/workpiece.md); without the table W is off.
# [workpiece]
# material = "aluminium"        # or alpha_ppm_per_K = 23.1 (1e-6/K); aluminium 23.1, steel 11.5
# u_alpha_ppm_per_K = 1.0       # u(alpha)
# T_degC = 23.5                 # the part's temperature, or T_readings_degC = [23.3, 23.7]
# u_T_K = 0.3                   # u(T) of the thermometer
# corrected = true              # the CMM corrects to 20 °C (with alpha_corr_ppm_per_K, default alpha)
# fixture_mm = [0, 0, 0]        # where the part is held (it expands about this point)
# enabled = true                # W on/off

# Optional: conformity decisions (docs/conformity.md) and report fields for the Summary sheet.
# [decision]
# rule = "iso14253"             # iso14253 | simple | guarded_acceptance (r) | guarded_rejection (r) | specific_risk (max_pfa)
# k = 2                         # U = k·u
# [[decision.tolerances]]
# parameter = "r0_mm"           # a length parameter of the fit
# lsl_mm = 24.995               # or tol_mm around nominal_mm
# usl_mm = 25.005
# measured_mm = 25.001          # optional; s_um and n_repeats add a type A repeatability
# [report]
# lab = "..."                   # also operator, cmm, artefact, job_id, notes
'''
