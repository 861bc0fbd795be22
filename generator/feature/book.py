"""The ``feature`` workbook: a least-squares fitted element (Forbes 2022) and the propagation of
the six-factor point-cloud V_X (Forbes 2025) to its parameters, as native formulas.

Sheets (in order):

``Instructions``  what, how, conventions and the Forbes 2022 errata
``Inputs``        hyper-parameters (named = task keys), probes            (pointcloud.vx_sheets)
``Points``        x_i, probing normals, probes                            (pointcloud.vx_sheets)
``Coords``, ``V_R`` ... ``V_P``, ``V_X``  the 3m x 3m V_X contributions   (pointcloud.vx_sheets;
                  only up to FEATURE_NATIVE_MAX_POINTS points)
``Fit``           the fitted frame and shape: values computed by xlfuncs.features.fit
                  (Gauss-Newton cannot be a native formula), clearly marked
``Local``         weights w_i and the points in the solution frame: P = (X - origin) R
``J``             residuals d, the Jacobian J (Forbes 2022 sections 4-8), local and machine
                  normals N, W = w^2
``H``             H = J^T W J, H^-1 = MINVERSE(H), the Gauss-Newton step (0 at the solution)
``G_A_D``         G_A|D^T = -W J H^-1       (eq. (12), transposed: one row per residual)
``G_A_X``         G_A|X^T = N G_A|D^T       (eq. (8), transposed: one row per coordinate)
``V_A``           T (reported <- local parameters) and, per factor, V_A,f = G V_X,f G^T and
                  T V_A,f T^T (Forbes 2025 section 5.6)
``Budget``        value, u and u per factor of each parameter (reported and paper parameters)
``Planning``      (when the task has [planning]) the analytic approximation H of the patch,
                  V = MINVERSE(H), s = sqrt(diag V) per row (Forbes 2022 Tables 1-8)
``Results``       parameter, value, u (the contract)

Above FEATURE_NATIVE_MAX_POINTS points the V_X sheets are not written; V_A,f of the factors
other than R are then values computed by xlfuncs (grey cells, with a note naming the core
function: ``generator.feature.job.propagation_method``); J, H, G and the R factor stay native
formulas.  Such workbooks also carry, as the large point-cloud workbook does
(``generator.pointcloud.large_book``):

``Live_addin``    the same numbers as Excel add-in formulas (``xlfuncs.udf``): ``cmm_feature``
                  (value, u and the six components of each reported parameter) and, per grey
                  factor, ``cmm_feature_va`` (reported V_A,f, at the cells of T V_A,f T^T on
                  'V_A') and T^T V_A,f T x 1e12 at the cells of the grey values.  #NAME? in
                  LibreOffice and without the add-in -- by design, no other cell refers to it.
``xlwings.conf``  ``UDF Modules = xlfuncs.udf`` for this workbook.
"""

from __future__ import annotations

from openpyxl.styles import Alignment

from xlfuncs import pointcloud as pc

from .. import __version__
from ..pointcloud.large_book import LIVE, addin_ranges, write_xlwings_conf
from ..pointcloud.vx_sheets import FACTOR_TITLES, explain_inputs, write_inputs, write_point_cloud_model, write_points
from ..workbook.book import FMT_SCI, Book, BookAdditions, Formula
from ..workbook.cache import FEATURE_NOT_APPLICABLE
from ..workbook.xlref import Block, block, cell
from .task import FIT_CURRENT, FIT_STALE, KIND, STALE_STEP, Task

#: native V_X formulas up to this many points (7 matrices of 3m x 3m plus J, G, V_A).  Measured
#: with `python bench/bench_feature.py --workbooks 24 48 72 100` (cylinder, full model; formulas
#: 1.3.4 / LibreOffice 7.4 on 2 shared cores; second figure under load ~4.5):
#:   m =  24:  formulas  5-11 s, LibreOffice  3-6 s
#:   m =  48:  formulas 13-19 s, LibreOffice  5-7 s
#:   m =  72:  formulas 23-34 s, LibreOffice  8-15 s
#:   m = 100:  formulas 53-70 s, LibreOffice 27-34 s
#: Above it the V_X sheets are omitted and V_A of PQ, S, ET, ER, P are core values (2,000 points:
#: LibreOffice recalculates in 6 s).
FEATURE_NATIVE_MAX_POINTS = 100

FMT = "0.000000000"
#: core-computed V_A blocks are written x 1e12 (see _write_V_A)
VALUE_SCALE = 1e12
SMALL = FMT_SCI


def write_feature_book(task: Task, results: dict, path, fit, method: str, *,
                       native_max_points: int | None = None, additions: BookAdditions | None = None):
    """The workbook of a fitted feature: ``fit`` = (fit, per-factor V_A) of the task and
    ``method`` the name of the core function that computed V_A (both from
    :mod:`generator.feature.job`: ``fitted``, ``propagation_method``)."""
    f, unc = fit
    limit = FEATURE_NATIVE_MAX_POINTS if native_max_points is None else native_max_points
    native = f.m <= limit
    book = Book(KIND, task.name, f"Uncertainty of a least-squares {_label(f)} — {task.name}")
    _instructions(book, task, f, native, limit, method)
    if native:
        layout = write_point_cloud_model(book, task.cloud, task.params)
        X, V = layout.X, layout.V
        probe_rows = None
    else:
        _, probe_rows = write_inputs(book, task.params, task.cloud)
        X, _, _ = write_points(book, task.cloud, probe_rows)
        V = None
    fitref = _write_fit(book, f, task)
    local = _write_local(book, f, task, X)
    labels = task.cloud.labels
    jac = _write_jacobian(book, f, local, labels)
    hs = _write_H(book, f, jac, labels)
    gx = _write_G(book, f, jac, hs)
    va = _write_V_A(book, f, unc, gx, V, method)
    rows = _write_budget(book, f, va, fitref)
    if task.planning is not None:
        _write_planning(book, task, results)
    if not native:
        _write_live(book, task, f, va, probe_rows)
    _write_results(book, f, rows)
    if not native:
        write_xlwings_conf(book)
    book.save(path, additions)


#: the Results columns: the contract's parameter, value, u (in the parameter's unit, docs/cli.md),
#: then what a person reads: the unit, u in µm (lengths) or µrad (angles; for a unit-vector
#: component u x 1e6, the tilt of the direction in µrad), and whether the fit is current
RESULT_COLUMNS = ["parameter", "value", "u", "unit", "u_um", "u_urad", "fit_state"]
NOT_APPLICABLE = FEATURE_NOT_APPLICABLE


def result_row(name: str, budget_row: int, step: Block) -> list:
    """One Results row of parameter ``name`` (its row on 'Budget'); ``step`` = the Gauss-Newton
    step on 'H'."""
    scale, shown = u_display(name)
    u_shown = Formula(f"={cell(budget_row, U_COLUMN, 'Budget')}")
    return [name, Formula(f"={cell(budget_row, 2, 'Budget')}"),
            Formula(f"={cell(budget_row, U_COLUMN, 'Budget')}/{scale:g}"), _unit(name),
            u_shown if shown == "µm" else NOT_APPLICABLE,
            u_shown if shown != "µm" else NOT_APPLICABLE,
            Formula(f'=IF(SQRT(SUMSQ({step.ref}))>{STALE_STEP:.9f},"{FIT_STALE}","{FIT_CURRENT}")')]


