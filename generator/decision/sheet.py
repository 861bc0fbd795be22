"""The ``Decision`` sheet of a workbook: the conformity decisions of
:mod:`generator.decision.decide` as live formulas.

The sheet computes everything from the Results cells and its own inputs (limits, measured
values, r, max_pfa, k) with formulas all four engines accept (``_xlfn.NORM.DIST`` through
``xlref.norm_s_dist``, ``_xlfn.NORM.S.INV``, measured in ``docs/engines.md``); JCGM 106:2012, 7.3-7.4.
"""

from __future__ import annotations

import textwrap
from typing import Any

from openpyxl.chart import Reference

from cmmwb.xlfuncs import conformity as cf
from cmmwb.xlfuncs import dof
from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.statement import decimals_for

from ..workbook.book import Book, ChartSeries
from ..workbook.styles import FMT_MM, FMT_UM, HEADER_FONT, TITLE_FONT
from ..workbook.xlref import cell, col, norm_s_dist, quote_sheet
from . import risks
from .decide import DecisionSpec, rows_of

SHEET = "Decision"
FMT_P = "0.000000"
HEADER_ROW = 7
FIRST_ROW = HEADER_ROW + 1     #: the first characteristic's row
#: columns of the decision table (first row of the table: headers with units)
COLUMNS = ["item", "characteristic", "value_mm", "u_task_um", "s_um", "n_repeats", "u_A_um", "nu_A", "u_um", "nu_eff",
           "k", "U_um", "lsl_mm", "usl_mm", "w_um", "A_L_mm", "A_U_mm", "R_L_mm", "R_U_mm", "p_c", "outcome",
           "zone"]


def column(name: str) -> int:
    """1-based column of the Decision table (``COLUMNS``)."""
    return COLUMNS.index(name) + 1
#: chart data, each row on the scale of its own tolerance (``chart_scale``): two-sided
#: (x - midpoint)/(half the tolerance), limits at ±1; one-sided ±1 + (x - T)/max(4U, |value - T|)
CHART_COLUMNS = ["y_rel", "y_plus_U_rel", "y_minus_U_rel", "lsl_rel", "usl_rel", "A_L_rel", "A_U_rel"]
CHART_NOTE = ("chart: {name}, on the row's own scale: two-sided tolerance (x − midpoint)/(half the tolerance), "
              "the limits at −1 and +1; one-sided +1 + (x − T_U)/s or −1 + (x − T_L)/s, s = max(4U, |value − T|) (a "
              "one-sided tolerance has no width: the limit at ±1, a value within 4U of it on a linear scale, one "
              "farther inside at 0, one farther outside at ±2)")
#: the specific-risk rule's exact two-sided acceptance limits: h = (T_U - T_L)/(2u) and Newton's
#: iterates s_j = (d/u)² of xlfuncs.conformity.specific_risk_iterates, one column per step
NEWTON_COLUMNS = ["h_half_tol_per_u"] + [f"newton_s{j}" for j in range(cf.NEWTON_STEPS + 1)]


def _results_cols(book: Book, sheet: str = "Results") -> dict[str, int]:
    """Column (1-based) of each header name in row 1 of ``sheet``."""
    ws = book.wb[sheet]
    return {str(c.value): c.column for c in ws[1] if c.value is not None}


