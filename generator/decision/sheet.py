"""The ``Decision`` sheet of a workbook: the conformity decisions of
:mod:`generator.decision.decide` as live formulas.

The sheet computes everything from the cells of the task's records
(:class:`generator.quantities.Quantity`: the kind's Results, or another sheet of its own) and its
own inputs (limits, measured values, r, max_pfa, k) with formulas all four engines accept
(``_xlfn.NORM.DIST`` through ``xlref.norm_s_dist``, ``_xlfn.NORM.S.INV``, ``TDIST``, measured in
``docs/engines.md``); JCGM 106:2012, 7.3-7.4.  Each row gives the rule's outcome (``outcome``,
``zone``) and, separately, what the value and its U prove whatever the rule (``conformity``,
``conformity_zone``: ISO 14253-1:2017, 5.2, 5.3), and the coverage probability of its k.
"""

from __future__ import annotations

import textwrap
from typing import Any

from openpyxl.chart import Reference

from cmmwb.xlfuncs import conformity as cf
from cmmwb.xlfuncs import dof
from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.statement import decimals_for

from ..quantities import Quantity
from ..workbook.book import Book, ChartSeries
from ..workbook.styles import FMT_MM, FMT_UM, HEADER_FONT, TITLE_FONT
from ..workbook.xlref import cell, col, norm_s_dist
from . import risks
from .decide import DecisionSpec

SHEET = "Decision"
FMT_P = "0.000000"
HEADER_ROW = 7
FIRST_ROW = HEADER_ROW + 1     #: the first characteristic's row
#: columns of the decision table (first row of the table: headers with units)
COLUMNS = ["item", "characteristic", "value_mm", "u_task_um", "s_um", "n_repeats", "u_A_um", "nu_A", "u_um", "nu_eff",
           "k", "U_um", "lsl_mm", "usl_mm", "w_um", "A_L_mm", "A_U_mm", "R_L_mm", "R_U_mm", "p_c", "outcome",
           "zone", "conformity", "conformity_zone", "coverage_probability"]


def column(name: str) -> int:
    """1-based column of the Decision table (``COLUMNS``, then the chart data ``CHART_COLUMNS``)."""
    return (COLUMNS + CHART_COLUMNS).index(name) + 1
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


COLUMN_NOTES = [
    None, "the characteristic (a result of the task)",
    "measured value (input) or the task's value (from its Results)",
    "the task's standard uncertainty (type B, ν = ∞)",
    "repeatability: standard deviation of the n repeated measurements whose mean is the value (input)",
    "number of repeated measurements (input)", "type A: u_A = s/√n (GUM 4.2.3)", "ν_A = n - 1 (GUM G.3.3)",
    "combined standard uncertainty u = √(u_task² + u_A²)",
    "effective degrees of freedom, Welch–Satterthwaite (GUM G.4.1, eq. (G.2b))",
    "coverage factor: t_95.45(⌊ν_eff⌋) with [decision] k_from_dof (GUM G.6.4), else the task's k",
    "expanded uncertainty U = k·u", "lower specification limit", "upper specification limit",
    "guard band; > 0: acceptance interval inside the tolerance",
    "lower acceptance limit A_L = T_L + w (JCGM 106:2012, 8.3)", "upper acceptance limit A_U = T_U - w",
    "lower non-conformance limit R_L = T_L - U: below it non-conformity is proven (ISO 14253-1:2017, 5.3), "
    "whatever the rule",
    "upper non-conformance limit R_U = T_U + U: above it non-conformity is proven (ISO 14253-1:2017, 5.3)",
    "probability of conformance p_c = Φ((T_U-y)/u) - Φ((T_L-y)/u) (JCGM 106:2012, eq. (12))",
    "the decision rule's outcome: accepted / rejected (binary rules), conforms / does not conform / cannot be "
    "decided (the ISO 14253-1 rule)", "the rule's zone of the value",
    "what the value and U prove, whatever the rule (ISO 14253-1:2017, 5.2, 5.3): conformity proven in "
    "[T_L + U, T_U - U], non-conformity proven outside [T_L - U, T_U + U], else neither",
    "ISO 14253-1 zone of the value: conformance zone, uncertainty range, non-conformance zone",
    "coverage probability of k: 2Φ(k) - 1 for ν_eff = ∞, 1 - TDIST(k, ⌊ν_eff⌋, 2) for a finite ν_eff "
    "(GUM G.1.3, G.3.2, G.6.4)"]