def _write_results(book: Book, f, rows: list[tuple[str, int]]) -> None:
    step = gn_step_block(f.n)
    ws = book.results(
        RESULT_COLUMNS, [result_row(name, r, step) for name, r in rows],
        notes=[None, "fitted value, in the unit of column 'unit' (mm, rad, or 1 for a unit-vector "
               "component)", "standard uncertainty, in the unit of column 'unit' (the contract's "
               "column; u_um / u_urad show it in µm or µrad)",
               "unit of value and u (the contract's columns parameter, value, u are in the "
               "parameter's unit: mm, rad or 1)",
               "u in µm, for a length (the same u as column u)",
               "u in µrad, for an angle; for a unit-vector component u x 1e6 (to first order the "
               "tilt of the direction in µrad)",
               f"'{FIT_CURRENT}' while the fitted values on 'Fit' are the least-squares solution "
               "of the points on 'Points'/'Local'; red when the Gauss-Newton step on 'H' is not "
               f"zero (norm > {STALE_STEP:g} in mm and rad): the points or weights were edited, "
               "the values on 'Fit' are no longer their fit, and the results are stale. The fit "
               "is not a formula: read the workbook back (cmmwb read) and build it again."],
        formats=[None, "0.000000", FMT_SCI, None, "0.0000", "0.0000", None])
    last = 1 + len(rows)
    for r in range(2, last + 1):   # unit and '—' centred: a right-aligned 0 ran into the unit '1'
        for c in (4, 5, 6):
            if ws.cell(row=r, column=c).data_type == "s":
                ws.cell(row=r, column=c).alignment = Alignment(horizontal="center")
    book.flag_unless(ws, f"G2:G{last}", FIT_CURRENT)
    for col, width in (("B", 16), ("C", 12), ("E", 10), ("F", 10), ("G", 12)):
        ws.column_dimensions[col].width = width


def _label(f) -> str:
    return "circle (in space)" if f.kind == "circle_space" else f.element


# -- instructions ---------------------------------------------------------------------------

ERRATA = [
    "Forbes 2022 conventions used here (docs/errata.md, section 'Forbes 2022'):",
    "- Axis parameters u_A, v_A of sections 7-8 are small rotations of the axis about the frame x and y "
    "axes (rot_x, rot_y): the Jacobian rows -[cos, sin, -z sin, z cos, 1] of section 7 belong to them.",
    "- Sphere patch (section 5.1): H_A(2,4) = int sin(theta) int cos^2(phi), H_A(3,3) = (a2-a1) int "
    "sin^2(phi) cos(phi); H_A(3,4) = (a2-a1) int sin(phi) cos(phi) is missing in the paper.",
    "- Cap (section 5.2): H_gamma(1,1) has + cos^3(gamma)/3.  Segment (eq. (20)): V_alpha(4,4) = "
    "(alpha + sin(2 alpha)/2)/(3 alpha D14) (printed inverted).",
    "- Cone (Tables 6, 7): points uniform by area (weight rho = r0 - z tan(phi), signed: Table 6's "
    "phi = 70 deg row integrates past the apex); Table 6 needs r0 = 100, a = 50 (the text says r0 = 50, "
    "a = 100); Table 7 needs r0 = a = 50 and its rotation columns are s(u_A), s(v_A), not a s(...).",
    "- Table 8: 's(a) = sigma_R u(a)' means u(a) = sigma_R s(a); the nine-point elevation is "
    "asin((8 + sqrt(4320))/76) = 75.95 deg.",
]


def _instructions(book: Book, task: Task, f, native: bool, limit: int, method: str) -> None:
    book.para("What this workbook computes", bold=True)
    book.para(
        f"The uncertainty of a least-squares {_label(f)} fitted to {f.m} points, per CMM influence "
        "factor. Fit and sensitivities: A. Forbes, 'Sensitivity analysis for Gaussian-associated features', "
        "Appl. Sci. 2022, 12, 2808 (orthogonal distance regression, eqs. (7), (11); G_A|X = -(J^T W J)^-1 "
        "J^T W N^T, eqs. (8), (12)). Point-cloud variance V_X: A. Forbes, Appl. Sci. 2025, 15, 271, eq. (28); "
        "V_A = G_A|X V_X G_A|X^T per factor (section 5.6).",
        "The fit itself (Gauss-Newton iterations) is done by cmmwb's core and written on 'Fit' as values "
        "(grey); everything that follows from it -- Jacobian, H, MINVERSE, G, V_A -- is a native formula.")
    book.gap()
    book.para("How to use it", bold=True)
    book.para(
        "1. Edit the yellow cells: hyper-parameters on 'Inputs', weights on 'Local', points and normals on "
        "'Points'. G and V_A recalculate. After moving points or changing weights the fitted values on "
        "'Fit' are no longer the least-squares solution: the Gauss-Newton step on 'H' then is not zero "
        "(rebuild from the task file to refit: `cmmwb read`, edit, `cmmwb build`).",
        "2. 'Budget' lists each parameter with u and its six components (u^2 = sum of u_f^2), in µm for "
        "lengths, µrad for angles and 1e-6 for direction components (column u_unit); 'Results' is "
        "the machine-readable summary, where u is in the parameter's unit as the task file's keys say "
        "(lengths mm, angles rad, direction components 1).",
        "3. Reported parameters: the locating point of a line, plane, cylinder or cone is the point of the "
        "axis (plane) nearest to the reference point (the centroid of the points unless the task sets "
        "reference_mm); its uncertainty is that of the axis in the plane through it orthogonal to the axis. "
        "Directions are unit vectors (their covariance is singular along the direction). The paper's own "
        "parameters (axis in standard position) are in the second table of 'Budget'.")
    if not native:
        book.para(
            f"4. This task has {f.m} points, more than the {limit} for which the 3m x 3m V_X matrices are "
            "laid out as native formulas: the V_X sheets are omitted and V_A of the factors PQ, S, ET, ER and "
            f"P on 'V_A' are VALUES computed when the workbook was built by {method} "
            f"(cmmwb {__version__}), marked grey with a note; they do not follow edits of the inputs. J, H, "
            "G and the R factor remain formulas.",
            f"5. '{LIVE}' holds the same numbers as formulas of the cmmwb Excel add-in (xlwings user-defined "
            "functions cmm_feature and cmm_feature_va in xlfuncs.udf) over 'Points', the probes and "
            "parameters on 'Inputs' and the weights on 'Local': value, u and u per factor of each parameter "
            "(as on 'Budget'), and per grey factor V_A of the reported parameters and of the paper "
            "parameters (x 1e12) in the cells where 'V_A' has them. In Excel with the add-in they refit and "
            "recompute live; install and use: docs/addins.md of cmmwb (save as .xlsm, reference "
            "xlwings, Import Functions; 'xlwings.conf' already names the module). In LibreOffice, or in "
            f"Excel without the add-in, '{LIVE}' shows #NAME?: by design, no other cell refers to it, so "
            "every result stays visible.")
    explain_inputs(book)
    book.gap()
    book.para("Conventions", bold=True)
    book.para(*ERRATA, *task.notes)


# -- the fit (values) -------------------------------------------------------------------------

