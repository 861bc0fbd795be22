"""The ``pointcloud`` workbook for tasks beyond the native-formula limit (more than
``vx_sheets.NATIVE_MAX_POINTS`` points): no 3m x 3m V_X sheets, the Gaussian-process blocks as
labelled values, and the same blocks as live Excel add-in formulas on a sheet of their own.

Design (LibreOffice users see every number; Excel users with the add-in see it live):

``Inputs``, ``Points``  as in the native workbook (named hyper-parameters, probes table, points
            with probe offsets p and ram positions u = x - p as formulas)
``Budget``  one row per distance, the columns of the native workbook plus the ram difference
            du = u_j - u_i.  d, n, u, U and the explicit factors are native formulas:
            u_R = sqrt(2) sigma_R (Forbes 2025 section 6.1), u_PQ (6.2), u_S (6.3, eq. 31 at the
            ram positions).  The Gaussian-process factors ET, ER, P are eq. (29),
            u_f = sqrt(n^T B_f n), a native formula of n and the pair block B_f on ``GP_blocks``.
``GP_blocks`` VALUES (grey): per distance the 3 x 3 blocks B_f = V_ii + V_jj - V_ij - V_ji of
            V_ET, V_ER, V_P (µm², row-major), computed at build time by
            ``xlfuncs.blocked.pair_blocks``; beside them the inputs they were computed for and a
            check cell ``gp_snapshot_ok`` that turns FALSE when an input they depend on is
            edited (then rebuild, or use the add-in).
``Live_addin`` the same numbers as add-in formulas (``cmmwb.xlfuncs.udf``: ``cmm_distances``,
            ``cmm_pair_blocks``), cell for cell beside the values: live in Excel with the
            add-in; #NAME? in LibreOffice and without the add-in -- by design, nothing else
            refers to this sheet.
``MPE``, ``Results``  as in the native workbook (Results are formulas referring to Budget).
``xlwings.conf`` the add-in setting ``UDF Modules = cmmwb.xlfuncs.udf`` for this workbook.
"""

from __future__ import annotations

from copy import copy
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.model.hyperparameters import HYPER, PROBE_OVERRIDES, in_table, of_factor

from .. import __version__
from ..errors import InputError
from ..workbook.book import Book, BookAdditions
from ..workbook.styles import FMT_SCI, VALUE_FILL
from ..workbook.workpiece import N_ROWS as WORKPIECE_ROWS
from ..workbook.workpiece import U_EPS
from ..workbook.xlref import Block, block, cell
from .book import KIND, RESULT_COLUMNS, budget_chart, extra_inputs, results_rows, write_mpe
from .vx_sheets import NATIVE_MAX_POINTS, explain_inputs, write_inputs, write_points

GP_FACTORS = ("ET", "ER", "P")
BLOCK_COLUMNS = ("xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz")
#: distance rows a large workbook holds (the JSON holds any number)
MAX_BOOK_DISTANCES = 200_000
#: points a sheet holds (Excel: 1,048,576 rows, one header row)
MAX_BOOK_POINTS = 1_048_575
LIVE = "Live_addin"
GP = "GP_blocks"
SMALL = FMT_SCI

BUDGET_COLUMNS = ["from", "to", "group", "d_mm", "u_um", "U_um", *(f"u_{f}_um" for f in pc.FACTORS),
                  "dx_mm", "dy_mm", "dz_mm", "nx", "ny", "nz", "dux_mm", "duy_mm", "duz_mm"]
C = {name: k + 1 for k, name in enumerate(BUDGET_COLUMNS)}


