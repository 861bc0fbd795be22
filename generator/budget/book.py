


"""The ``budget`` workbook: Wojtyła/Płowucha 2023 uncertainty budgets as live formulas.

Sheets: Instructions, Inputs (MPE, essential points, TEDs: named input cells), one sheet per
characteristic, Results.  A characteristic sheet shows the budget of the chosen variant in the
layout of the paper's Tables 1-8 (input, x_i in mm, dl/dx_i, u_i in µm, contribution, then l,
u_c, U), a table of every variant's u_c side by side, and the budgets of the other variants
below.  A position sheet first combines its two distance budgets (Table 9).

Every computed cell is a formula of the named inputs: x_i = coordinate differences, u_i =
b (A_um + |x_i|/B_mm), the sensitivities are the closed-form derivatives of the cross/dot-product
models written out cell by cell (cross products component-wise, next to each budget under
"intermediate quantities"), contributions, u_c = SQRT(SUMSQ(...)), U = k u_c.  Only plain
single-cell formulas are used (no array formulas, INDEX or OFFSET).
"""

from __future__ import annotations

import json
from pathlib import Path

from openpyxl.styles import Alignment

from cmmwb.xlfuncs import budget as bd

from ..workbook.book import Book, BookAdditions, Formula
from ..workbook.styles import HEADER_FONT
from ..workbook.workpiece import write_workpiece_inputs
from ..workbook.xlref import block, cell
from .block import (
    C_INPUT,
    DOF_HEADER,
    FMT_U,
    NU_EFF_NOTE,
    BudgetCells,
    CharCells,
    coord,
    nu_eff_formula,
    type_a_cells,
    write_variant,
)
from .task import MODEL_TEXT, distance_name


def _variant_table(book: Book, ws, r0: int, title: str, d: bd.DistanceBudget,
                   cells: dict[str, BudgetCells], sheet: str) -> int:
    """Every variant's l, u_c and U side by side (formulas pointing at their budgets), the
    lowest u_c now, and whether the chosen variant is still the lowest."""
    book.text(ws, r0, C_INPUT, title, font=HEADER_FONT)
    book.header(ws, r0 + 1, C_INPUT, ["variant", "equation", "l_mm", "u_c_um", "U_um", "chosen"],
                [None, "Wojtyła/Płowucha 2023", None, "u_c of the variant's budget (eq. (6))",
                 None, "the variant whose budget is reported (auto: lowest u_c at build time)"])
    r = r0 + 2
    first = r
    chosen_u = None
    for vb in d.variants:
        bc = cells[vb.label]
        book.text(ws, r, 1, vb.label)
        book.text(ws, r, 2, vb.spec.equation)
        book.formula(ws, r, 3, f"={_ref(bc.sheet, bc.value, sheet)}", fmt="0.0000")
        book.formula(ws, r, 4, f"={_ref(bc.sheet, bc.u, sheet)}", fmt=FMT_U)
        book.formula(ws, r, 5, f"={_ref(bc.sheet, bc.U, sheet)}", fmt=FMT_U)
        if vb is d.chosen:
            book.text(ws, r, 6, "chosen")
            chosen_u = cell(r, 4)
        r += 1
    book.text(ws, r, 3, "lowest_u_c_um")
    book.formula(ws, r, 4, f"=MIN({block(first, 4, len(d.variants), 1)})", fmt=FMT_U)
    book.text(ws, r + 1, 3, "chosen_is_lowest")
    book.formula(ws, r + 1, 4, f"=IF({chosen_u}<={cell(r, 4)}*(1+1E-9),\"yes\",\"no\")",
                 fmt=None, note="'no' after an edit: another variant now has a lower u_c; set "
                 "variant in the task file or rebuild with variant = \"auto\"")
    return r + 3