def _write_fit(book: Book, f, task: Task) -> dict:
    ws = book.sheet("Fit")
    book.text(ws, 1, 1, f"Fitted {_label(f)}: values computed by xlfuncs.features.fit "
                        f"(Gauss-Newton, {f.iterations} iterations) -- not formulas",
              font=None)
    note = ("Computed by cmmwb's core (xlfuncs.features.fit): the least-squares orthogonal "
            "distance fit of Forbes 2022 eq. (7)/(11) by Gauss-Newton. An iteration has no native "
            "formula; the 'H' sheet shows the next Gauss-Newton step, 0 at the solution.")
    book.text(ws, 3, 1, "origin_mm")
    for a in range(3):
        book.text(ws, 2, 2 + a, "xyz"[a])
        c = book.number(ws, 3, 2 + a, f.origin_mm[a], fmt=FMT, computed=True)
    book.note(ws.cell(row=3, column=2), note + " Origin of the solution frame: the locating "
                                               "point (centre for spheres and circles).")
    book.define("fit_origin", Block("Fit", 3, 2, 1, 3).ref)
    book.text(ws, 4, 1, "R: columns = frame x, y, z axes (z = element axis / normal)")
    for a in range(3):
        book.text(ws, 5 + a, 1, f"R row {'xyz'[a]}")
        for b in range(3):
            book.number(ws, 5 + a, 2 + b, f.R[a, b], fmt=FMT, computed=True)
    book.note(ws.cell(row=5, column=2), note + " Rotation of the solution frame: local "
                                               "coordinates P = (X - origin) R.")
    book.define("fit_R", Block("Fit", 5, 2, 3, 3).ref)
    refs = {"origin": Block("Fit", 3, 2, 1, 3), "R": Block("Fit", 5, 2, 3, 3)}
    r = 9
    for name, value, label in (("fit_r0", f.shape[0] if f.shape else None, "r0_mm"),
                               ("fit_phi", f.shape[1] if len(f.shape) > 1 else None, "phi_rad")):
        if value is None:
            continue
        book.text(ws, r, 1, label)
        book.number(ws, r, 2, value, fmt=FMT, computed=True)
        book.note(ws.cell(row=r, column=2), note)
        book.define(name, cell(r, 2, "Fit"))
        refs[name] = cell(r, 2, "Fit")
        r += 1
    r += 1
    for label, value in (("element", _label(f)), ("points m", f.m),
                         ("residuals per point k", f.k),
                         ("iterations", f.iterations),
                         ("rms residual (mm)", f.rms_mm),
                         ("circle plane", f.circle_plane or "")):
        if label == "circle plane" and not f.circle_plane:
            continue
        book.text(ws, r, 1, label)
        if isinstance(value, str):
            book.text(ws, r, 2, value)
        else:  # numbers as numbers: the rms of an exact fit is rounding noise, not text to compare
            book.number(ws, r, 2, value, fmt="0" if isinstance(value, int) else FMT_SCI, computed=True)
        r += 1
    ws.column_dimensions["A"].width = 28
    for c in "BCD":
        ws.column_dimensions[c].width = 18
    return refs


# -- local coordinates, Jacobian ----------------------------------------------------------------

def _write_local(book: Book, f, task: Task, X: Block) -> dict:
    ws = book.sheet("Local")
    cols = ["id", "w", "x_loc_mm", "y_loc_mm", "z_loc_mm", "rho_mm", "c", "s"]
    notes = ["point id (Points)", "weight w_i of Forbes 2022 eq. (11) (W = diag(w_i^2), eq. (12))",
             "P = (X - origin) R: the points in the frame in which the element is in standard "
             "position (axis along z, locating point at the origin)", None, None,
             "distance from the frame z axis (sphere: from the centre)", "cos(theta) = x/rho",
             "sin(theta) = y/rho"]
    book.header(ws, 1, 1, cols, notes)
    m = f.m
    for i in range(m):
        book.text(ws, 2 + i, 1, task.cloud.labels[i])
        book.number(ws, 2 + i, 2, f.weights[i], fmt="General")
    P = Block("Local", 2, 3, m, 3)
    book.array(P, f"=MMULT({X.ref}-fit_origin,fit_R)", fmt=FMT,
               note="P = (X - origin) R, one row per point (Forbes 2022 section 3: the data "
                    "transformed so that the element is in standard position)")
    needs_rho = f.kind not in ("plane", "line")
    for i in range(m):
        r = 2 + i
        x, y, z = (cell(r, 3 + a) for a in range(3))
        if needs_rho:
            rho = f"SQRT({x}^2+{y}^2+{z}^2)" if f.kind == "sphere" else f"SQRT({x}^2+{y}^2)"
            book.formula(ws, r, 6, f"={rho}", fmt=FMT)
            book.formula(ws, r, 7, f"={x}/{cell(r, 6)}", fmt=FMT)
            book.formula(ws, r, 8, f"={y}/{cell(r, 6)}", fmt=FMT)
    ws.freeze_panes = "C2"
    return {"P": P, "w": Block("Local", 2, 2, m, 1)}


def _residual_rows(kind: str, x, y, z, rho, c, s):
    """(residual label, d formula, J formulas, local normal formulas) per residual of a point.
    Numbers are returned as floats (written as constants), formulas as strings."""
    if kind == "plane":
        return [("d", z, [-1.0, f"-{y}", x], [0.0, 0.0, 1.0])]
    if kind == "line":
        return [("d_x", x, [-1.0, 0.0, 0.0, f"-{z}"], [1.0, 0.0, 0.0]),
                ("d_y", y, [0.0, -1.0, z, 0.0], [0.0, 1.0, 0.0])]
    if kind == "sphere":
        nx, ny, nz = f"{x}/{rho}", f"{y}/{rho}", f"{z}/{rho}"
        return [("d", f"{rho}-fit_r0", [f"-({nx})", f"-({ny})", f"-({nz})", -1.0], [nx, ny, nz])]
    if kind == "circle":
        return [("d", f"{rho}-fit_r0", [f"-{c}", f"-{s}", -1.0], [c, s, 0.0])]
    if kind == "cylinder":
        return [("d", f"{rho}-fit_r0", [f"-{c}", f"-{s}", f"{z}*{s}", f"-({z}*{c})", -1.0],
                 [c, s, 0.0])]
    if kind == "circle_space":
        return [("d_axial", z, [0.0, 0.0, -1.0, f"-{y}", x, 0.0], [0.0, 0.0, 1.0]),
                ("d_radial", f"{rho}-fit_r0",
                 [f"-{c}", f"-{s}", 0.0, f"{z}*{s}", f"-({z}*{c})", -1.0], [c, s, 0.0])]
    if kind == "cone":
        cp, sp = "COS(fit_phi)", "SIN(fit_phi)"
        dC = f"({rho}-fit_r0)"
        return [("d", f"{cp}*{dC}+{sp}*{z}",
                 [f"-({cp}*{c})", f"-({cp}*{s})", f"{cp}*{z}*{s}-{sp}*{y}",
                  f"{sp}*{x}-{cp}*{z}*{c}", f"-{cp}", f"{cp}*{z}-{sp}*{dC}"],
                 [f"{cp}*{c}", f"{cp}*{s}", sp])]
    raise ValueError(kind)


J_NOTES = {
    "plane": "Forbes 2022 section 6: d = z (standard position), J = (-1, -y, x) for (z_A, rot_x, rot_y)",
    "line": "line in space: offsets d_x = x, d_y = y from the z axis; J rows (-1, 0, 0, -z), (0, -1, z, 0)",
    "sphere": "Forbes 2022 section 5: d = r_i - r0, J = -[n_i^T, 1]",
    "circle": "Forbes 2022 section 4: d = r_i - r0, J = -[n_i^T, 1]",
    "cylinder": "Forbes 2022 section 7: d = rho - r0, J = -[cos, sin, -z sin, z cos, 1]",
    "circle_space": "circle in space: axial residual z (J = (0,0,-1,-y,x,0)) and radial residual "
                    "rho - r0 (J = -[cos, sin, 0, -z sin, z cos, 1])",
    "cone": "Forbes 2022 section 8, eq. (26): d = cos(phi) d_C + sin(phi) d_P; J = [-cos(phi) cos, "
            "-cos(phi) sin, w sin, -w cos, -cos(phi), z/cos(phi)] on the cone, w = z/cos(phi) - r0 sin(phi)",
}