def write_sheet(book: Book, kind: str, spec: DecisionSpec, results: dict, decisions: list[dict]
                ) -> dict[str, dict[str, Any]]:
    """The ``Decision`` sheet; returns the values to cache in its formula cells
    ({sheet: {coordinate: value}}, from the core's ``decisions``)."""
    rows = rows_of(kind, results, spec)
    sheet_cols = {name: _results_cols(book, name) for name in {row.sheet for row in rows.values()}}
    ws = book.sheet(SHEET)
    cache: dict[str, Any] = {}
    rule = spec.rule
    book.text(ws, 1, 1, "Conformity decisions", font=TITLE_FONT)
    intro = textwrap.wrap(f"Decision rule: {rule.text}. p_c = probability of conformance, normal PDF "
                          "(JCGM 106:2012, 7.3-7.4); A = acceptance limits, R = limits beyond which the value "
                          "does not conform; w = guard band (µm).", 150)
    for j, line in enumerate(intro[:HEADER_ROW - 3]):
        book.text(ws, 2 + j, 1, line)
    # rule parameters (named inputs)
    r0 = HEADER_ROW - 1
    book.text(ws, r0, 1, "rule", font=HEADER_FONT)
    book.text(ws, r0, 2, rule.kind)
    params = []
    if rule.kind in ("guarded_acceptance", "guarded_rejection"):
        params.append(("decision_r", "r", rule.r, 0.0, 10.0, "guard band factor: w = r·U (JCGM 106:2012, 8.3.2)"))
    if rule.kind == "specific_risk":
        params.append(("decision_max_pfa", "max_pfa", rule.max_pfa, 1e-9, 0.5,
                       "largest probability of false acceptance: accept when p_c >= 1 - max_pfa (JCGM 106:2012, 9.3)"))
    if spec.k is not None:
        params.append(("decision_k", "k", spec.k, 0.1, 10.0, "coverage factor: U = k·u"))
    for j, (name, label, value, lo, hi, note) in enumerate(params):
        book.text(ws, r0, 3 + 2 * j, label, font=HEADER_FONT)
        book.input(ws, r0, 4 + 2 * j, name, value, lo=lo, hi=hi, note=note)
    h = HEADER_ROW
    newton = rule.kind == "specific_risk"
    extra = NEWTON_COLUMNS if newton else []
    book.header(ws, h, 1, COLUMNS + CHART_COLUMNS + extra, notes=[
        None, "the characteristic (Results row)", "measured value (input) or the task's value (from Results)",
        "the task's standard uncertainty (type B, ν = ∞)",
        "repeatability: standard deviation of the n repeated measurements whose mean is the value (input)",
        "number of repeated measurements (input)", "type A: u_A = s/√n (GUM 4.2.3)", "ν_A = n - 1 (GUM G.3.3)",
        "combined standard uncertainty u = √(u_task² + u_A²)",
        "effective degrees of freedom, Welch–Satterthwaite (GUM G.4.1, eq. (G.2b))",
        "coverage factor: t_95.45(⌊ν_eff⌋) with [decision] k_from_dof (GUM G.6.4), else the task's k",
        "expanded uncertainty U = k·u", "lower specification limit (input)",
        "upper specification limit (input)", "guard band; > 0: acceptance interval inside the tolerance",
        "lower acceptance limit A_L = T_L + w (JCGM 106:2012, 8.3)", "upper acceptance limit A_U = T_U - w",
        "below R_L: does not conform", "above R_U: does not conform",
        "probability of conformance p_c = Φ((T_U-y)/u) - Φ((T_L-y)/u) (JCGM 106:2012, eq. (12))",
        "the decision", "the zone of the measured value"] + [CHART_NOTE.format(name=c) for c in CHART_COLUMNS]
        + (["two-sided tolerance: h = (T_U - T_L)/(2u), half the tolerance in units of u"]
           + [NEWTON_NOTE + (" Start: s_0 = max(0, h - z)², z = Φ⁻¹(1 - max_pfa), the one-sided limit." if j == 0
                             else f" Step {j}.") for j in range(cf.NEWTON_STEPS + 1)] if newton else []))
    c = {name: j + 1 for j, name in enumerate(COLUMNS + CHART_COLUMNS + extra)}
    prior_rows: list[dict] = []
    for i, (t, d) in enumerate(zip(spec.tolerances, decisions)):
        r = h + 1 + i
        row = rows[t.label]
        rr = row.index + 2
        results_sheet = quote_sheet(row.sheet)
        rcols = sheet_cols[row.sheet]
        fmt_mm = mm_format(d["U_um"])
        at = lambda name: cell(r, c[name], absolute=False)  # noqa: E731
        ws.cell(r, c["item"]).value = i + 1
        book.text(ws, r, c["characteristic"], t.label)
        if t.measured_mm is not None:
            book.input(ws, r, c["value_mm"], f"{t.name_prefix}_measured_mm", t.measured_mm, fmt=fmt_mm,
                       note="measured value (input)")
        else:
            book.formula(ws, r, c["value_mm"], f"={results_sheet}!{cell(rr, rcols[row.value_col])}", fmt=fmt_mm,
                         note="the task's value (Results); give [[decision.tolerances]] measured_mm for a measured one")
            cache[at("value_mm")] = d["value_mm"]
        u_ref = f"{results_sheet}!{cell(rr, rcols[row.u_col])}"
        book.formula(ws, r, c["u_task_um"], f"={u_ref}" if row.u_scale == 1 else f"={u_ref}*{row.u_scale:g}",
                     fmt=FMT_UM)
        cache[at("u_task_um")] = d["u_task_um"]
        # the task's own coverage factor: U/u of its Results (budget, pointcloud) or [decision] k
        k_task = (f"{results_sheet}!{cell(rr, rcols[row.U_col])}/{u_ref}" if row.U_col is not None
                  else "decision_k")
        if t.type_a:
            book.input(ws, r, c["s_um"], f"{t.name_prefix}_s_um", t.s_um, lo=0.0, fmt=FMT_UM,
                       note="standard deviation of the repeated measurements (µm)")
            book.input(ws, r, c["n_repeats"], f"{t.name_prefix}_n_repeats", t.n_repeats, lo=2.0, fmt="0",
                       note="number of repeated measurements")
            book.formula(ws, r, c["u_A_um"], f"={at('s_um')}/SQRT({at('n_repeats')})", fmt=FMT_UM)
            book.formula(ws, r, c["nu_A"], f"={at('n_repeats')}-1", fmt="0")
            book.formula(ws, r, c["u_um"], f"=SQRT({at('u_task_um')}^2+{at('u_A_um')}^2)", fmt=FMT_UM)
            book.formula(ws, r, c["nu_eff"], f"={at('u_um')}^4/({at('u_A_um')}^4/{at('nu_A')})", fmt="0.00")
            cache.update({at("u_A_um"): d["u_A_um"], at("nu_A"): d["nu_A"], at("nu_eff"): d["nu_eff"]})
            if spec.k_from_dof:
                book.formula(ws, r, c["k"], f"=_xlfn.T.INV.2T(1-{dof.P_K2},INT({at('nu_eff')}))", fmt="0.000",
                             note="t_95.45(ν) for ν = ⌊ν_eff⌋ (GUM G.6.4)")
            else:
                book.formula(ws, r, c["k"], f"={k_task}", fmt="0.000")
            book.formula(ws, r, c["U_um"], f"={at('k')}*{at('u_um')}", fmt=FMT_UM)
        else:
            for name in ("s_um", "n_repeats", "u_A_um", "nu_A"):
                book.text(ws, r, c[name], "—")
            book.text(ws, r, c["nu_eff"], "∞")
            book.formula(ws, r, c["u_um"], f"={at('u_task_um')}", fmt=FMT_UM)
            book.formula(ws, r, c["k"], f"={k_task}", fmt="0.000")
            if row.U_col is not None:
                book.formula(ws, r, c["U_um"], f"={results_sheet}!{cell(rr, rcols[row.U_col])}", fmt=FMT_UM)
            else:
                book.formula(ws, r, c["U_um"], f"={at('k')}*{at('u_um')}", fmt=FMT_UM)
        cache[at("u_um")] = d["u_um"]
        cache[at("k")] = d["k"]
        cache[at("U_um")] = d["U_um"]
        tol = d
        for key in ("lsl_mm", "usl_mm"):
            if tol[key] is None:
                book.text(ws, r, c[key], "—")
            elif key in t.limit_cells:      # the kind's own tolerance cell (Characteristics)
                ccols = sheet_cols.get("Characteristics") or _results_cols(book, "Characteristics")
                expr = t.limit_cells[key].format(**{name: f"{quote_sheet('Characteristics')}!{cell(rr, j)}"
                                                    for name, j in ccols.items() if name.isidentifier()})
                book.formula(ws, r, c[key], f"={expr}", fmt=fmt_mm,
                             note=("the tolerance typed on 'Characteristics'" if expr != "0" else
                                   "a margin (zone - value) conforms when >= 0"))
                cache[at(key)] = tol[key]
            else:
                book.input(ws, r, c[key], f"{t.name_prefix}_{key}", tol[key], fmt=fmt_mm,
                           note=("lower" if key == "lsl_mm" else "upper") + " specification limit (mm)")
        y, u, U = at("value_mm"), at("u_um"), at("U_um")
        lsl = at("lsl_mm") if tol["lsl_mm"] is not None else None
        usl = at("usl_mm") if tol["usl_mm"] is not None else None
        w = {"simple": "=0", "iso14253": f"={U}", "guarded_acceptance": f"=decision_r*{U}",
             "guarded_rejection": f"=-(decision_r*{U})",
             "specific_risk": f"=_xlfn.NORM.S.INV(1-decision_max_pfa)*{u}"}[rule.kind]
        w_note = None
        if newton and lsl is not None and usl is not None:
            w, w_note = _newton_cells(book, ws, r, c, at, d, lsl, usl, u, cache)
        elif newton:
            for name in NEWTON_COLUMNS:
                book.text(ws, r, c[name], "—")
            w_note = "one-sided tolerance: w = z·u, z = Φ⁻¹(1 - max_pfa) (JCGM 106:2012, 7.3 Table 1): p_c = 1 - max_pfa on A"
        book.formula(ws, r, c["w_um"], w, fmt=FMT_UM, note=w_note)
        cache[at("w_um")] = d["w_um"]
        wc = at("w_um")
        acc = [None, None]
        sides = ((lsl, "+", "A_L_mm", "R_L_mm"), (usl, "-", "A_U_mm", "R_U_mm"))
        for j, (lim, sign, a_name, r_name) in enumerate(sides):
            if lim is None:
                book.text(ws, r, c[a_name], "—")
                book.text(ws, r, c[r_name], "—")
                continue
            book.formula(ws, r, c[a_name], f"={lim}{sign}{wc}/1000", fmt=fmt_mm)
            cache[at(a_name)] = d["acceptance_limits_mm"][j]
            acc[j] = at(a_name)
            other = "-" if sign == "+" else "+"
            if rule.kind == "iso14253":
                book.formula(ws, r, c[r_name], f"={lim}{other}{U}/1000", fmt=fmt_mm)
                cache[at(r_name)] = (d["lsl_mm"] - d["U_um"] / 1000) if j == 0 else (d["usl_mm"] + d["U_um"] / 1000)
            else:
                book.formula(ws, r, c[r_name], f"={at(a_name)}", fmt=fmt_mm)
                cache[at(r_name)] = d["acceptance_limits_mm"][j]
        terms = []
        if usl is not None:
            terms.append(norm_s_dist(f"({usl}-{y})*1000/{u}"))
        if lsl is not None:
            terms.append(norm_s_dist(f"({lsl}-{y})*1000/{u}"))
        pc = terms[0] if usl is not None else f"1-{terms[0]}"
        if len(terms) == 2:
            pc = f"{terms[0]}-{terms[1]}"
        book.formula(ws, r, c["p_c"], "=" + pc, fmt=FMT_P,
                     note="JCGM 106:2012, 7.3 eq. (9)-(10) and 7.4 eq. (12); u in µm, limits in mm")
        cache[at("p_c")] = d["p_c"]
        inside_acc = _inside(y, acc[0], acc[1])
        rl = at("R_L_mm") if lsl is not None else None
        ru = at("R_U_mm") if usl is not None else None
        if rule.kind == "iso14253":
            outside_rej = _outside(y, rl, ru)
            outcome = (f'=IF({inside_acc},"{cf.CONFORMS}",IF({outside_rej},"{cf.DOES_NOT_CONFORM}",'
                       f'"{cf.UNDECIDED}"))')
            zone = (f'=IF({inside_acc},"conformance zone",IF({outside_rej},"non-conformance zone",'
                    f'"uncertainty range"))')
        elif rule.kind == "specific_risk":
            ok = f"{at('p_c')}>=1-decision_max_pfa"
            outcome = f'=IF({ok},"{cf.CONFORMS}","{cf.DOES_NOT_CONFORM}")'
            zone = f'=IF({ok},"acceptance zone","rejection zone")'
        else:
            outcome = f'=IF({inside_acc},"{cf.CONFORMS}","{cf.DOES_NOT_CONFORM}")'
            zone = f'=IF({inside_acc},"acceptance zone","rejection zone")'
        book.formula(ws, r, c["outcome"], outcome, fmt=None)
        book.formula(ws, r, c["zone"], zone, fmt=None)
        cache[at("outcome")] = d["outcome"]
        cache[at("zone")] = d["zone"]
        if t.process_sd_um is not None:
            prior_rows.append({"item": i + 1, "label": t.label, "prefix": t.name_prefix, "decision": d,
                               "u": u, "lsl": lsl, "usl": usl, "A_L": acc[0], "A_U": acc[1]})
        # chart data: each row on the scale of its own tolerance (CHART_NOTE)
        off, ref, scale, off_v, ref_v, scale_v = chart_scale(lsl, usl, U, y, d)

        def rel(x: str) -> str:
            return f"={off}({x}-{ref})/{scale}" if off else f"=({x}-{ref})/{scale}"

        y_v = off_v + (d["value_mm"] - ref_v) / scale_v
        u_rel = d["U_um"] / cf.UM_PER_MM / scale_v
        book.formula(ws, r, c["y_rel"], rel(y), fmt="0.000")
        book.formula(ws, r, c["y_plus_U_rel"], f"={at('y_rel')}+{U}/1000/{scale}", fmt="0.000")
        book.formula(ws, r, c["y_minus_U_rel"], f"={at('y_rel')}-{U}/1000/{scale}", fmt="0.000")
        cache.update({at("y_rel"): y_v, at("y_plus_U_rel"): y_v + u_rel, at("y_minus_U_rel"): y_v - u_rel})
        for lim, j, name, aname in ((lsl, 0, "lsl_rel", "A_L_rel"), (usl, 1, "usl_rel", "A_U_rel")):
            if lim is None:
                continue
            book.formula(ws, r, c[name], rel(lim), fmt="0.000")
            book.formula(ws, r, c[aname], rel(acc[j]), fmt="0.000")
            cache[at(name)] = off_v + (d["lsl_mm" if j == 0 else "usl_mm"] - ref_v) / scale_v
            cache[at(aname)] = off_v + (d["acceptance_limits_mm"][j] - ref_v) / scale_v
    n = len(spec.tolerances)
    last = h + n
    xs = Reference(ws, min_col=c["item"], min_row=h + 1, max_row=last)

    def ref_of(name):
        return Reference(ws, min_col=c[name], min_row=h + 1, max_row=last)

    series = [ChartSeries("measured value", xs, ref_of("y_rel"), colour="000000"),
              ChartSeries("value + U", xs, ref_of("y_plus_U_rel"), colour="1F77B4"),
              ChartSeries("value − U", xs, ref_of("y_minus_U_rel"), colour="1F77B4"),
              ChartSeries("lower specification limit", xs, ref_of("lsl_rel"), colour="D62728", symbol="dash"),
              ChartSeries("upper specification limit", xs, ref_of("usl_rel"), colour="D62728", symbol="dash"),
              ChartSeries("lower acceptance limit", xs, ref_of("A_L_rel"), colour="2CA02C", symbol="dash"),
              ChartSeries("upper acceptance limit", xs, ref_of("A_U_rel"), colour="2CA02C", symbol="dash")]
    book.scatter(ws, f"B{last + 3}", "Measured value ± U against the specification (red) and acceptance (green) "
                 "limits, each row on its own tolerance's scale", "item (row of the table)",
                 "position in the tolerance (limits at ±1)", series, width=24, height=11, x_min=0)
    for name, width in (("characteristic", 18), ("outcome", 18), ("zone", 22)):
        ws.column_dimensions[col(c[name])].width = width
    bottom = last + 26
    if prior_rows:
        top = last + 28
        risks.write_node_table(book, ws, top + 1, len(COLUMNS) + 2)
        bottom = risks.write_rows(book, ws, top, prior_rows, cache)
    book.print_setup(ws, landscape=True, title_rows=h, area=f"A1:{col(c['zone'])}{bottom}")
    return {SHEET: cache}