def _pareto(book: Book, ws, r0: int, items: list[tuple[str, float, str, float]], u_ref: str,
            what: str) -> int:
    """A Pareto table of the contributions (largest first, ordered by the values at build time;
    the cells stay live) and its bar chart; returns the rows used.

    ``items`` = (label, factor, contribution cell, contribution at build time): the table shows
    |factor * contribution| (µm) and its share of u_c^2 (%), which add up to 100 %."""
    from openpyxl.chart import Reference

    book.text(ws, r0, 1, f"Contributions to {what}, largest first (Pareto; order as built)",
              font=HEADER_FONT)
    book.header(ws, r0 + 1, 1, ["input", "abs_contribution_um", "share_of_u_c2_pct"],
                ["input quantity of the budget above", "|dl/dx_i u_i| (µm; for a position: 2 |dl/dx_i u_i| of "
                 "its distance budget, Table 9)", "(contribution / u_c)^2 in %: the shares add up to 100 %"])
    order = sorted(range(len(items)), key=lambda k: -abs(items[k][1] * items[k][3]))
    r = r0 + 2
    for k in order:
        label, factor, ref, _ = items[k]
        book.text(ws, r, 1, label)
        f = f"ABS({ref})" if factor == 1 else f"{factor:g}*ABS({ref})"
        book.formula(ws, r, 2, f"={f}", fmt=FMT_U)
        book.formula(ws, r, 3, f"=100*({cell(r, 2)}/{u_ref})^2", fmt="0.0")
        r += 1
    last = r - 1
    book.bars(ws, f"D{r0 + 1}", f"Contributions to {what} (µm), largest first", "|contribution| / µm",
              Reference(ws, min_col=1, min_row=r0 + 2, max_row=last),
              [Reference(ws, min_col=2, min_row=r0 + 1, max_row=last)],
              width=17, height=max(6.0, 0.45 * len(items) + 2.5))
    chart_rows = int(max(6.0, 0.45 * len(items) + 2.5) / 0.53) + 2
    return max(last - r0 + 2, chart_rows)


def _page_breaks(blocks: list[tuple[int, int]]) -> list[int]:
    """Rows that start a new page so that no block (first row, last row) is split, assuming
    ``ROWS_PER_PAGE`` rows per printed page."""
    breaks, top = [], 1
    for a, b in sorted(blocks):
        if b - top + 1 > ROWS_PER_PAGE and a > top:
            breaks.append(a)
            top = a
    return breaks


def _ref(target_sheet: str, coord: str, here: str) -> str:
    r, c = _split(coord)
    return cell(r, c, None if target_sheet == here else target_sheet)


def _split(coord: str) -> tuple[int, int]:
    from openpyxl.utils.cell import column_index_from_string, coordinate_from_string

    letters, row = coordinate_from_string(coord)
    return row, column_index_from_string(letters)


def _distance_section(book: Book, ws, r0: int, heading: str, d: bd.DistanceBudget,
                      type_a: dict | None = None) -> tuple[CharCells, int, list]:
    """The chosen variant's budget of one distance; returns its cells, the next row and the
    pending (other) variants to write further down."""
    ch = d.chosen
    title = f"{heading} — variant {ch.label}, {ch.spec.equation}"
    bc, r = write_variant(book, ws, r0, title, ch, notes=True, type_a=type_a)
    cc = CharCells(ws.title, bc.value, bc.u, bc.U, rows=bc.rows, chosen=bc,
                   variants={ch.label: bc}, nu_eff=bc.nu_eff, type_a=bc.type_a)
    return cc, r, [v for v in d.variants if v is not ch]


def _set_widths(ws) -> None:
    for col, width in (("A", 30), ("B", 14), ("C", 14), ("D", 14), ("E", 16), ("F", 9),
                       ("G", 14), ("H", 13), ("I", 13), ("J", 13), ("K", 48), ("L", 18), ("M", 10)):
        ws.column_dimensions[col].width = width


# -- sheets ---------------------------------------------------------------------------------------

def _write_distance_sheet(book: Book, task, c, d: bd.DistanceBudget, type_a: dict | None = None) -> CharCells:
    ws = book.sheet(c.name)
    _set_widths(ws)
    book.text(ws, 1, 1, f"{c.name}: {MODEL_TEXT[c.model]}", font=HEADER_FONT)
    book.text(ws, 2, 1, _points_text(c) + f"; variant requested: {c.variant}")
    cc, r, others = _distance_section(book, ws, 4, f"Budget of {c.name}", d, type_a)
    keep = [(1, r - 1)]
    pareto = [(inp, 1.0, row["contribution"], float(x))
              for inp, row, x in zip(d.chosen.inputs, cc.rows, d.chosen.contributions_um)]
    pareto += [(row["input"], 1.0, row["contribution"], float(t["contribution_um"]))
               for row, t in zip(cc.chosen.thermal, d.chosen.thermal)]
    r = _others_and_table(book, ws, r, [(c.name, d, cc, others)], keep=keep, pareto=pareto,
                          pareto_u=cc.u, what=f"u_c of {c.name}")
    ws.freeze_panes = "B1"
    return cc