def _put(book: Book, ws, r: int, c: int, v, fmt=FMT):
    if isinstance(v, float):
        ws.cell(row=r, column=c).value = v
    else:
        book.formula(ws, r, c, f"={v}", fmt=fmt)


def _write_jacobian(book: Book, f, local: dict, labels) -> dict:
    ws = book.sheet("J")
    n, k, m = f.n, f.k, f.m
    cols = ["point", "residual", "w2", "d_mm"] + [f"J_{nm}" for nm in f.local_names] + \
           ["nl_x", "nl_y", "nl_z", "n_x", "n_y", "n_z"]
    notes = [None, None, "W = diag(w_i^2), Forbes 2022 eq. (12)", "signed orthogonal distance "
             "(residual) at the fitted values, eq. (7)"] + \
            [J_NOTES[f.kind]] + [None] * (n - 1) + \
            ["unit normal of the residual in the frame"] + [None] * 2 + \
            ["normal in machine coordinates, n = R nl: the columns of N in G_A|X = G_A|D N^T (eq. (8))"] + [None] * 2
    book.header(ws, 1, 1, cols, notes)
    c0 = 5
    for i in range(m):
        lr = 2 + i
        x, y, z = (cell(lr, 3 + a, "Local") for a in range(3))
        rho, c, s = (cell(lr, 6 + a, "Local") for a in range(3))
        for j, (lab, d, Jrow, nl) in enumerate(_residual_rows(f.kind, x, y, z, rho, c, s)):
            r = 2 + k * i + j
            book.text(ws, r, 1, labels[i])
            book.text(ws, r, 2, lab)
            book.formula(ws, r, 3, f"={cell(lr, 2, 'Local')}^2", fmt="General")
            _put(book, ws, r, 4, d, fmt=SMALL)
            for p, v in enumerate(Jrow):
                _put(book, ws, r, c0 + p, v)
            for a, v in enumerate(nl):
                _put(book, ws, r, c0 + n + a, v)
            nlb = Block("J", r, c0 + n, 1, 3)
            for a in range(3):
                book.formula(ws, r, c0 + n + 3 + a,
                             f"=SUMPRODUCT({Block('Fit', 5 + a, 2, 1, 3).ref},{nlb.local})")
    ws.freeze_panes = "C2"
    km = k * m
    return {"J": Block("J", 2, c0, km, n), "w2": Block("J", 2, 3, km, 1),
            "d": Block("J", 2, 4, km, 1), "N": Block("J", 2, c0 + n + 3, km, 3)}


# -- H, G ---------------------------------------------------------------------------------------

def _matrix_labels(book, ws, r, c, rows, cols):
    for q, lab in enumerate(cols):
        book.text(ws, r - 1, c + q, lab)
    for q, lab in enumerate(rows):
        book.text(ws, r + q, c - 1, lab)


def _write_H(book: Book, f, jac: dict, labels) -> dict:
    ws = book.sheet("H")
    n = f.n
    names = list(f.local_names)
    J, w2, d = jac["J"].ref, jac["w2"].ref, jac["d"].ref
    book.text(ws, 1, 1, "H = J^T W J (Forbes 2022 eqs. (10), (12))")
    H = Block("H", 3, 2, n, n)
    _matrix_labels(book, ws, 3, 2, names, names)
    book.array(H, f"=MMULT(TRANSPOSE({J}),{J}*{w2})", fmt=SMALL,
               note="H = J^T W J, W = diag(w_i^2) (eq. (12)); for V_X = sigma_R^2 I and w = 1, "
                    "V_A = sigma_R^2 H^-1 (eq. (10))")
    r = 3 + n + 2
    book.text(ws, r - 2, 1, "H^-1 = MINVERSE(H)")
    Hi = Block("H", r, 2, n, n)
    _matrix_labels(book, ws, r, 2, names, names)
    book.array(Hi, f"=MINVERSE({H.ref})", fmt=SMALL, note="(J^T W J)^-1")
    step = gn_step_block(n)
    r2 = step.row
    assert r2 == r + n + 2
    book.text(ws, r2 - 1, 1, "Gauss-Newton step from the fitted values: delta = -(J^T W J)^-1 "
                             "J^T W d (0 at the least-squares solution)")
    for q, lab in enumerate(names):
        book.text(ws, r2 + q, 1, lab)
    book.array(step, f"=-MMULT({Hi.ref},MMULT(TRANSPOSE({J}*{w2}),{d}))", fmt=SMALL,
               note="Optimality check (Forbes 2022 section 3: J^T d = 0 at the solution). A "
                    "non-zero step means the points or weights changed since the fit.")
    ws.column_dimensions["A"].width = 14
    # G_A|D^T
    wg = book.sheet("G_A_D")
    km = f.k * f.m
    book.text(wg, 1, 1, "G_A|D^T = -W J (J^T W J)^-1: row = residual, column = parameter "
                        "(Forbes 2022 eq. (12), transposed)")
    GDt = Block("G_A_D", 3, 2, km, n)
    for q, lab in enumerate(names):
        book.text(wg, 2, 2 + q, lab)
    for q in range(km):
        i, j = divmod(q, f.k)
        book.text(wg, 3 + q, 1, labels[i] + (f" ({j + 1})" if f.k > 1 else ""))
    book.array(GDt, f"=-MMULT({J}*{w2},{Hi.ref})", fmt=SMALL,
               note="G_A|D = -(J^T W J)^-1 J^T W (eq. (12)); shown transposed")
    wg.freeze_panes = "B3"
    return {"H": H, "Hinv": Hi, "GDt": GDt, "step": step}


def _write_G(book: Book, f, jac: dict, hs: dict) -> Block:
    ws = book.sheet("G_A_X")
    n, k, m = f.n, f.k, f.m
    book.text(ws, 1, 1, "G_A|X^T = N G_A|D^T: row = coordinate x1, y1, z1, x2, ..., column = "
                        "parameter (Forbes 2022 eq. (8), transposed; unit: parameter unit per mm)")
    for q, lab in enumerate(f.local_names):
        book.text(ws, 2, 2 + q, lab)
    GDt, N = hs["GDt"], jac["N"]
    for i in range(m):
        for a in range(3):
            r = 3 + 3 * i + a
            book.text(ws, r, 1, f"{'xyz'[a]}{i + 1}")
            for p in range(n):
                terms = [f"{GDt.cell(k * i + j, p)}*{N.cell(k * i + j, a)}" for j in range(k)]
                book.formula(ws, r, 2 + p, "=" + "+".join(terms), fmt=SMALL)
    book.note(ws.cell(row=3, column=2), "G_A|X(p, 3i+a) = sum over the residuals r of point i of "
                                        "G_A|D(p, r) n_r(a): a shift of x_i along the fitted normal "
                                        "changes the residual by the same amount (eq. (8))")
    ws.freeze_panes = "B3"
    return Block("G_A_X", 3, 2, 3 * m, n)