def write_large_book(task, results: dict, path: Path, additions: BookAdditions | None = None) -> None:
    """Write the workbook of a ``pointcloud`` task with more than NATIVE_MAX_POINTS points."""
    m, n = task.cloud.m, len(task.pairs)
    if m > MAX_BOOK_POINTS:
        raise InputError(f"{m} points do not fit one sheet of a workbook (at most {MAX_BOOK_POINTS} "
                         "rows): split the points into several tasks", file=task.path, where="[points]")
    if n > MAX_BOOK_DISTANCES:
        raise InputError(f"{n} distances: a workbook holds at most {MAX_BOOK_DISTANCES} distance rows; "
                         "list the distances you need with [[distances]] (from = ..., to = \"*\" "
                         "gives one point against all others)", file=task.path,
                         where="[[distances]]" if n != m * (m - 1) // 2 else "[points]")
    blocks = bl.pair_blocks(task.cloud, task.params, task.pairs, GP_FACTORS)
    book = Book(KIND, task.name, f"Point-cloud uncertainty of distances — {task.name} ({m} points)")
    _instructions(book, task)
    _, probe_rows = write_inputs(book, task.params, task.cloud, extra_inputs(task))
    X, _N, U = write_points(book, task.cloud, probe_rows)
    refs = _Refs(task, probe_rows)
    gp_cols = _write_gp_blocks(book, task, blocks)
    first = _write_budget(book, task, X, U, probe_rows, gp_cols)
    _write_live(book, task, refs)
    if task.mpe is not None:
        write_mpe(book, task)
    budget_chart(book, book.wb["Budget"], task, first)   # after MPE: the chart draws its MPE line
    book.results(RESULT_COLUMNS, results_rows(task, first, results))
    write_xlwings_conf(book)
    book.save(path, additions)


def addin_ranges(m: int, probe_rows: dict) -> tuple[str, str, str]:
    """The ranges every add-in formula reads (``cmmwb.xlfuncs.udf`` argument layout): ``points`` =
    Points!A:H of the m points, ``probes`` = the probes table on Inputs (rows ``probe_rows``
    of :func:`generator.pointcloud.vx_sheets.write_inputs`), ``params`` = names and values of the 12
    hyper-parameters on Inputs and the part's rows after them (the factor W, docs/workpiece.md).
    Shared by the pointcloud and the feature workbooks."""
    rows = sorted(probe_rows.values())
    return (block(2, 1, m, 8, "Points"),
            block(rows[0], 1, rows[-1] - rows[0] + 1, 8, "Inputs"),
            block(2, 1, len(in_table("parameters")) + WORKPIECE_ROWS, 2, "Inputs"))


def write_xlwings_conf(book: Book) -> None:
    """The sheet ``xlwings.conf``: the add-in setting ``UDF Modules = cmmwb.xlfuncs.udf`` for this
    workbook (read by xlwings' Import Functions; ignored by every other program)."""
    ws = book.sheet("xlwings.conf", protect=False)
    book.text(ws, 1, 1, "UDF Modules")
    book.text(ws, 1, 2, "cmmwb.xlfuncs.udf")


class _Refs:
    """Ranges the add-in formulas read: the points table, the ids, the probes, the parameters."""

    def __init__(self, task, probe_rows: dict):
        n = len(task.pairs)
        self.points, self.probes, self.params = addin_ranges(task.cloud.m, probe_rows)
        self.from_ids = block(2, 1, n, 1, "Budget")
        self.to_ids = block(2, 2, n, 1, "Budget")

    def args(self) -> str:
        return ",".join((self.points, self.from_ids, self.to_ids, self.probes, self.params))


def _instructions(book: Book, task) -> None:
    m, n = task.cloud.m, len(task.pairs)
    book.para("What this workbook computes", bold=True)
    book.para(
        f"The standard uncertainty u(d) of {n} distances between {m} measured points and its six "
        "components (A. Forbes, 'CMM influence factors and uncertainty associated with length "
        "measurement', Appl. Sci. 2025, 15, 271, eqs. (28)-(30)).",
        f"{m} points are more than the {NATIVE_MAX_POINTS} for which the 3m x 3m matrices V_R ... V_P "
        f"are laid out as native formulas ({3 * m} x {3 * m} numbers per factor). Each distance needs "
        "only the 3 x 3 blocks of its two points (eq. 29), so this workbook shows those:")
    book.gap()
    book.para("Where every number comes from", bold=True)
    book.para(
        "Budget — native formulas: d, the direction n, u_R (section 6.1), u_PQ (6.2), u_S (6.3, at the ram "
        "positions x - p), u = root sum of squares (eq. 30), U = K u.",
        "Budget u_ET, u_ER, u_P — native formulas sqrt(n^T B n) (eq. 29) of n and the pair blocks "
        "B = V_ii + V_jj - V_ij - V_ji on 'GP_blocks'.",
        "Budget u_W — the part's thermal expansion, a native formula d u(eps) of the workpiece inputs on "
        "'Inputs' (docs/workpiece.md; zero while workpiece_enabled = 0).",
        f"GP_blocks — grey cells are VALUES, not formulas: the Gaussian-process blocks of V_ET (eq. 21), "
        f"V_ER (eqs. 24-25) and V_P (eqs. 26-27), computed when the workbook was built by "
        f"xlfuncs.blocked.pair_blocks (cmmwb {__version__}). Beside them: the inputs they were computed "
        "for, and gp_snapshot_ok, which turns FALSE when you edit one of those inputs (lambda_ET_mm, "
        "sigma_ER_urad, a probe offset, a point ...). Then rebuild (`cmmwb read`, `cmmwb build`) or use "
        "the Excel add-in.",
        "Live_addin — the same numbers as formulas of the cmmwb Excel add-in (xlwings user-defined "
        "functions cmm_distances and cmm_pair_blocks in cmmwb.xlfuncs.udf), cell for cell in the layout of "
        "'GP_blocks' and 'Budget'. In Excel with the add-in they recompute live from Inputs and Points; "
        "install and use: docs/addins.md of cmmwb (save as .xlsm, reference xlwings, Import "
        "Functions; 'xlwings.conf' already names the module). In LibreOffice, or in Excel without the "
        "add-in, this sheet shows #NAME?: by design, no other cell refers to it, so every result "
        "stays visible.")
    book.gap()
    book.para("How to use it", bold=True)
    book.para(
        "1. Edit the yellow cells only: hyper-parameters and MPE on 'Inputs', probe offsets, point "
        "coordinates and normals on 'Points'. The native parts recalculate at once; u_ET, u_ER and u_P use "
        "the values on 'GP_blocks', which do not follow edits (gp_snapshot_ok then turns FALSE); in Excel "
        "with the add-in, 'Live_addin' follows every edit.",
        "2. Structural changes (more points, another probe, other distances) go through the task file: "
        "`cmmwb read` this workbook, edit the task, `cmmwb build` again.",
        "3. 'Budget' is the distance table in the layout of Forbes 2025 Tables 4/5; 'Results' is the "
        "machine-readable summary; 'MPE' (when the task has [mpe]) compares K u(d) with the MPE statement.")
    book.gap()
    book.para("Conventions (see docs/errata.md)", bold=True)
    book.para(
        "Units: coordinates mm, uncertainties µm, variances µm², scale/squareness ppm, rotations µrad.",
        "Scale/squareness, ET and ER act on the ram positions x_i - p_k(i) (sections 4.3, 5.3, 5.4); probing "
        "effects of different probes are independent (section 5.5).",
        *task.notes)
    explain_inputs(book)


def _template(book: Book, **styles):
    """The style array of a cell of this workbook with these styles: copied onto many cells, it
    styles them without openpyxl's per-attribute bookkeeping (seconds for 10^5 cells).  (Style
    arrays index the workbook's own style tables, so the template cell must live in it.)"""
    ws = book.wb.create_sheet("__style_template")
    c = ws.cell(row=1, column=1)
    for k, v in styles.items():
        setattr(c, k, v)
    style = copy(c._style)
    book.wb.remove(ws)
    return style


def _finite(v: float, where: str) -> float:
    v = float(v)
    if not np.isfinite(v):
        raise InputError(f"{where}: the core produced {v!r}")
    return v


def _write_gp_blocks(book: Book, task, blocks: dict) -> dict:
    """The GP pair blocks as labelled values; returns {factor: first column}."""
    ws = book.sheet(GP)
    labels = task.cloud.labels
    cols = {f: 3 + 9 * k for k, f in enumerate(GP_FACTORS)}
    header = ["from", "to"] + [f"B_{f}_{ab}_um2" for f in GP_FACTORS for ab in BLOCK_COLUMNS]
    titles = {"ET": "location errors, eq. (21)", "ER": "rotation errors, eqs. (24)-(25)",
              "P": "probing, eqs. (26)-(27)"}
    notes = [None, None] + [
        (f"B_{f} = V_ii + V_jj - V_ij - V_ji of V_{f} ({titles[f]}), µm², row-major. VALUES computed at "
         f"build time by xlfuncs.blocked.pair_blocks (cmmwb {__version__}) for the inputs listed at the right "
         f"of this sheet; live: the same cells on sheet {LIVE} (add-in function cmm_pair_blocks)")
        if ab == "xx" else None for f in GP_FACTORS for ab in BLOCK_COLUMNS]
    book.header(ws, 1, 1, header, notes)
    style = _template(book, number_format=SMALL, fill=VALUE_FILL)
    for q, (i, j) in enumerate(task.pairs):
        r = 2 + q
        book.text(ws, r, 1, labels[i])
        book.text(ws, r, 2, labels[j])
        for f in GP_FACTORS:
            vals = blocks[f][q].reshape(9)
            c0 = cols[f]
            for k in range(9):
                c = ws.cell(row=r, column=c0 + k)
                c.value = _finite(vals[k], f"{GP}!{cell(r, c0 + k, absolute=False)}")
                c._style = copy(style)
    ws.freeze_panes = "C2"
    _write_snapshot(book, ws, task, 3 + 9 * len(GP_FACTORS) + 1)
    n = len(task.pairs)
    book.print_setup(ws, matrix=(n, 2 + 9 * len(GP_FACTORS)), caption=(
        f"{GP}: the first rows of the {n} pair blocks (values); the whole table is in the workbook, not in "
        "the printout"))
    return cols


def _write_snapshot(book: Book, ws, task, c0: int) -> None:
    """The inputs the GP values depend on, as they were at build time and as they are now, and
    the check cell ``gp_snapshot_ok``.  Points enter through checksums (sum and sum of squares
    of each column, with a tolerance from the exactly rounded sum of magnitudes)."""
    import math

    book.header(ws, 1, c0, ["input the GP values depend on", "value at build", "value now", "tolerance",
                            "same"],
                [None, "the value the GP_blocks were computed with", "the current input cell",
                 "largest rounding difference accepted", "|now - build| <= tolerance"])
    rows: list[tuple[str, float, str, float]] = []
    p = task.params
    for key in (*of_factor("ET"), *of_factor("ER")):
        v = getattr(p, key)
        rows.append((key, v, key, 1e-12 * abs(v)))
    for k, probe in enumerate(task.cloud.probes):
        res = probe.resolved(p)
        vals = [(f"p{'xyz'[a]}_mm", res.offset_mm[a]) for a in range(3)] + \
               [(key, getattr(res, key)) for key in PROBE_OVERRIDES if HYPER[key].factor == "P"]
        for key, v in vals:
            rows.append((f"probe {probe.id} {key}", float(v), f"probe{k + 1}_{key}", 1e-12 * abs(v)))
    m = task.cloud.m
    for a, name in enumerate(("x_mm", "y_mm", "z_mm", "nx", "ny", "nz")):
        col = (task.cloud.X_mm if a < 3 else task.cloud.N)[:, a % 3]
        rng = block(2, 2 + a, m, 1, "Points")
        mag = math.fsum(abs(float(x)) for x in col)
        rows.append((f"sum of Points {name}", math.fsum(col), f"SUM({rng})", 1e-11 * mag))
        rows.append((f"sum of squares of Points {name}", math.fsum(float(x) ** 2 for x in col),
                     f"SUMSQ({rng})", 1e-11 * math.fsum(float(x) ** 2 for x in col)))
    for q, (label, value, now, tol) in enumerate(rows):
        r = 2 + q
        book.text(ws, r, c0, label)
        book.number(ws, r, c0 + 1, value, fmt="General", computed=True)
        book.formula(ws, r, c0 + 2, f"={now}", fmt="General")
        book.number(ws, r, c0 + 3, tol, fmt="General", computed=True)
        book.formula(ws, r, c0 + 4, f"=ABS({cell(r, c0 + 2)}-{cell(r, c0 + 1)})<={cell(r, c0 + 3)}",
                     fmt="General")
    r = 2 + len(rows) + 1
    book.text(ws, r, c0, "gp_snapshot_ok")
    book.formula(ws, r, c0 + 4, f"=AND({block(2, c0 + 4, len(rows), 1)})", name="gp_snapshot_ok",
                 fmt="General", note="TRUE while every input the GP blocks depend on is as at build time; "
                                     "FALSE: rebuild the workbook or use the Excel add-in (Live_addin)")
    ws.column_dimensions[ws.cell(row=1, column=c0).column_letter].width = 32


def _write_budget(book: Book, task, X: Block, U: Block, probe_rows: dict, gp_cols: dict) -> int:
    ws = book.sheet("Budget")
    notes = [None, None, "free label (e.g. LL, RR, LR, FF of Forbes 2025 Figures 6/7)",
             "d_ij = ||x_j - x_i||", "u(d_ij), eq. (30): root sum of squares of the components", "U = K u",
             "u_R = sqrt(2) sigma_R, Forbes 2025 section 6.1",
             "u_PQ = sqrt(sigma_PQ,k(i)^2 + sigma_PQ,k(j)^2) for two probes, 0 for one probe (section 6.2)",
             "u_S, eq. (31) with du = u_j - u_i (ram positions, section 4.3): "
             "sigma_S^2 (n.du)^2 + sigma_Sa^2 sum (n_a du_a)^2 + sigma_Q^2 ((n_x du_y)^2 + (n_x du_z)^2 + (n_y du_z)^2)",
             *[f"u_{f} = sqrt(n^T B_{f} n), eq. (29), B_{f} = the pair block of V_{f} on GP_blocks (values; "
               f"live on {LIVE})" for f in GP_FACTORS],
             "u_W = d u(eps): the part's thermal expansion is a scale about the fixture point (docs/workpiece.md)",
             "x_j - x_i", None, None, "n_ij = (x_j - x_i)/d_ij", None, None,
             "du = u_j - u_i, ram positions u = x - p (Points)", None, None]
    book.header(ws, 1, 1, BUDGET_COLUMNS, notes)
    labels = task.cloud.labels
    k = task.cloud.probe_index
    first = 2
    for q, (i, j) in enumerate(task.pairs):
        r = first + q
        book.text(ws, r, 1, labels[i])
        book.text(ws, r, 2, labels[j])
        book.text(ws, r, 3, task.groups[q])
        for a in range(3):
            book.formula(ws, r, C["dx_mm"] + a, f"={X.cell(j, a)}-{X.cell(i, a)}")
            book.formula(ws, r, C["dux_mm"] + a, f"={U.cell(j, a)}-{U.cell(i, a)}")
        book.formula(ws, r, C["d_mm"], f"=SQRT(SUMSQ({block(r, C['dx_mm'], 1, 3)}))", fmt="0.0000")
        for a in range(3):
            book.formula(ws, r, C["nx"] + a, f"={cell(r, C['dx_mm'] + a)}/{cell(r, C['d_mm'])}")
        nx, ny, nz = (cell(r, C["nx"] + a) for a in range(3))
        ux, uy, uz = (cell(r, C["dux_mm"] + a) for a in range(3))
        book.formula(ws, r, C["u_R_um"], "=SQRT(2*sigma_R_um^2)", fmt="0.0000")
        if k[i] == k[j]:
            book.formula(ws, r, C["u_PQ_um"], "=0", fmt="0.0000")
        else:
            si, sj = (cell(probe_rows[int(k[x])], 5, "Inputs") for x in (i, j))
            book.formula(ws, r, C["u_PQ_um"], f"=SQRT({si}^2+{sj}^2)", fmt="0.0000")
        book.formula(
            ws, r, C["u_S_um"],
            f"=SQRT((sigma_S_ppm*0.001)^2*({nx}*{ux}+{ny}*{uy}+{nz}*{uz})^2"
            f"+(sigma_Sa_ppm*0.001)^2*(({nx}*{ux})^2+({ny}*{uy})^2+({nz}*{uz})^2)"
            f"+(sigma_Q_ppm*0.001)^2*(({nx}*{uy})^2+({nx}*{uz})^2+({ny}*{uz})^2))", fmt="0.0000")
        nvec = (nx, ny, nz)
        for f in GP_FACTORS:
            c0 = gp_cols[f]
            B = [[cell(r, c0 + 3 * a + b, GP) for b in range(3)] for a in range(3)]
            quad = "+".join(f"{nvec[a]}*({'+'.join(f'{B[a][b]}*{nvec[b]}' for b in range(3))})" for a in range(3))
            book.formula(ws, r, C[f"u_{f}_um"], f"=SQRT(MAX(0,{quad}))", fmt="0.0000")
        book.formula(ws, r, C["u_W_um"], f"={cell(r, C['d_mm'])}*{U_EPS}*0.001", fmt="0.0000")
        book.formula(ws, r, C["u_um"], f"=SQRT(SUMSQ({block(r, C['u_R_um'], 1, len(pc.FACTORS))}))", fmt="0.0000")
        book.formula(ws, r, C["U_um"], f"=K*{cell(r, C['u_um'])}", fmt="0.0000")
    ws.freeze_panes = "D2"
    for col, w in zip("ABC", (8, 8, 7)):
        ws.column_dimensions[col].width = w
    return first


def _write_live(book: Book, task, refs: _Refs) -> None:
    """Add-in formulas over the same cells as the values: columns C.. hold the GP pair blocks
    exactly where GP_blocks has them, then d, u and the six components of each distance.
    LibreOffice shows #NAME? here (no add-in); nothing else refers to this sheet."""
    ws = book.sheet(LIVE, protect=False)
    n = len(task.pairs)
    labels = task.cloud.labels
    dist_cols = ["d_mm", "u_um", *(f"u_{f}_um" for f in pc.FACTORS)]
    gp_header = [f"B_{f}_{ab}_um2" for f in GP_FACTORS for ab in BLOCK_COLUMNS]
    book.header(ws, 1, 1, ["from", "to", *gp_header, *dist_cols],
                [None, None] +
                [f"cmm_pair_blocks(\"{f}\", points, from, to, probes, params): the pair block B_{f} "
                 "of the same cells on GP_blocks, computed live by the Excel add-in"
                 if ab == "xx" else None for f in GP_FACTORS for ab in BLOCK_COLUMNS] +
                ["cmm_distances(points, from, to, probes, params): d, u and the components of "
                 "eqs. (29)-(30) as on Budget (W with the part's inputs in params), computed live by the Excel "
                 "add-in"] + [None] * (len(dist_cols) - 1))
    for q, (i, j) in enumerate(task.pairs):
        book.text(ws, 2 + q, 1, labels[i])
        book.text(ws, 2 + q, 2, labels[j])
    args = refs.args()
    for k, f in enumerate(GP_FACTORS):
        book.array(Block(LIVE, 2, 3 + 9 * k, n, 9), f"=cmm_pair_blocks(\"{f}\",{args})", fmt=None)
    book.array(Block(LIVE, 2, 3 + 9 * len(GP_FACTORS), n, len(dist_cols)), f"=cmm_distances({args})",
               fmt=None)
    ws.freeze_panes = "C2"