ROWS_PER_PAGE = 50   # budget rows that fit one landscape A4 page at the fit-to-width scale


def _others_and_table(book: Book, ws, r: int, sections, *, keep: list[tuple[int, int]],
                      pareto: list[tuple[str, float, str, float]], pareto_u: str, what: str) -> int:
    """Variant tables first (near the top), the Pareto of the contributions, then the budgets of
    the other variants; sets the print setup (the chosen budgets, the variant tables and the
    Pareto print, each block on one page; the other variants stay in the workbook only)."""
    # the tables need the other variants' cells: compute the layout of the blocks first by
    # writing the tables after the blocks but placing the tables above them
    table_rows = sum(len(d.variants) + 5 for _, d, _, _ in sections)
    r_table = r
    keep.append((r, r + table_rows - 1))
    r_pareto = r + table_rows
    pareto_rows = _pareto(book, ws, r_pareto, pareto, pareto_u, what)
    keep.append((r_pareto, r_pareto + pareto_rows - 1))
    r_blocks = r_pareto + pareto_rows + 1
    book.print_setup(ws, landscape=True, title_rows=None, area=f"A1:M{r_pareto + pareto_rows - 1}",
                     row_breaks=_page_breaks(keep),
                     caption=f"{ws.title}: chosen budget, variants, contributions (the budgets of the "
                             "other variants are in the workbook below, not printed)")
    book.text(ws, r_blocks, 1, "Budgets of the other variants", font=HEADER_FONT)
    r_blocks += 1
    for name, d, cc, others in sections:
        for vb in others:
            bc, r_blocks = write_variant(book, ws, r_blocks, f"{name} — variant {vb.label}, "
                                         f"{vb.spec.equation}", vb, notes=False)
            cc.variants[vb.label] = bc
    for name, d, cc, others in sections:
        r_table = _variant_table(book, ws, r_table, f"Variants of {name}: u_c side by side "
                                 "(the lowest is selected, section 2)", d, cc.variants, ws.title)
    return r_blocks