# -- V_A per factor -----------------------------------------------------------------------------

def _T_entries(f) -> dict[tuple[int, int], str | float]:
    """T = d(reported)/d(local) as formulas of the frame rotation R (see xlfuncs.features)."""
    g = len(f.names)
    out: dict[tuple[int, int], str | float] = {}
    if f.kind in ("sphere", "circle"):
        for i in range(g):
            out[(i, i)] = 1.0
        return out
    ix = {nm: j for j, nm in enumerate(f.local_names)}

    def R(a, b):
        return cell(5 + a, 2 + b, "Fit")

    for b, ax in enumerate(("x_A_mm", "y_A_mm", "z_A_mm")):
        if ax in ix:
            for a in range(3):
                out[(a, ix[ax])] = R(a, b)
    for a in range(3):
        out[(3 + a, ix["rot_y_rad"])] = R(a, 0)
        out[(3 + a, ix["rot_x_rad"])] = f"-{R(a, 1)}"
    for extra in ("r0_mm", "phi_rad"):
        if extra in ix:
            out[(f.names.index(extra), ix[extra])] = 1.0
    return out


def v_a_layout(n: int, g: int) -> dict[str, tuple[Block, Block]]:
    """Where 'V_A' holds each factor's (paper, reported) covariance blocks."""
    first, span = 3 + g + 3, max(n, g) + 3
    return {fac: (Block("V_A", first + q * span, 2, n, n),
                  Block("V_A", first + q * span, 2 + n + 2, g, g))
            for q, fac in enumerate((*pc.FACTORS, "total"))}


def gn_step_block(n: int) -> Block:
    """The Gauss-Newton step on 'H' (n x 1)."""
    return Block("H", 3 + n + 2 + n + 2, 2, n, 1)


def _write_V_A(book: Book, f, unc, G: Block, V, method: str) -> dict:
    ws = book.sheet("V_A")
    n, g = f.n, len(f.names)
    names, lnames = list(f.names), list(f.local_names)
    book.text(ws, 1, 1, "T: reported parameters <- paper parameters (linear map at the fit; "
                        "reported covariance = T V_A T^T)")
    T = Block("V_A", 3, 2, g, n)
    _matrix_labels(book, ws, 3, 2, names, lnames)
    ent = _T_entries(f)
    for a in range(g):
        for b in range(n):
            v = ent.get((a, b), 0.0)
            if isinstance(v, float):
                ws.cell(row=3 + a, column=2 + b).value = v
            else:
                book.formula(ws, 3 + a, 2 + b, f"={v}", fmt=FMT)
    book.note(ws.cell(row=3, column=2),
              "Locating point: R (dx_A, dy_A, dz_A); direction: R (rot_y, -rot_x, 0); r0, phi "
              "unchanged (xlfuncs.features, reported parameters)")
    out_local, out_glob, grey = {}, {}, {}
    Gt = G.ref
    for fac, (L, Gl) in v_a_layout(n, g).items():
        top = L.row
        book.text(ws, top - 2, 1, f"{fac}: V_A,{fac} paper parameters (left), reported T V_A T^T (right)"
                  if fac != "total" else "total: sum of the six contributions (Forbes 2025 section 5.6)")
        _matrix_labels(book, ws, top, 2, lnames, lnames)
        _matrix_labels(book, ws, top, 2 + n + 2, names, names)
        if fac == "total":
            book.array(L, "=" + "+".join(out_local[x].ref for x in pc.FACTORS), fmt=SMALL,
                       note="V_A = sum over the factors (Forbes 2025 section 5.6)")
        elif V is not None:
            book.array(L, f"=MMULT(MMULT(TRANSPOSE({Gt}),{V[fac].ref}),{Gt})*0.000001", fmt=SMALL,
                       note=f"V_A,{fac} = G_A|X V_{fac} G_A|X^T (µm² -> mm²: x 1e-6), "
                            "Forbes 2025 section 5.6")
        elif fac == "R":
            book.array(L, f"=sigma_R_um^2*MMULT(TRANSPOSE({Gt}),{Gt})*0.000001", fmt=SMALL,
                       note="V_A,R = sigma_R^2 G_A|X G_A|X^T (V_R = sigma_R^2 I, Forbes 2025 eq. (8))")
        else:
            # The core's values, scaled by 1e12 (mm^2 -> nm^2): the `formulas` engine rounds
            # numeric constants to 15 decimal places, which would cut 1e-8 mm^2 to 7 digits.
            Vv = unc.V_local[fac] * VALUE_SCALE
            vb = Block("V_A", top, 2 + n + 2 + g + 2, n, n)
            book.text(ws, top - 1, vb.column, f"V_A,{fac} x 1e12 (values from xlfuncs)")
            for a in range(n):
                for b in range(n):
                    book.number(ws, top + a, vb.column + b, Vv[a, b], fmt="0.000000E+00",
                                computed=True)
            book.note(ws.cell(row=top, column=vb.column),
                      f"VALUES, not formulas: V_A,{fac} = G_A|X V_{fac} G_A|X^T computed at build "
                      f"time by {method} (cmmwb {__version__}); V_X "
                      f"({3 * f.m} x {3 * f.m}) is too large for native formulas. In units of 1e-12 "
                      f"(mm^2 -> nm^2, rad^2 -> (µrad)^2), scaled back on the left. Live: the same "
                      f"cells on sheet {LIVE} (add-in function cmm_feature_va)")
            grey[fac] = vb
            book.array(L, f"={vb.ref}*{1 / VALUE_SCALE:.0E}", fmt=SMALL,
                       note=f"V_A,{fac}: the grey values on the right (computed by xlfuncs, "
                            "not formulas) x 1e-12")
        book.array(Gl, f"=MMULT(MMULT({T.ref},{L.ref}),TRANSPOSE({T.ref}))", fmt=SMALL,
                   note="T V_A T^T: covariance of the reported parameters")
        out_local[fac], out_glob[fac] = L, Gl
    return {"local": out_local, "global": out_glob, "T": T, "grey": grey}


#: display scale of an uncertainty: mm -> µm, rad -> µrad, a unit-vector component -> 1e-6
_U_DISPLAY = {"mm": (1e3, "µm"), "rad": (1e6, "µrad"), "1": (1e6, "1e-6")}

#: columns of the 'Budget' tables: u and u per factor start in column U_COLUMN, in u_unit
U_COLUMN = 5


def u_display(name: str) -> tuple[float, str]:
    """The display scale and unit of the uncertainty of parameter ``name`` on 'Budget'."""
    return _U_DISPLAY[_unit(name)]