NEWTON_NOTE = ("exact specific-risk acceptance limits A = midpoint ± d·u of a two-sided tolerance: the root "
               "s = d² of Φ(h - √s) + Φ(h + √s) - 2 + max_pfa = 0 (p_c = 1 - max_pfa on A, JCGM 106:2012, "
               "7.4 eq. (12)) by Newton's method, s_j+1 = max(0, s_j - G/G'), G' = (φ(h+d) - φ(h-d))/(2d), "
               "-h·φ(h) at s = 0 (xlfuncs.conformity.specific_risk_iterates; docs/errata.md).")


def _newton_cells(book: Book, ws, r: int, c: dict[str, int], at, d: dict, lsl: str, usl: str, u: str,
                  cache: dict[str, Any]) -> tuple[str, str]:
    """The Newton columns of one two-sided row of the specific-risk rule and the formula of its
    guard band w = (h - √s_N)·u (or half the tolerance when even the midpoint falls short)."""
    hc = at("h_half_tol_per_u")
    book.formula(ws, r, c["h_half_tol_per_u"], f"=({usl}-{lsl})*1000/(2*{u})", fmt="0.000000")
    half_um = (d["usl_mm"] - d["lsl_mm"]) * cf.UM_PER_MM / 2.0
    h_val = half_um / d["u_um"]
    cache[hc] = h_val
    iterates = cf.specific_risk_iterates(h_val, d["max_pfa"])
    book.formula(ws, r, c["newton_s0"], f"=MAX(0,{hc}-_xlfn.NORM.S.INV(1-decision_max_pfa))^2", fmt="0.000000")
    for j in range(1, cf.NEWTON_STEPS + 1):
        s = at(f"newton_s{j - 1}")
        g = (f"{norm_s_dist(f'{hc}-SQRT({s})')}+{norm_s_dist(f'{hc}+SQRT({s})')}"
             f"-2+decision_max_pfa")
        dg = (f"IF({s}>0,({norm_s_dist(f'{hc}+SQRT({s})', False)}-{norm_s_dist(f'{hc}-SQRT({s})', False)})"
              f"/(2*SQRT({s})),-{hc}*{norm_s_dist(hc, False)})")
        book.formula(ws, r, c[f"newton_s{j}"], f"=MAX(0,{s}-({g})/({dg}))", fmt="0.000000")
    for j, v in enumerate(iterates):
        cache[at(f"newton_s{j}")] = v
    last = at(f"newton_s{cf.NEWTON_STEPS}")
    w = (f"=IF({norm_s_dist(hc)}-{norm_s_dist(f'-{hc}')}<1-decision_max_pfa,"
         f"({usl}-{lsl})*1000/2*(1+1E-9),({hc}-SQRT({last}))*{u})")
    note = ("two-sided tolerance: w = (h - √s_N)·u from the Newton columns at the right, so that p_c = 1 - max_pfa "
            "exactly on A (JCGM 106:2012, 7.4 eq. (12)); half the tolerance (nothing accepted) when even the "
            "midpoint has p_c < 1 - max_pfa")
    return w, note