def _write_position_sheet(book: Book, task, c, pb: bd.PositionBudget, type_a: dict | None = None) -> CharCells:
    ws = book.sheet(c.name)
    _set_widths(ws)
    book.text(ws, 1, 1, f"{c.name}: position deviation of the axis point {pb.point}, cylindrical "
              "tolerance zone (Wojtyła/Płowucha 2023 eq. (22))", font=HEADER_FONT)
    book.text(ws, 2, 1, "POS = 2 sqrt((l1 - l1_TED)^2 + (l2 - l2_TED)^2); u_POS = 2 sqrt(u_l1^2 + "
              "u_l2^2) (Table 9 convention: the RMS of POS at the exact location, docs/errata.md)")
    book.text(ws, 4, 1, f"Budget of {c.name} (Table 9)", font=HEADER_FONT)
    book.header(ws, 5, 8, DOF_HEADER,
                ["l_i combines the inputs of its distance budget below: close to normal (GUM G.2)",
                 "nu of l_i: the nu_eff of its distance budget below (GUM G.4.1)"])
    book.header(ws, 5, 1, ["input", "value_mm", "sensitivity_mm/mm", "u_um", "contribution_um",
                           "TED_mm", "datum"],
                ["the distances of the axis point from the two datums", "l_i (mm), from the "
                 "distance budgets below", "2: POS = 2 |deviation|; u_POS = 2 sqrt(u_l1^2 + "
                 "u_l2^2) (Table 9); eq. (26) would give 2 max(u_l1, u_l2)",
                 "u_c of the distance budget below", "sensitivity * u", "theoretically exact "
                 "distance (input cell on 'Inputs')", None])
    # distance budgets further down
    sections = []
    r = 13
    keep = [(1, 12)]
    dist_cells = []
    for i, d in enumerate(pb.distances):
        heading = (f"Budget of {distance_name(c, i)}: distance of {pb.point} from the "
                   f"{pb.datums[i]} datum")
        r_start = r
        cc, r, others = _distance_section(book, ws, r, heading, d)
        keep.append((r_start, r - 1))
        dist_cells.append(cc)
        sections.append((distance_name(c, i), d, cc, others))
    # u_POS^2 = sum over both distance budgets of (2 * contribution)^2 (Table 9 convention)
    pareto = [(f"{distance_name(c, i)}: {inp}", bd.POSITION_FACTOR, row["contribution"], float(x))
              for i, (d, cc) in enumerate(zip(pb.distances, dist_cells))
              for inp, row, x in [*zip(d.chosen.inputs, cc.rows, d.chosen.contributions_um),
                                  *((row["input"], row, t["contribution_um"])
                                    for row, t in zip(cc.chosen.thermal, d.chosen.thermal))]]
    _others_and_table(book, ws, r, sections, keep=keep, pareto=pareto, pareto_u="E9",
                      what=f"u_POS of {c.name}")
    rows = []
    for i, (d, cc) in enumerate(zip(pb.distances, dist_cells)):
        rr = 6 + i
        book.text(ws, rr, 1, pb.inputs[i])
        book.formula(ws, rr, 2, f"={_ref(ws.title, cc.value, ws.title)}", fmt="0.0000")
        book.formula(ws, rr, 3, f"={bd.POSITION_FACTOR:g}", fmt="0")
        book.formula(ws, rr, 4, f"={_ref(ws.title, cc.u, ws.title)}", fmt=FMT_U)
        book.formula(ws, rr, 5, f"={cell(rr, 3)}*{cell(rr, 4)}", fmt=FMT_U)
        book.formula(ws, rr, 6, f"={c.name}_ted{i + 1}_mm", fmt="0.00##")
        book.text(ws, rr, 7, pb.datums[i])
        book.text(ws, rr, 8, "normal")
        book.formula(ws, rr, 9, f"={_ref(ws.title, cc.nu_eff, ws.title)}", fmt="0.00",
                     note=NU_EFF_NOTE).alignment = Alignment(horizontal="right")
        rows.append({"input": pb.inputs[i], "value": coord(cell(rr, 2)),
                     "sensitivity": coord(cell(rr, 3)), "u": coord(cell(rr, 4)),
                     "contribution": coord(cell(rr, 5)), "distribution": coord(cell(rr, 8)),
                     "nu": coord(cell(rr, 9))})
    book.text(ws, 8, 4, "POS_mm")
    book.formula(ws, 8, 5, f"=2*SQRT(({cell(6, 2)}-{cell(6, 6)})^2+({cell(7, 2)}-{cell(7, 6)})^2)",
                 fmt="0.0000", note="POS = 2 sqrt((l1 - l1_TED)^2 + (l2 - l2_TED)^2), eq. (22)")
    book.text(ws, 9, 4, "u_POS_um")
    book.formula(ws, 9, 5, f"=SQRT(SUMSQ({block(6, 5, 2, 1)}))", fmt=FMT_U,
                 note="u_POS = 2 sqrt(u_l1^2 + u_l2^2): Table 9 (docs/errata.md)")
    book.text(ws, 10, 4, "U_POS_um")
    book.formula(ws, 10, 5, f"=k*{cell(9, 5)}", fmt=FMT_U, note="U = k u_POS")
    book.text(ws, 11, 4, "u_eq26_um")
    book.formula(ws, 11, 5, f"=2*MAX({block(6, 4, 2, 1)})", fmt=FMT_U,
                 note="for comparison only: the paper's eq. (26) with u_l = max(u_l1, u_l2); "
                      "Table 9 does not follow it")
    # degrees of freedom of u_POS (and of a type A repeatability) in columns J-K, rows 6-11
    if type_a is None:
        book.text(ws, 9, 10, "nu_eff")
        book.formula(ws, 9, 11, nu_eff_formula("E9", [6, 7], 5, 9), fmt="0.00",
                     note=NU_EFF_NOTE).alignment = Alignment(horizontal="left")
        nu_eff, a_cells = "K9", None
    else:
        n = type_a["tolerance"]
        book.text(ws, 6, 10, "u_A_um")
        book.formula(ws, 6, 11, f"=tol{n}_s_um/SQRT(tol{n}_n_repeats)", fmt=FMT_U,
                     note=f"type A, normal: u_A = s/sqrt(n) of [[decision.tolerances]] #{n} (its s_um, "
                          "n_repeats are input cells on the Decision sheet), GUM 4.2.3; sensitivity 1 on POS")
        book.text(ws, 7, 10, "nu_A")
        book.formula(ws, 7, 11, f"=tol{n}_n_repeats-1", fmt="0", note="nu = n - 1 (GUM G.3.3)")
        # ν_eff over the rows 6-7 (contribution E, ν I) and the type A (u_A K6, ν_A K7)
        got, _ = type_a_cells(book, ws, 8, 10, 11, "E9", "K6", type_a, [6, 7], 5, 9)
        terms = f"{cell(6, 11)}^4/{cell(7, 11)}"
        uw = cell(8, 11)
        two = "+".join(f"IF(ISNUMBER({cell(r, 9)}),{cell(r, 5)}^4/{cell(r, 9)},0)" for r in (6, 7))
        book.formula(ws, 9, 11, f"={uw}^4/({two}+{terms})", fmt="0.00", note=NU_EFF_NOTE)
        for rr in range(6, 12):
            ws.cell(rr, 11).alignment = Alignment(horizontal="left")
        nu_eff = "K9"
        a_cells = {"u": "K6", "contribution": "K6", "nu": "K7", **got}
    ws.freeze_panes = "B1"
    return CharCells(ws.title, "E8", "E9", "E10", rows=rows, distances=dist_cells, nu_eff=nu_eff,
                     type_a=a_cells)


