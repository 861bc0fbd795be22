"""The calibration book's report page (``Summary``, :mod:`generator.workbook.report_page`) and
the MPE verdict as a live decision (docs/calibrate.md section 3).

* :func:`decision_block`: C_max <= 1 decided with u(C_max) under the rule of ``--rule`` on the
  Model sheet, live formulas of the MPE sheet's ``C_max`` (the same outcome, conformity statement,
  p_c and limits as :func:`xlfuncs.calibration.mpe_decision`, the JSON's
  ``mpe_check.fitted.decision``);
* :func:`write_page`: the header (the task, the SHA-256 of the task file and the recordings, the
  time, the version), one record per result (the estimated hyper-parameters, the effects' estimates,
  C_max with its decision and tolerance bar), the rule in words.
"""

from __future__ import annotations

from cmmwb.xlfuncs import conformity as cf

from ..quantities import Quantity
from ..workbook.book import Book
from ..workbook.report_page import Live, PageHeader, PageRow, write_report_page
from ..workbook.xlref import norm_s_dist

#: the outcome of each rule, a formula of the block's names (``conformity``: the same for every rule)
OUTCOME = {
    "iso14253": f'IF(C_max<=1-U_C_max,"{cf.CONFORMS}",IF(C_max>1+U_C_max,"{cf.DOES_NOT_CONFORM}",'
                f'"{cf.UNDECIDED}"))',
    "specific_risk": f'IF(p_c_C_max>=1-mpe_max_pfa,"{cf.ACCEPTED}","{cf.REJECTED}")',
}
BINARY = f'IF(C_max<=A_U_C_max,"{cf.ACCEPTED}","{cf.REJECTED}")'
GUARD = {"simple": "0", "iso14253": "U_C_max", "guarded_acceptance": "mpe_rule_r*U_C_max",
         "guarded_rejection": "-mpe_rule_r*U_C_max", "specific_risk": "_xlfn.NORM.S.INV(1-mpe_max_pfa)*u_C_max"}
CONFORMITY = (f'IF(C_max<=1-U_C_max,"{cf.CONFORMITY_PROVEN}",IF(C_max>1+U_C_max,"{cf.NONCONFORMITY_PROVEN}",'
              f'"{cf.NEITHER_PROVEN}"))')
ZONE = (f'IF(MPE_conformity="{cf.CONFORMITY_PROVEN}","{cf.CONFORMITY_ZONES[cf.CONFORMITY_PROVEN]}",'
        f'IF(MPE_conformity="{cf.NONCONFORMITY_PROVEN}","{cf.CONFORMITY_ZONES[cf.NONCONFORMITY_PROVEN]}",'
        f'"{cf.CONFORMITY_ZONES[cf.NEITHER_PROVEN]}"))')