def _budget_table(book: Book, ws, top: int, names, values, blocks: dict) -> list[tuple[str, int]]:
    """One budget table from row ``top`` (header): parameter, value, unit, u_unit, u and u per
    factor, the uncertainties in µm / µrad (1e-6 for a unit-vector component) from the diagonal
    of the V_A blocks ``blocks`` (which are in the parameters' units squared)."""
    cols = ["parameter", with_units("value", [_unit(n) for n in names]), "unit", "u_unit",
            *[with_units(u, [u_display(n)[1] for n in names]) for u in
              ("u", *[f"u_{fac}" for fac in pc.FACTORS])]]
    notes = [None, "fitted value, in the unit of column 'unit'", None,
             "unit of u and u_R ... u_P in this row: µm for a length, µrad for an angle, 1e-6 for a "
             "unit-vector component",
             "u = sqrt(diag V_A), in u_unit; u^2 = sum of u_f^2 (Forbes 2025 section 5.6)"] + \
            [f"u_{fac}: sqrt of the diagonal of V_A,{fac}, in u_unit" for fac in pc.FACTORS]
    book.header(ws, top, 1, cols, notes)
    rows = []
    for p, name in enumerate(names):
        r = top + 1 + p
        scale, unit = u_display(name)
        book.text(ws, r, 1, name)
        if isinstance(values[p], float):
            ws.cell(row=r, column=2).value = values[p]
            ws.cell(row=r, column=2).number_format = FMT_VALUE
        else:
            book.formula(ws, r, 2, f"={values[p]}", fmt=FMT_VALUE)
        book.text(ws, r, 3, _unit(name))
        book.text(ws, r, 4, unit)
        for q, fac in enumerate(("total", *pc.FACTORS)):
            book.formula(ws, r, U_COLUMN + q, f"=SQRT(MAX(0,{blocks[fac].cell(p, p)}))*{scale:g}", fmt="0.0000")
        rows.append((name, r))
    return rows


#: fitted values as a person reads them: 1 nm for lengths, 1e-6 rad / 1e-6 for angles and
#: unit-vector components (the cells keep full precision)
FMT_VALUE = "0.000000"
#: how the units of one table's rows are written in its header: one unit as a suffix (u_um),
#: several as "u (µm, 1e-6)", the row's unit being in column 'unit' / 'u_unit'
_SUFFIX = {"mm": "mm", "µm": "um", "rad": "rad", "µrad": "urad"}


def with_units(label: str, units) -> str:
    """``label`` with the units of the rows of its column: ``u_um`` when all rows share one unit
    that has a key suffix, otherwise ``u (µm, 1e-6)`` (a unit-vector component's unit is 1)."""
    units = list(dict.fromkeys(units))
    if len(units) == 1 and units[0] in _SUFFIX:
        return f"{label}_{_SUFFIX[units[0]]}"
    return f"{label} ({', '.join(units)})"


def _write_budget(book: Book, f, va: dict, fitref: dict) -> list[tuple[str, int]]:
    ws = book.sheet("Budget")
    rows = _budget_table(book, ws, 1, f.names, _value_refs(f), va["global"])
    r0 = 2 + len(f.names) + 2
    book.text(ws, r0, 1, "Paper parameters (Forbes 2022, element in standard position in the "
                         "solution frame on 'Fit'); values are offsets from the fit, 0 at the solution",
              font=None)
    values = []
    for p, name in enumerate(f.local_names):
        if name == "r0_mm" and "fit_r0" in fitref and f.kind not in ("sphere", "circle"):
            values.append("fit_r0")
        elif name == "phi_rad":
            values.append("fit_phi")
        elif f.kind in ("sphere", "circle"):
            values.append(_value_refs(f)[p])
        else:
            values.append(0.0)
    paper = _budget_table(book, ws, r0 + 1, f.local_names, values, va["local"])
    _factor_chart(book, ws, paper[-1][1] + 2, rows)
    ws.column_dimensions["A"].width = 14
    ws.freeze_panes = "B2"
    return rows


def _factor_chart(book: Book, ws, anchor: int, rows: list[tuple[str, int]]) -> None:
    """A chart of u per factor of the length parameters in µm (Forbes 2025 section 5.6), on its
    own printed page."""
    from openpyxl.chart import Reference

    length_rows = [r for name, r in rows if _unit(name) == "mm"]
    if not length_rows:
        return
    first, last = U_COLUMN + 1, U_COLUMN + len(pc.FACTORS)
    book.print_setup(ws, row_breaks=[anchor - 1])   # the chart on its own printed page
    # the chart's categories in words, in the row above it (the headers carry units)
    book.text(ws, anchor, 1, "influence factor (chart axis)")
    for q, fac in enumerate(pc.FACTORS):
        book.text(ws, anchor, first + q, FACTOR_WORDS[fac])
    book.bars(ws, f"A{anchor + 1}", "u per influence factor of the length parameters (µm), "
              "Forbes 2025 section 5.6", "u / µm",
              Reference(ws, min_col=first, max_col=last, min_row=anchor),
              [(ws.cell(row=r, column=1).value, Reference(ws, min_col=first, max_col=last,
                                                          min_row=r, max_row=r))
               for r in length_rows], horizontal=False, width=18, height=8, page=book)


#: the influence factors of Forbes 2025 (Table 3) as the chart names them: "ET location errors"
FACTOR_WORDS = {fac: f"{fac} {title.split(',')[0]}" for fac, title in FACTOR_TITLES.items()}


def _unit(name: str) -> str:
    return "mm" if name.endswith("_mm") else "rad" if name.endswith("_rad") else "1"


# -- the same numbers as Excel add-in formulas (above the native limit) -----------------------------

#: 'Live_addin' columns of the fit options the add-in formulas read (rows 3, 4)
LIVE_OPTION_COLUMN = 11


def _write_live(book: Book, task: Task, f, va: dict, probe_rows: dict) -> None:
    """The sheet ``Live_addin``: ``cmm_feature`` (rows 3.., the parameters of 'Budget') and, per
    factor whose V_A is a grey value block on 'V_A', ``cmm_feature_va`` at the cells of the
    reported covariance T V_A,f T^T and T^T V_A,f T x 1e12 at the cells of the grey values (T
    has orthonormal columns: T^T T = I, so this is V_A,f of the paper parameters).  The add-in
    refits the points with the task's options: the element, circle_plane, the weights on
    'Local', axis_hint and reference_mm (cells on this sheet).  LibreOffice shows #NAME? here
    (no add-in); no other cell refers to this sheet.  Protected like every sheet with formulas
    (no password)."""
    ws = book.sheet(LIVE)
    m, n, g = f.m, f.n, len(f.names)
    points, probes, params = addin_ranges(m, probe_rows)
    weights = block(2, 2, m, 1, "Local")
    circle_plane = (task.circle_plane or "space") if task.element == "circle" else ""
    book.text(ws, 1, 1, "The numbers of 'Budget' and the grey values of 'V_A' as formulas of the cmmwb "
                        "Excel add-in (xlfuncs.udf, docs/addins.md): live in Excel with the add-in, "
                        "#NAME? elsewhere (no other cell refers to this sheet)", font=None)
    # the fit options of the task (the add-in refits the points with them)
    oc = LIVE_OPTION_COLUMN
    book.header(ws, 2, oc, ["fit option", "x", "y", "z"],
                ["[feature] keys of the task file as built, read by the add-in formulas of this "
                 "sheet (empty: the default); change them in the task file", None, None, None])
    for r, (key, v) in enumerate((("axis_hint", task.axis_hint), ("reference_mm", task.reference_mm)),
                                 start=3):
        book.text(ws, r, oc, key)
        if v is not None:
            for a in range(3):
                ws.cell(row=r, column=oc + 1 + a).value = float(v[a])
    options = f'"{circle_plane}",{weights},{block(3, oc + 1, 1, 3)},{block(4, oc + 1, 1, 3)}'
    head = f'"{task.element}",{points},{probes},{params}'
    cols = ["parameter", "value", "u", *(f"u_{fac}" for fac in pc.FACTORS)]
    book.header(ws, 2, 1, cols,
                ["cmm_feature(element, points, probes, params, circle_plane, weights, axis_hint, "
                 "reference_mm): each reported parameter with its value, u and u per factor, the "
                 "rows of 'Budget' with u in the parameter's unit (as on 'Results'), computed live by the Excel add-in "
                 "(Forbes 2022 fit; Forbes 2025 section 5.6)"] + [None] * (len(cols) - 1))
    book.array(Block(LIVE, 3, 1, g, len(cols)), f"=cmm_feature({head},{options})", fmt=None)
    names, lnames = list(f.names), list(f.local_names)
    T = va["T"].ref
    for fac, vb in va["grey"].items():
        Gl = va["global"][fac]
        top = Gl.row
        book.text(ws, top - 2, 1, f"{fac}: V_A,{fac} of the reported parameters = cmm_feature_va(..., "
                                  f"\"{fac}\", ...) at the cells of T V_A,{fac} T^T on 'V_A' (left); "
                                  f"T^T V_A,{fac} T x 1e12 (paper parameters) at the cells of the grey "
                                  "values (right)")
        _matrix_labels(book, ws, top, Gl.column, names, names)
        _matrix_labels(book, ws, top, vb.column, lnames, lnames)
        live = Block(LIVE, top, Gl.column, g, g)
        book.array(live, f'=cmm_feature_va({head},"{fac}",{options})', fmt=SMALL,
                   note=f"V_A,{fac} = G_A|X V_{fac} G_A|X^T of the reported parameters (their units "
                        "squared), computed live by the Excel add-in in row blocks (xlfuncs.blocked)")
        book.array(Block(LIVE, top, vb.column, n, n),
                   f"=MMULT(TRANSPOSE({T}),MMULT({live.local},{T}))*{VALUE_SCALE:.0E}",
                   fmt="0.000000E+00",
                   note=f"T^T V_A,{fac} T x 1e12: V_A,{fac} of the paper parameters in the frame on "
                        "'Fit' (T^T T = I), the grey values of 'V_A' computed live")
    ws.freeze_panes = "B3"