def _points_text(c) -> str:
    parts = []
    for k, v in c.points.items():
        parts.append(f"{k} = {', '.join(v) if isinstance(v, tuple) else v}")
    if c.datum:
        parts.append(f"datum = {c.datum}")
    return "; ".join(parts)


def _write_inputs(book: Book, task) -> None:
    ws = book.sheet("Inputs")
    ws.column_dimensions["A"].width = 22
    for col in "BCD":
        ws.column_dimensions[col].width = 14
    ws.column_dimensions["E"].width = 70
    book.text(ws, 1, 1, "Inputs: edit the yellow cells, every budget recalculates", font=HEADER_FONT)
    book.text(ws, 2, 1, "task_name")
    book.text(ws, 2, 2, task.name)
    book.text(ws, 2, 5, json.dumps(task.notes, ensure_ascii=False))
    book.header(ws, 3, 1, ["key", "value", "unit", "", "meaning"])
    m = task.mpe
    rows = [("A_um", m.A_um, "µm", 0.0, "E_L,MPE = A + L/B: constant term A (eq. (5))"),
            ("B_mm", m.B_mm, "mm/µm", 1e-12, "E_L,MPE = A + L/B: length term L/B, L in mm"),
            ("b", m.b, "1", 1e-12, "u = b E_L,MPE: 0.577 = 1/sqrt(3) for a uniform distribution "
                                   "(eq. (5)); 1/3 in section 4 of the paper"),
            ("k", m.k, "1", 1e-12, "coverage factor, U = k u")]
    r = 4
    for key, value, unit, lo, meaning in rows:
        book.text(ws, r, 1, key)
        book.input(ws, r, 2, key, value, lo=lo, note=meaning)
        book.text(ws, r, 3, unit)
        book.text(ws, r, 5, meaning)
        r += 1
    if task.part is not None:
        # the part's temperature (the factor W, docs/workpiece.md): its rows in every budget
        r += 1
        book.text(ws, r, 1, "The part's temperature, factor W (docs/workpiece.md); not in the MPE statement",
                  font=HEADER_FONT)
        p = task.part
        r = write_workpiece_inputs(book, ws, r + 1, p.workpiece,
                                   {"u_alpha_ppm_per_K": p.u_alpha_ppm_per_K, "u_T_K": p.u_T_K},
                                   columns=(1, 2, 3, 5))
    r += 1
    book.text(ws, r, 1, "Essential points (mm); defined names <point>_x_mm, <point>_y_mm, "
              "<point>_z_mm", font=HEADER_FONT)
    book.header(ws, r + 1, 1, ["point", "x_mm", "y_mm", "z_mm", "role"])
    r += 2
    roles = _point_roles(task)
    for name, xyz in task.points.items():
        book.text(ws, r, 1, name)
        for k, ax in enumerate(bd.AXES):
            book.input(ws, r, 2 + k, f"{name}_{ax}_mm", xyz[k])
        book.text(ws, r, 5, roles.get(name, ""))
        r += 1
    if task.datum_system is not None:
        ds = task.datum_system
        r += 1
        book.text(ws, r, 1, "Datum system (section 3, eqs. (7)-(9))", font=HEADER_FONT)
        book.text(ws, r + 1, 1, f"primary: plane {''.join(ds.primary)}, normal u = "
                  f"{ds.primary[0]}{ds.primary[1]} x {ds.primary[0]}{ds.primary[2]} (or the "
                  "other two vertex pairs)")
        book.text(ws, r + 2, 1, f"secondary: plane through {ds.secondary[0]} and {ds.secondary[1]} "
                  f"perpendicular to the primary, normal v = {''.join(ds.secondary)} x u")
        book.text(ws, r + 3, 1, f"tertiary: plane through {ds.tertiary_point} perpendicular to "
                  "both, normal w = u x v")
        book.text(ws, r + 4, 1, "datum_system")
        book.text(ws, r + 4, 5, json.dumps({"primary": list(ds.primary),
                                            "secondary": list(ds.secondary),
                                            "tertiary": ds.tertiary_point}))
        r += 6
    pos = [c for c in task.characteristics if c.model == "position"]
    if pos:
        book.text(ws, r, 1, "Theoretically exact distances of the positions (mm); defined names "
                  "<characteristic>_ted1_mm, _ted2_mm", font=HEADER_FONT)
        book.header(ws, r + 1, 1, ["characteristic", "ted_mm", "datum", "", "distance"])
        r += 2
        for c in pos:
            for i in range(2):
                book.text(ws, r, 1, c.name)
                book.input(ws, r, 2, f"{c.name}_ted{i + 1}_mm", c.ted_mm[i], lo=0.0)
                book.text(ws, r, 3, c.datums[i])
                book.text(ws, r, 5, f"l_{c.points['point']},{i + 1}")
                r += 1
        r += 1
    book.text(ws, r, 1, "Characteristics (structure; change it in the task file)",
              font=HEADER_FONT)
    book.header(ws, r + 1, 1, ["name", "model", "", "", "definition"],
                [None, None, None, None, "the task-file keys of the characteristic (JSON): the "
                 "points it uses, datum(s), the variant requested; ted_mm are the named cells above"])
    r += 2
    for c in task.characteristics:
        book.text(ws, r, 1, c.name)
        book.text(ws, r, 2, c.model)
        book.text(ws, r, 5, json.dumps(definition(c), ensure_ascii=False))
        r += 1