def write_sheet(book: Book, spec: DecisionSpec, quantities: list[Quantity], decisions: list[dict]) -> dict[str, int]:
    """The ``Decision`` sheet; the values the core computed (``decisions``) are cached in its
    formula cells.  Returns the row of each decided record (label -> row)."""
    by_label = {q.label: q for q in quantities}
    ws = book.sheet(SHEET)
    cache: dict[str, Any] = {}
    rule = spec.rule
    # the title fits the columns item and characteristic, which print on every page across; the
    # rule in words right of them (on the first page only)
    book.text(ws, 1, 1, "Decisions", font=TITLE_FONT)
    intro = textwrap.wrap(f"Decision rule: {rule.text}. p_c = probability of conformance, normal PDF "
                          "(JCGM 106:2012, 7.3-7.4); A = acceptance limits of the rule; R = non-conformance "
                          "limits T ∓ U (ISO 14253-1); w = guard band (µm). 'outcome' is the rule's, "
                          "'conformity' what value and U prove.", 115)
    for j, line in enumerate(intro[:HEADER_ROW - 2]):
        book.text(ws, 1 + j, 3, line)
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
    book.header(ws, h, 1, COLUMNS + CHART_COLUMNS + extra, notes=COLUMN_NOTES
                + [CHART_NOTE.format(name=c) for c in CHART_COLUMNS]
                + (["two-sided tolerance: h = (T_U - T_L)/(2u), half the tolerance in units of u"]
                   + [NEWTON_NOTE + (" Start: s_0 = max(0, h - z)², z = Φ⁻¹(1 - max_pfa), the one-sided limit."
                                     if j == 0 else f" Step {j}.") for j in range(cf.NEWTON_STEPS + 1)]
                   if newton else []))
    c = {name: j + 1 for j, name in enumerate(COLUMNS + CHART_COLUMNS + extra)}
    prior_rows: list[dict] = []
    rows: dict[str, int] = {}
    for i, (t, d) in enumerate(zip(spec.tolerances, decisions)):
        r = h + 1 + i
        rows[t.label] = r
        q = by_label[t.label]
        assert q.cells is not None, t.label
        fmt_mm = mm_format(d["U_um"])
        at = lambda name: cell(r, c[name], absolute=False)  # noqa: E731
        ws.cell(r, c["item"]).value = i + 1
        book.text(ws, r, c["characteristic"], t.label)
        if t.measured_mm is not None:
            book.input(ws, r, c["value_mm"], f"{t.name_prefix}_measured_mm", t.measured_mm, fmt=fmt_mm,
                       note="measured value (input)")
        else:
            book.formula(ws, r, c["value_mm"], f"={q.cells.value}", fmt=fmt_mm,
                         note="the task's value; give [[decision.tolerances]] measured_mm for a measured one")
            cache[at("value_mm")] = d["value_mm"]
        u_ref = q.cells.u
        book.formula(ws, r, c["u_task_um"], f"={u_ref}" if q.cells.u_scale == 1 else f"={u_ref}*{q.cells.u_scale:g}",
                     fmt=FMT_UM)
        cache[at("u_task_um")] = d["u_task_um"]
        # the task's own coverage factor: U/u of its cells, or the [decision] k
        k_task = (f"{q.cells.U}/{u_ref}" if q.own_U and q.cells.U is not None
                  else q.cells.k if q.own_U and q.cells.k else "decision_k")
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
            if q.own_U and q.cells.U is not None:
                book.formula(ws, r, c["U_um"], f"={q.cells.U}", fmt=FMT_UM)
            else:
                book.formula(ws, r, c["U_um"], f"={at('k')}*{at('u_um')}", fmt=FMT_UM)
        cache[at("u_um")] = d["u_um"]
        cache[at("k")] = d["k"]
        cache[at("U_um")] = d["U_um"]
        tol = d
        for key in ("lsl_mm", "usl_mm"):
            if tol[key] is None:
                book.text(ws, r, c[key], "—")
            elif key in t.limit_cells:      # the kind's own tolerance cell (a drawing's characteristic)
                expr = t.limit_cells[key]
                book.formula(ws, r, c[key], f"={expr}", fmt=fmt_mm,
                             note=("the tolerance typed on its own sheet" if expr != "0" else
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
            book.formula(ws, r, c[r_name], f"={lim}{other}{U}/1000", fmt=fmt_mm)
            cache[at(r_name)] = d["non_conformance_limits_mm"][j]
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
        # what value and U prove (ISO 14253-1:2017, 5.2, 5.3), whatever the rule
        proven = _inside(y, f"{lsl}+{U}/1000" if lsl else None, f"{usl}-{U}/1000" if usl else None)
        disproven = _outside(y, at("R_L_mm") if lsl else None, at("R_U_mm") if usl else None)
        book.formula(ws, r, c["conformity"], f'=IF({proven},"{cf.CONFORMITY_PROVEN}",IF({disproven},'
                     f'"{cf.NONCONFORMITY_PROVEN}","{cf.NEITHER_PROVEN}"))', fmt=None)
        book.formula(ws, r, c["conformity_zone"], f'=IF({proven},"{cf.CONFORMITY_ZONES[cf.CONFORMITY_PROVEN]}",'
                     f'IF({disproven},"{cf.CONFORMITY_ZONES[cf.NONCONFORMITY_PROVEN]}",'
                     f'"{cf.CONFORMITY_ZONES[cf.NEITHER_PROVEN]}"))', fmt=None)
        cache[at("conformity")] = d["conformity"]
        cache[at("conformity_zone")] = d["conformity_zone"]
        inside_acc = _inside(y, acc[0], acc[1])
        if rule.kind == "iso14253":
            outcome = (f'=IF({proven},"{cf.CONFORMS}",IF({disproven},"{cf.DOES_NOT_CONFORM}",'
                       f'"{cf.UNDECIDED}"))')
            zone = (f'=IF({proven},"conformance zone",IF({disproven},"non-conformance zone",'
                    f'"uncertainty range"))')
        else:
            ok = f"{at('p_c')}>=1-decision_max_pfa" if rule.kind == "specific_risk" else inside_acc
            outcome = f'=IF({ok},"{cf.ACCEPTED}","{cf.REJECTED}")'
            zone = f'=IF({ok},"acceptance zone","rejection zone")'
        book.formula(ws, r, c["outcome"], outcome, fmt=None)
        book.formula(ws, r, c["zone"], zone, fmt=None)
        cache[at("outcome")] = d["outcome"]
        cache[at("zone")] = d["zone"]
        nu_eff, k = at("nu_eff"), at("k")
        book.formula(ws, r, c["coverage_probability"],
                     f"=IF(ISNUMBER({nu_eff}),1-TDIST({k},INT({nu_eff}),2),2*{norm_s_dist(k)}-1)", fmt="0.0000",
                     note="GUM G.1.3, G.3.2: the probability that y ± U covers the value (t with ⌊ν_eff⌋ "
                          "degrees of freedom, normal for ν_eff = ∞)")
        cache[at("coverage_probability")] = d["coverage_probability"]
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
    book.scatter(ws, f"C{last + 3}", "Measured value ± U against the specification (red) and acceptance (green) "
                 "limits, each row on its own tolerance's scale", "item (row of the table)",
                 "position in the tolerance (limits at ±1)", series, width=24, height=11, x_min=0)
    _widths(ws, c, h, last, cache)
    bottom = last + 26
    if prior_rows:
        top = last + 28
        risks.write_node_table(book, ws, top + 1, len(COLUMNS) + 2)
        bottom = risks.write_rows(book, ws, top, prior_rows, cache)
    book.cache_cells(ws, cache)
    # the chart on the table's page when both fit, else on the next page (never split)
    breaks = [last + 2] if last + 2 + CHART_ROWS > ROWS_PER_PAGE else []
    book.print_setup(ws, landscape=True, title_rows=h, title_columns="A:B", min_scale=READABLE_SCALE,
                     area=f"A1:{col(c['coverage_probability'])}{bottom}", fit_widths=False, footer_pt=10,
                     row_breaks=breaks)
    return rows


def _widths(ws, c: dict[str, int], h: int, last: int, cache: dict[str, Any]) -> None:
    """Column widths of the decision table that fit what each column shows (its header, texts,
    and numbers as their format shows the values the core computed), no wider: the table prints
    at a fixed scale, pages across (the other columns: as fit_widths makes them)."""
    from ..workbook.pagesetup import display_len, fit_widths

    fit_widths(ws)
    for name in COLUMNS:
        j = c[name]
        want = 1.1 * len(name) + 1
        for r in range(h + 1, last + 1):
            x = ws.cell(row=r, column=j)
            v = cache.get(x.coordinate, x.value if x.data_type != "f" else None)
            if isinstance(v, str):
                want = max(want, len(v))
            elif isinstance(v, (int, float)):
                want = max(want, display_len(v, x.number_format))
        ws.column_dimensions[col(j)].width = round(min(want + 2.0, 40), 1)


#: the print scale of the Decision sheet: 11 pt text prints at 9.4 pt, a chart's 10 pt axis labels
#: at 8.5 pt (as many pages across as that needs, the item and characteristic columns repeated on
#: each)
READABLE_SCALE = 0.85
#: rows of a printed page at that scale (A4 landscape, 17.9 cm between the margins, rows of
#: 0.45 cm: 47; less a margin) and the rows the chart (11 cm) covers
ROWS_PER_PAGE = 44
CHART_ROWS = 26


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


def chart_scale_values(d: dict) -> tuple[float, float, float]:
    """(offset, reference, scale) of :func:`chart_scale` for the decision ``d`` (JSON): a value
    x (mm) is at offset + (x - reference)/scale."""
    lsl, usl = d["lsl_mm"], d["usl_mm"]
    if lsl is not None and usl is not None:
        return 0.0, (lsl + usl) / 2, (usl - lsl) / 2
    four_u = 4 * d["U_um"] / cf.UM_PER_MM
    t, off = (usl, 1.0) if usl is not None else (lsl, -1.0)
    return off, t, max(four_u, abs(d["value_mm"] - t))


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