def decision_block(book: Book, ws, row: int, dec: dict, u_from: str) -> int:
    """The MPE decision from ``row`` on (column A labels, B cells, C units), defined names for
    the report page; returns the next free row."""
    rule = dec["rule"]
    book.text(ws, row, 1, f"MPE decision: C_max <= 1, {dec['rule_name']}")
    r = row + 1

    def put(label: str, name: str, formula: str, value, fmt: str | None, note: str, unit: str | None = "1") -> None:
        nonlocal r
        book.text(ws, r, 1, label)
        book.formula(ws, r, 2, f"={formula}", name=name, fmt=fmt, value=value, note=note)
        if unit is not None:          # a word result has none: it runs on into the empty cells right of it
            book.text(ws, r, 3, unit)
        r += 1

    book.text(ws, r, 1, "u_C_max")
    book.number(ws, r, 2, dec["u"], fmt="0.0000", computed=True)
    book.define("u_C_max", f"'{ws.title}'!$B${r}")
    book.note(ws.cell(row=r, column=2), "u(C_max), computed by the core from " + u_from)
    book.text(ws, r, 3, "1")
    r += 1
    book.text(ws, r, 1, "k_C_max")
    book.input(ws, r, 2, "k_C_max", dec["k"], lo=0.0, fmt="0.00", note="coverage factor of U(C_max) = k·u(C_max)")
    book.text(ws, r, 3, "1")
    r += 1
    if rule in ("guarded_acceptance", "guarded_rejection"):
        book.text(ws, r, 1, "mpe_rule_r")
        book.input(ws, r, 2, "mpe_rule_r", dec["r"], lo=0.0, fmt="0.00", note="guard band w = r·U")
        r += 1
    if rule == "specific_risk":
        book.text(ws, r, 1, "mpe_max_pfa")
        book.input(ws, r, 2, "mpe_max_pfa", dec["max_pfa"], lo=0.0, hi=0.5, fmt="0.000",
                   note="the largest probability of false acceptance (JCGM 106:2012, 9.3)")
        r += 1
    put("U_C_max", "U_C_max", "k_C_max*u_C_max", dec["U"], "0.0000", "expanded uncertainty of C_max")
    put("p_c", "p_c_C_max", norm_s_dist("(1-C_max)/u_C_max"), dec["p_c"], "0.0000",
        "probability that C_max <= 1 (JCGM 106:2012, 7.3, one-sided)")
    put("w", "w_C_max", GUARD[rule], dec["w"], "0.0000", "guard band of the rule (positive: inside the limit)")
    put("A_U", "A_U_C_max", "1-w_C_max", dec["acceptance_limit"], "0.0000", "acceptance limit of C_max")
    put("decision", "MPE_decision", OUTCOME.get(rule, BINARY), dec["outcome"], None,
        "the rule's outcome: " + cf.RULE_TEXT[rule], unit=None)
    put("conformity", "MPE_conformity", CONFORMITY, dec["conformity"], None,
        "what C_max and U prove whatever the rule (ISO 14253-1:2017, 5.2, 5.3)", unit=None)
    put("zone", "MPE_zone", ZONE, dec["conformity_zone"], None, "the ISO 14253-1 zone of C_max", unit=None)
    # the tolerance bar of a one-sided limit, as on the Decision sheets: +1 + (x - 1)/s,
    # s = max(4U, |C_max - 1|)
    s = max(4 * dec["U"], abs(dec["value"] - 1.0))
    put("bar_scale", "bar_s_C_max", "MAX(4*U_C_max,ABS(C_max-1))", s, "0.0000",
        "the scale of the tolerance bar (report page): one-sided limit at +1")
    return r + 1