def definition(c) -> dict:
    """The task-file keys of a characteristic other than name, model and ted_mm."""
    out = {k: (list(v) if isinstance(v, tuple) else v) for k, v in c.points.items()}
    if c.datum:
        out["datum"] = c.datum
    if c.datums:
        out["datums"] = list(c.datums)
    out["variant"] = c.variant if isinstance(c.variant, str) else list(c.variant)
    return out


def _point_roles(task) -> dict[str, str]:
    roles: dict[str, list[str]] = {}
    ds = task.datum_system
    if ds is not None:
        for p in ds.primary:
            roles.setdefault(p, []).append("primary datum")
        for p in ds.secondary:
            roles.setdefault(p, []).append("secondary datum")
        if ds.tertiary_point not in ds.secondary:
            roles.setdefault(ds.tertiary_point, []).append("tertiary datum")
    for c in task.characteristics:
        for v in c.points.values():
            for p in (v if isinstance(v, tuple) else (v,)):
                if c.name not in roles.get(p, []):
                    roles.setdefault(p, []).append(c.name)
    return {k: ", ".join(v) for k, v in roles.items()}


def _instructions(book: Book, task) -> None:
    book.para("What this workbook computes", bold=True)
    book.para(
        "Uncertainty budgets by the sensitivity-analysis method of M. Wojtyła, P. Rosner, "
        "W. Płowucha et al., 'Determination of uncertainty of coordinate measurements on the "
        "basis of the formula for E_L,MPE', Measurement 222 (2023) 113635.",
        "Each characteristic is a distance l of a few essential points. Its input quantities x_i are "
        "coordinate differences of the points (x_CS4 = x(S4) - x(C), mm); each has u(x_i) = "
        "b * E_L,MPE(|x_i|) = b (A + |x_i|/B) (eq. 5); u_c = sqrt(sum((dl/dx_i u_i)^2)) (eq. 6); "
        "U = k u_c.",
        "The sensitivities dl/dx_i are the closed-form derivatives of the cross/dot-product models "
        "(eqs. 1-4, 7-21, 27-35), written as cell formulas next to each budget (columns G-K: "
        "normal vectors, signed distance t, its sign s, and the gradient g = dl/dn).",
        "No macros, no pasted numbers: click any cell and follow it back to the inputs.")
    book.gap()
    book.para("How to use it", bold=True)
    book.para(
        "1. Edit the yellow cells on 'Inputs' only: MPE (A_um, B_mm), b, k, point coordinates, TEDs.",
        "2. Each characteristic sheet shows the budget of the chosen variant in the layout of the "
        "paper's Tables 1-8, a table of all variants' u_c side by side, and the other variants' "
        "budgets below. A position sheet combines its two distance budgets (Table 9).",
        "3. 'auto' picks the variant of lowest u_c when the workbook is built. After an edit, "
        "'chosen_is_lowest' says whether another variant has become lower; rebuild with cmmwb to "
        "switch.",
        "4. Structural changes (other points, characteristics, variants) go through the task file "
        "and `cmmwb build`.")
    book.gap()
    book.para("Conventions (docs/errata.md, section Wojtyła/Płowucha 2023)", bold=True)
    book.para(
        "Tables 1-9 of the paper follow E = 3 + L/250 µm with b = 0.577 (the MicroXcel of section "
        "6), not the 2 + L/250, b = 1/3 stated in section 4.",
        "Position, cylindrical zone: u_POS = 2 sqrt(u_l1^2 + u_l2^2), which reproduces Table 9. "
        "Eq. (26) (u_POS ~ 2 u_l) is not what Table 9 uses; it is shown as u_eq26_um for comparison.",
        "A point exactly on a plane-type datum (l = 0): |.| has a kink; the one-sided derivative "
        "(sign +1) is used, with the same u_c from either side. The paper instead replaced the zero "
        "x components of CS4, DS4, DS3 by 0.01 mm; the shipped knuckle task does that through the "
        "coordinates of S3 and S4.",
        "Degenerate geometry (collinear plane points, parallel lines, a point on a line, coincident "
        "points) makes the formulas return #DIV/0! rather than a number.",
        *task.notes)