def _value_refs(f) -> list[str]:
    o = [cell(3, 2 + a, "Fit") for a in range(3)]
    if f.kind == "sphere":
        return [*o, "fit_r0"]
    if f.kind == "circle":
        from xlfuncs.features import CIRCLE_PLANES

        cols, _ = CIRCLE_PLANES[f.circle_plane]
        return [o[cols[0]], o[cols[1]], "fit_r0"]
    v = [cell(5 + a, 4, "Fit") for a in range(3)]
    out = [*o, *v]
    if f.kind in ("cylinder", "circle_space", "cone"):
        out.append("fit_r0")
    if f.kind == "cone":
        out.append("fit_phi")
    return out


# -- planning (Tables 1-8) --------------------------------------------------------------------

_ARC = [("alpha_rad", "RADIANS({arc_deg})/2"),
        ("E_c", "SIN({alpha_rad})/{alpha_rad}"),
        ("E_c2", "0.5+SIN(2*{alpha_rad})/(4*{alpha_rad})"),
        ("E_s2", "0.5-SIN(2*{alpha_rad})/(4*{alpha_rad})")]


def planning_templates(pattern: str, space: bool):
    """Helper cells and the upper triangle of H (Excel formula templates with {key}
    placeholders) of the analytic approximations in xlfuncs.partial."""
    if pattern == "circle_arc" and not space:
        return 3, _ARC, {(0, 0): "{E_c2}", (0, 2): "{E_c}", (1, 1): "{E_s2}", (2, 2): 1.0}
    if pattern == "circle_arc":
        return 6, _ARC, {(0, 0): "{E_c2}", (0, 5): "{E_c}", (1, 1): "{E_s2}", (5, 5): 1.0,
                         (2, 2): 1.0, (2, 4): "-({r0_mm}*{E_c})", (3, 3): "{r0_mm}^2*{E_s2}",
                         (4, 4): "{r0_mm}^2*{E_c2}"}
    if pattern in ("sphere_cap", "sphere_full"):
        g = "{gamma_deg}" if pattern == "sphere_cap" else "180"
        helpers = [("gamma_rad", f"RADIANS({g})"), ("cg", "COS({gamma_rad})"),
                   ("h11", "(2/3-{cg}+{cg}^3/3)/(2*(1-{cg}))"),
                   ("h33", "(1-{cg}^3)/(3*(1-{cg}))"),
                   ("h34", "(1-COS(2*{gamma_rad}))/(4*(1-{cg}))")]
        return 4, helpers, {(0, 0): "{h11}", (1, 1): "{h11}", (2, 2): "{h33}", (2, 3): "{h34}",
                            (3, 3): 1.0}
    if pattern == "sphere_band":
        helpers = [("beta_rad", "RADIANS({beta_deg})"), ("sb2", "SIN({beta_rad})^2")]
        return 4, helpers, {(0, 0): "(1-{sb2}/3)/2", (1, 1): "(1-{sb2}/3)/2",
                            (2, 2): "{sb2}/3", (3, 3): 1.0}
    if pattern == "sphere_segment":
        helpers = [("alpha_rad", "RADIANS({arc_deg})/2"),
                   ("h11", "({alpha_rad}+SIN(2*{alpha_rad})/2)/(3*{alpha_rad})"),
                   ("h22", "({alpha_rad}-SIN(2*{alpha_rad})/2)/(3*{alpha_rad})"),
                   ("h14", "PI()*SIN({alpha_rad})/(4*{alpha_rad})")]
        return 4, helpers, {(0, 0): "{h11}", (0, 3): "{h14}", (1, 1): "{h22}",
                            (2, 2): "1/3", (3, 3): 1.0}
    if pattern == "sphere_patch":
        helpers = [("t1", "RADIANS({theta_from_deg})"), ("t2", "RADIANS({theta_to_deg})"),
                   ("p1", "RADIANS({phi_from_deg})"), ("p2", "RADIANS({phi_to_deg})"),
                   ("Ic2", "({t2}-{t1})/2+(SIN(2*{t2})-SIN(2*{t1}))/4"),
                   ("Is2", "({t2}-{t1})/2-(SIN(2*{t2})-SIN(2*{t1}))/4"),
                   ("Isc", "(SIN({t2})^2-SIN({t1})^2)/2"),
                   ("Ic", "SIN({t2})-SIN({t1})"), ("Is", "COS({t1})-COS({t2})"),
                   ("I1", "{t2}-{t1}"),
                   ("c3", "SIN({p2})-SIN({p2})^3/3-SIN({p1})+SIN({p1})^3/3"),
                   ("sc2", "(COS({p1})^3-COS({p2})^3)/3"),
                   ("c2", "({p2}-{p1})/2+(SIN(2*{p2})-SIN(2*{p1}))/4"),
                   ("s2c", "(SIN({p2})^3-SIN({p1})^3)/3"),
                   ("sc", "(SIN({p2})^2-SIN({p1})^2)/2"),
                   ("c1", "SIN({p2})-SIN({p1})"), ("A", "{I1}*{c1}")]
        return 4, helpers, {(0, 0): "{Ic2}*{c3}/{A}", (0, 1): "{Isc}*{c3}/{A}",
                            (0, 2): "{Ic}*{sc2}/{A}", (0, 3): "{Ic}*{c2}/{A}",
                            (1, 1): "{Is2}*{c3}/{A}", (1, 2): "{Is}*{sc2}/{A}",
                            (1, 3): "{Is}*{c2}/{A}", (2, 2): "{I1}*{s2c}/{A}",
                            (2, 3): "{I1}*{sc}/{A}", (3, 3): 1.0}
    if pattern == "plane_rectangle":
        return 3, [], {(0, 0): 1.0, (1, 1): "{half_width_y_mm}^2/3",
                       (2, 2): "{half_width_x_mm}^2/3"}
    if pattern == "line_segment":
        return 4, [], {(0, 0): 1.0, (1, 1): 1.0, (2, 2): "{half_length_mm}^2/3",
                       (3, 3): "{half_length_mm}^2/3"}
    if pattern == "cylinder_patch":
        return 5, _ARC, {(0, 0): "{E_c2}", (0, 4): "{E_c}", (1, 1): "{E_s2}",
                         (2, 2): "{half_height_mm}^2/3*{E_s2}",
                         (3, 3): "{half_height_mm}^2/3*{E_c2}", (4, 4): 1.0}
    if pattern == "cone_patch":
        helpers = _ARC + [
            ("phi_rad", "RADIANS({phi_deg})"), ("cp", "COS({phi_rad})"), ("sp", "SIN({phi_rad})"),
            ("M1", "-(TAN({phi_rad})*{half_height_mm}^2)/(3*{r0_mm})"),
            ("M2", "{half_height_mm}^2/3"),
            ("Ew", "{M1}/{cp}-{r0_mm}*{sp}"),
            ("Ew2", "{M2}/{cp}^2-2*{r0_mm}*{sp}*{M1}/{cp}+({r0_mm}*{sp})^2"),
            ("Ewz", "{M2}/{cp}-{r0_mm}*{sp}*{M1}")]
        return 6, helpers, {
            (0, 0): "{cp}^2*{E_c2}", (0, 3): "{cp}*{E_c2}*{Ew}", (0, 4): "{cp}^2*{E_c}",
            (0, 5): "-({E_c}*{M1})", (1, 1): "{cp}^2*{E_s2}", (1, 2): "-({cp}*{E_s2}*{Ew})",
            (2, 2): "{E_s2}*{Ew2}", (3, 3): "{E_c2}*{Ew2}", (3, 4): "{cp}*{E_c}*{Ew}",
            (3, 5): "-({E_c}*{Ewz}/{cp})", (4, 4): "{cp}^2", (4, 5): "-({M1})",
            (5, 5): "{M2}/{cp}^2"}
    raise ValueError(pattern)


