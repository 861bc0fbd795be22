


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

``Live_addin``    the same numbers as Excel add-in formulas (``cmmwb.xlfuncs.udf``): ``cmm_feature``
                  (value, u and the six components of each reported parameter) and, per grey
                  factor, ``cmm_feature_va`` (reported V_A,f, at the cells of T V_A,f T^T on
                  'V_A') and T^T V_A,f T x 1e12 at the cells of the grey values.  #NAME? in
                  LibreOffice and without the add-in -- by design, no other cell refers to it.
``xlwings.conf``  ``UDF Modules = cmmwb.xlfuncs.udf`` for this workbook.

This module writes the workbook in that order, its ``Instructions`` and ``Results``; the other
sheets are written by ``fit_sheets`` (Fit ... G_A_X), ``va_sheets`` (V_A, Budget),
``planning_sheet`` and ``live_sheet``.
"""

from __future__ import annotations

from openpyxl.styles import Alignment

from .. import __version__
from ..pointcloud.large_book import LIVE, write_xlwings_conf
from ..pointcloud.vx_sheets import explain_inputs, write_inputs, write_point_cloud_model, write_points
from ..workbook.book import Book, BookAdditions, Formula
from ..workbook.styles import FMT_SCI
from ..workbook.xlref import Block, cell
from .fit_sheets import feature_label, gn_step_block, write_fit, write_G, write_H, write_jacobian, write_local
from .live_sheet import write_live
from .planning_sheet import write_planning
from .task import FIT_CURRENT, FIT_STALE, KIND, STALE_STEP, Task
from .va_sheets import U_COLUMN, u_display, unit_of, write_budget, write_V_A

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


def write_feature_book(task: Task, results: dict, path, fit, method: str, *,
                       native_max_points: int | None = None, additions: BookAdditions | None = None):
    """The workbook of a fitted feature: ``fit`` = (fit, per-factor V_A) of the task and
    ``method`` the name of the core function that computed V_A (both from
    :mod:`generator.feature.job`: ``fitted``, ``propagation_method``)."""
    f, unc = fit
    limit = FEATURE_NATIVE_MAX_POINTS if native_max_points is None else native_max_points
    native = f.m <= limit
    book = Book(KIND, task.name, f"Uncertainty of a least-squares {feature_label(f)} — {task.name}")
    _instructions(book, task, f, native, limit, method)
    if native:
        layout = write_point_cloud_model(book, task.cloud, task.params)
        X, V = layout.X, layout.V
        probe_rows = None
    else:
        _, probe_rows = write_inputs(book, task.params, task.cloud)
        X, _, _ = write_points(book, task.cloud, probe_rows)
        V = None
    fitref = write_fit(book, f, task)
    local = write_local(book, f, task, X)
    labels = task.cloud.labels
    jac = write_jacobian(book, f, local, labels)
    hs = write_H(book, f, jac, labels)
    gx = write_G(book, f, jac, hs)
    va = write_V_A(book, f, unc, gx, V, method)
    rows = write_budget(book, f, va, fitref)
    if task.planning is not None:
        write_planning(book, task, results)
    if not native:
        write_live(book, task, f, va, probe_rows)
    _write_results(book, f, rows, results["feature"])
    if not native:
        write_xlwings_conf(book)
    book.save(path, additions)


#: the Results columns: the contract's parameter, value, u (in the parameter's unit, docs/cli.md),
#: then what a person reads: the unit, u in µm (lengths) or µrad (angles; for a unit-vector
#: component u x 1e6, the tilt of the direction in µrad), and whether the fit is current
RESULT_COLUMNS = ["parameter", "value", "u", "unit", "u_um", "u_urad", "fit_state"]
NOT_APPLICABLE = "—"


def result_row(name: str, budget_row: int, step: Block, fe: dict | None = None) -> list:
    """One Results row of parameter ``name`` (its row on 'Budget'); ``step`` = the Gauss-Newton
    step on 'H'; ``fe`` = the results' ``feature`` (the JSON), whose values are cached."""
    scale, shown = u_display(name)
    value, u, state = (fe["parameters"][name], fe["u"][name], fe["fit"]["state"]) if fe else (None, None, None)
    u_shown = Formula(f"={cell(budget_row, U_COLUMN, 'Budget')}", None if u is None else u * scale)
    return [name, Formula(f"={cell(budget_row, 2, 'Budget')}", value),
            Formula(f"={cell(budget_row, U_COLUMN, 'Budget')}/{scale:g}", u), unit_of(name),
            u_shown if shown == "µm" else NOT_APPLICABLE,
            u_shown if shown != "µm" else NOT_APPLICABLE,
            Formula(f'=IF(SQRT(SUMSQ({step.ref}))>{STALE_STEP:.9f},"{FIT_STALE}","{FIT_CURRENT}")', state)]


def _write_results(book: Book, f, rows: list[tuple[str, int]], fe: dict | None = None) -> None:
    step = gn_step_block(f.n)
    ws = book.results(
        RESULT_COLUMNS, [result_row(name, r, step, fe) for name, r in rows],
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
        f"The uncertainty of a least-squares {feature_label(f)} fitted to {f.m} points, per CMM influence "
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
            "functions cmm_feature and cmm_feature_va in cmmwb.xlfuncs.udf) over 'Points', the probes and "
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