def write_page(book: Book, result: dict, results_rows: dict[str, int], loop_rows: dict[str, int], mpe: bool) -> None:
    """The report page of the calibration: ``results_rows`` = Results row of each hyper-parameter,
    ``loop_rows`` = Loop row of each effect parameter (estimate in D, u in E)."""
    prov = result.get("provenance") or {}
    lines = [("task", f"calibration of the machine's hyper-parameters (cmmwb calibrate); start: "
                      f"{result['simulation']}")]
    tf = prov.get("task_file")
    if tf:
        lines.append(("task file", f"{tf['name']}  SHA-256 {tf['sha256']}"))
    for f in prov.get("input_files", []):
        lines.append(("input file", f"{f['name']}  SHA-256 {f['sha256']}"))
    lines.append(("built", f"{prov.get('built_utc', '')} (UTC) by cmmwb {prov.get('cmmwb_version', '')}"))
    lines.append(("effects", f"{', '.join(sorted({e['name'] for e in result['effects']})) or 'none'}; fed back: "
                             f"{result['feedback']}"))
    files = ", ".join(result["recordings"])
    rows = []

    def results_cell(label: str, column: str) -> str:
        return f"'Results'!${column}${results_rows[label]}"

    for h in result["hyper_parameters"]:
        if h["status"] != "estimated" or h["name"] not in results_rows:
            continue
        q = Quantity(h["name"], h["estimate"], h["unit"], h["u"], h["unit"], 2.0, h["unit"],
                     value_source=f"REML estimate from {files} (the locator's effects as fixed effects)",
                     u_source="the inverse observed information of the REML log-likelihood (delta method from log)")
        rows.append(PageRow(q, value=Live(results_cell(h["name"], "B"), h["estimate"]),
                            U=Live(f"2*{results_cell(h['name'], 'C')}", 2 * h["u"]), k=Live("2", 2.0),
                            note="estimate (no tolerance)", source=["value: " + q.value_source, "U: " + q.u_source]))
    for e in result["effects"]:
        for lb, b, u in zip(e["labels"], e["estimate"], e["u"]):
            key = f"{e['file']} {e['name']} {lb}"
            if key not in loop_rows or not u or u <= 0:
                continue
            unit = e["unit"].replace("um", "µm").replace("urad", "µrad")
            label = e["name"] if lb == e["name"] else f"{e['name']} {lb}"
            q = Quantity(label, b, unit, u, unit, 2.0, unit,
                         value_source=f"GLS estimate of the effect in {e['file']} at the fitted model (Loop sheet)",
                         u_source="the GLS covariance at the fitted model")
            r = loop_rows[key]
            rows.append(PageRow(q, value=Live(f"'Loop'!$D${r}", b), U=Live(f"2*'Loop'!$E${r}", 2 * u),
                                k=Live("2", 2.0), note=f"effect, fed back: {result['feedback']}",
                                source=["value: " + q.value_source, "U: " + q.u_source]))
    rule = None
    if mpe and result["mpe_check"]:
        m = result["mpe_check"]["fitted"]
        d = m["decision"]
        src = [f"value: C_max = max K u(d)/(A + d/B) of the fitted task (Forbes 2025 eq. 36; MPE sheet), at "
               f"d = {m['d_at_max_mm']:.0f} mm", "U: k·u(C_max), u from " + m["u_C_max_from"]]
        if d["U"] is not None:
            rule = d["rule_text"]
            q = Quantity("C_max", d["value"], "", d["u"], "", d["k"], "", usl=1.0,
                         value_source=src[0][7:], u_source=src[1][3:])
            s = max(4 * d["U"], abs(d["value"] - 1.0))
            y = 1 + (d["value"] - 1) / s
            bar = {"y": Live("1+(C_max-1)/bar_s_C_max", y),
                   "y_minus": Live("1+(C_max-U_C_max-1)/bar_s_C_max", y - d["U"] / s),
                   "y_plus": Live("1+(C_max+U_C_max-1)/bar_s_C_max", y + d["U"] / s),
                   "usl": Live("1", 1.0), "a_u": Live("1+(A_U_C_max-1)/bar_s_C_max", 1 + (d["acceptance_limit"] - 1) / s)}
            rows.append(PageRow(q, value=Live("C_max", d["value"]), U=Live("U_C_max", d["U"]), k=Live("k_C_max", d["k"]),
                                usl=Live("1", 1.0), p_c=Live("p_c_C_max", d["p_c"]),
                                decision=Live("MPE_decision", d["outcome"]), decision_note=f"({d['rule_name']})",
                                conformity=Live("MPE_conformity", d["conformity"]),
                                conformity_note=Live('"("&MPE_zone&")"', f"({d['conformity_zone']})"), bar=bar,
                                source=src))
    header = PageHeader("Summary — calibration", lines, rule, notes=[
        "Result statements: U = 2u rounded to two significant digits and the value to the same decimal place "
        "(GUM 7.2.6); full precision on the Results sheet. The hyper-parameters and effects have no tolerance; "
        "C_max is decided against C_max <= 1 (the fitted model meets the MPE statement at every distance).",
        "'decision' is the outcome of the rule named under it; 'conformity' is what C_max and U prove whatever the "
        "rule (ISO 14253-1:2017: conformity proven when C_max + U <= 1, non-conformity proven when C_max - U > 1, "
        "else neither: the uncertainty range).",
        *([(result.get("indicated") or {})["text"]] if (result.get("indicated") or {}).get("text") else [])])
    write_report_page(book, header, rows)