PLANNING_NOTES = {
    "circle_arc": "H_alpha of Forbes 2022 eq. (16) (Table 1)",
    "sphere_cap": "H_gamma of Forbes 2022 section 5.2 with +cos^3/3 (Table 2)",
    "sphere_full": "whole sphere: H = diag(1/3, 1/3, 1/3, 1) (section 5; Table 8 s|6)",
    "sphere_band": "inverse of V_beta, eq. (19) (Table 3)",
    "sphere_segment": "inverse of V_alpha, eq. (20), with V(4,4) un-inverted (Table 4)",
    "sphere_patch": "H_A/|A| of section 5.1 with the corrected H_A(2,4), H_A(3,3) and H_A(3,4)",
    "plane_rectangle": "H_ab of eq. (22) in the order (z_A, rot_x, rot_y)",
    "line_segment": "line in space: diag(1, 1, a^2/3, a^2/3)",
    "cylinder_patch": "H_a_alpha of section 7 (Table 5)",
    "cone_patch": "H_a_alpha_phi of section 8 in closed form, uniform by area (Tables 6, 7)",
}


def _write_planning(book: Book, task: Task, results: dict) -> None:
    plan = task.planning
    pl = results["planning"]
    ws = book.sheet("Planning")
    n, helpers, Hent = planning_templates(plan.pattern, plan.space)
    names = pl["parameter_names"]
    # named geometry inputs
    book.text(ws, 1, 1, f"Planning without data: {plan.pattern}, {PLANNING_NOTES[plan.pattern]}. "
                        "s = sqrt(diag H^-1), u = sigma_R s / sqrt(m) for V_X = sigma_R^2 I "
                        "(Forbes 2022 eq. (15)); u in the parameter's unit (mm, rad)")
    refs: dict[str, str] = {}
    r = 3
    geo = dict(plan.geometry)
    if "theta_deg" in geo:
        geo["theta_from_deg"], geo["theta_to_deg"] = geo.pop("theta_deg")
    if "phi_range_deg" in geo:
        geo["phi_from_deg"], geo["phi_to_deg"] = geo.pop("phi_range_deg")
    if plan.pattern == "circle_arc" and plan.space:
        geo.setdefault("r0_mm", 1.0)
    inputs = [(k, v) for k, v in geo.items()] + [("m_points", plan.m_points)]
    for key, value in inputs:
        book.text(ws, r, 1, key)
        book.input(ws, r, 2, key, value, lo=0.0 if key != "phi_deg" else None)
        refs[key] = key
        r += 1
    book.text(ws, r, 1, "sigma_R_um")
    book.formula(ws, r, 2, "=sigma_R_um", fmt="General", note="from 'Inputs'")
    r += 2
    sweep = plan.sweep
    rows = plan.values if sweep else [None]
    top = r
    head = [sweep or "row"] + [f"s({nm})" for nm in names] + [f"u({nm})" for nm in names]
    book.header(ws, top, 1, head, [f"{'input: ' + sweep if sweep else None}"] +
                [PLANNING_NOTES[plan.pattern]] + [None] * (n - 1) +
                ["u = sigma_R_um * 0.001 * s / sqrt(m_points) (mm or rad)"] + [None] * (n - 1))
    block_top = top + len(rows) + 3
    span = n + 5
    for q, v in enumerate(rows):
        tr = top + 1 + q
        if sweep:
            book.input(ws, tr, 1, None, v)
            refs_q = dict(refs, **{sweep: cell(tr, 1)})
        else:
            book.text(ws, tr, 1, "1")
            refs_q = dict(refs)
        br = block_top + q * span
        book.text(ws, br, 1, f"row {q + 1}" + (f": {sweep} = {v:g}" if sweep else ""))
        for h, (hname, tmpl) in enumerate(helpers):
            book.text(ws, br + 1, 2 + h, hname)
            book.formula(ws, br + 2, 2 + h, "=" + tmpl.format(**refs_q), fmt=FMT)
            refs_q[hname] = cell(br + 2, 2 + h)
        H = Block("Planning", br + 4, 2, n, n)
        Vb = Block("Planning", br + 4, 2 + n + 2, n, n)
        book.text(ws, br + 3, 2, "H")
        book.text(ws, br + 3, 2 + n + 2, "V = MINVERSE(H)")
        for a in range(n):
            for b in range(n):
                rr, cc = br + 4 + a, 2 + b
                if a > b:
                    book.formula(ws, rr, cc, f"={cell(br + 4 + b, 2 + a)}", fmt=FMT)
                    continue
                t = Hent.get((a, b), 0.0)
                if isinstance(t, float):
                    ws.cell(row=rr, column=cc).value = t
                else:
                    book.formula(ws, rr, cc, "=" + t.format(**refs_q), fmt=FMT)
        book.note(ws.cell(row=br + 4, column=2), PLANNING_NOTES[plan.pattern])
        book.array(Vb, f"=MINVERSE({H.ref})", fmt=FMT)
        for p in range(n):
            book.formula(ws, tr, 2 + p, f"=SQRT({Vb.cell(p, p)})", fmt="0.0000")
            book.formula(ws, tr, 2 + n + p,
                         f"=sigma_R_um*0.001*{cell(tr, 2 + p)}/SQRT(m_points)", fmt=SMALL)
    ws.column_dimensions["A"].width = 18