def chart_scale(lsl: str | None, usl: str | None, U: str, y: str, d: dict
                ) -> tuple[str, str, str, float, float, float]:
    """The chart's scale of one row, y = off + (x - ref)/scale (x, ref, scale in mm): two-sided
    ref = the midpoint, scale = half the tolerance (limits at ±1); one-sided ref = the limit,
    off = ±1, scale = max(4U, |value - limit|) (a one-sided tolerance has no width: a value
    within 4U of its limit on a linear scale, one farther inside at 0, one farther outside at ±2).
    Formula texts and values."""
    if lsl is not None and usl is not None:
        return ("", f"({lsl}+{usl})/2", f"(({usl}-{lsl})/2)", 0.0, (d["lsl_mm"] + d["usl_mm"]) / 2,
                (d["usl_mm"] - d["lsl_mm"]) / 2)
    four_u = 4 * d["U_um"] / cf.UM_PER_MM
    t, t_v, off, off_v = (usl, d["usl_mm"], "1+", 1.0) if usl is not None else (lsl, d["lsl_mm"], "-1+", -1.0)
    assert t is not None
    return (off, t, f"MAX(4*{U}/1000,ABS({y}-{t}))", off_v, t_v, max(four_u, abs(d["value_mm"] - t_v)))


def mm_format(U_um: float) -> str:
    """The number format of a row's values and limits in mm: 0.1 µm (FMT_MM), or finer so that
    U below 1 µm still shows its two significant digits (GUM 7.2.6): U = 0.64 µm -> 0.00001 mm."""
    try:
        dec = decimals_for(U_um) + 3
    except ModelError:
        return FMT_MM
    return FMT_MM if dec <= 4 else "0." + "0" * min(dec, 9)


def _inside(y: str, lo: str | None, hi: str | None) -> str:
    parts = ([f"{y}>={lo}"] if lo else []) + ([f"{y}<={hi}"] if hi else [])
    return parts[0] if len(parts) == 1 else f"AND({','.join(parts)})"


def _outside(y: str, lo: str | None, hi: str | None) -> str:
    parts = ([f"{y}<{lo}"] if lo else []) + ([f"{y}>{hi}"] if hi else [])
    return parts[0] if len(parts) == 1 else f"OR({','.join(parts)})"