def write(task, evaluated: list, path: Path, type_a: dict[str, dict] | None = None,
          additions: BookAdditions | None = None) -> dict[str, CharCells]:
    """Write the workbook to ``path``; return where each characteristic's cells are.  ``type_a``:
    the type A repeatabilities of ``[[decision.tolerances]]`` per characteristic
    (:func:`generator.budget.job.type_a`)."""
    type_a = type_a or {}
    book = Book("budget", task.name, f"Sensitivity-analysis uncertainty budgets — {task.name}")
    _instructions(book, task)
    _write_inputs(book, task)
    layout: dict[str, CharCells] = {}
    for c, r in zip(task.characteristics, evaluated):
        if c.model == "position":
            layout[c.name] = _write_position_sheet(book, task, c, r, type_a.get(c.name))
        else:
            layout[c.name] = _write_distance_sheet(book, task, c, r, type_a.get(c.name))
    rows = []
    for k, (c, r) in enumerate(zip(task.characteristics, evaluated)):
        cc = layout[c.name]
        cc.results_row = k + 2
        variant = r.variant if c.model == "position" else r.chosen.label
        v = r if c.model == "position" else r.chosen
        u, U = (r.u_um, r.U_um) if c.model == "position" else (r.chosen.u_c_um, r.chosen.U_um)
        sheet = cc.sheet
        rows.append([c.name, variant, Formula(f"={_ref(sheet, cc.value, '')}", v.value_mm),
                     Formula(f"={_ref(sheet, cc.u, '')}", u), Formula(f"={_ref(sheet, cc.U, '')}", U)])
    book.results(["name", "variant", "value_mm", "u_um", "U_um"], rows,
                 ["characteristic (task file)", "formula variant used (x cross, . dot product)",
                  "value of the characteristic, mm", "standard uncertainty u_c (u_POS), µm",
                  "expanded uncertainty U = k u, µm"])
    book.save(path, additions)
    return layout
