"""The ``Live_addin`` sheet of a ``feature`` workbook above the native limit: the same numbers as
Excel add-in formulas (``cmmwb.xlfuncs.udf``: ``cmm_feature``, ``cmm_feature_va``), as the large
point-cloud workbook does (``generator.pointcloud.large_book``)."""

from __future__ import annotations

from cmmwb.xlfuncs import pointcloud as pc

from ..pointcloud.large_book import LIVE, addin_ranges
from ..workbook.book import Book
from ..workbook.xlref import Block, block
from .fit_sheets import SMALL, matrix_labels
from .task import Task
from .va_sheets import VALUE_SCALE

# -- the same numbers as Excel add-in formulas (above the native limit) -----------------------------

#: 'Live_addin' columns of the fit options the add-in formulas read (rows 3, 4)
LIVE_OPTION_COLUMN = 11


def write_live(book: Book, task: Task, f, va: dict, probe_rows: dict) -> None:
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
                        "Excel add-in (cmmwb.xlfuncs.udf, docs/addins.md): live in Excel with the add-in, "
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
        matrix_labels(book, ws, top, Gl.column, names, names)
        matrix_labels(book, ws, top, vb.column, lnames, lnames)
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
