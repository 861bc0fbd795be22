"""The workbook of ``cmmwb validate``: the rows with their E_n as live formulas of the typed
values (measured, calibrated, U_cal, k_cal, the task's U and k), the count against the claimed
coverage (binomial, live), the chi-square of the rows, the structure's p-value (the core's: the
locator needs the whole covariance and its search) and the verdict under its rule, the chart of
the deviations against +-U and +-sqrt(U^2 + U_cal^2), the Results sheet and the report page every
book has (``Summary``, :mod:`generator.workbook.report_page`): the verdicts and the rows with the
largest E_n, each against its limits y_cal -+ sqrt(U^2 + U_cal^2)."""

from __future__ import annotations

from pathlib import Path

from openpyxl.styles import Alignment

from ..quantities import Quantity, Verdict
from ..workbook.book import Book, ChartSeries, Formula
from ..workbook.report_page import Live, PageHeader, PageRow, write_report_page
from ..workbook.xlref import block, cell, norm_s_dist

ROWS = "Rows"
VERDICT = "Verdict"
FIRST = 3            # first data row of the Rows sheet
PAGE_ROWS = 20       # the rows with the largest E_n on the report page
COLUMNS = ("row", "characteristic", "workpiece", "run", "unit", "measured", "repeats", "calibrated",
           "U_unit", "U_cal", "k_cal", "U", "k", "U_per_unit", "deviation", "U_c", "E_n", "within", "u_c",
           "claimed", "z", "probed", "plus_U", "minus_U", "plus_U_c", "minus_U_c")
C = {name: k + 1 for k, name in enumerate(COLUMNS)}
NOTES = {
    "measured": "measured value (the mean of the repeats), in the unit of column unit",
    "calibrated": "the certificate's calibrated value", "U_cal": "the certificate's expanded uncertainty (U unit)",
    "k_cal": "the certificate's coverage factor", "U": "the model's expanded uncertainty of this characteristic: the "
    "task's result (validation.json records)", "k": "the model's coverage factor",
    "U_per_unit": "U unit per value unit (1000: µm per mm)",
    "deviation": "(measured - calibrated) x U_per_unit", "U_c": "sqrt(U^2 + U_cal^2)",
    "E_n": "|deviation| / U_c (ISO/TS 15530-4 criterion E_n <= 1)", "within": "1 when E_n <= 1",
    "u_c": "sqrt((U/k)^2 + (U_cal/k_cal)^2): standard uncertainty of the deviation under the model",
    "claimed": "the coverage the model claims for the row: 2 Phi(U_c/u_c) - 1 (NORM.DIST(z,0,1,TRUE): the form every engine has)", "z": "deviation / u_c",
    "probed": "1 when the row has its probed points (handed to the mismatch locator)",
}


#: the columns in the value's unit and in the U unit (their headers carry it when all rows share it)
IN_VALUE_UNIT = ("measured", "calibrated")
IN_U_UNIT = ("U_cal", "U", "deviation", "U_c", "u_c", "plus_U", "minus_U", "plus_U_c", "minus_U_c")
SUFFIX = {"mm": "mm", "µm": "um", "deg": "deg", "rad": "rad", "µrad": "urad"}


def headers(result: dict) -> list[str]:
    """The Rows sheet's headers: with the units in their names (``measured_mm``, ``E_n``, ``U_um``)
    when every row has the same units; the unit columns say them either way."""
    units = {r["unit"] for r in result["rows"]}
    U_units = {r["U_unit"] for r in result["rows"]}
    out = []
    for name in COLUMNS:
        if name in IN_VALUE_UNIT and len(units) == 1 and next(iter(units)) in SUFFIX:
            name = f"{name}_{SUFFIX[next(iter(units))]}"
        elif name in IN_U_UNIT and len(U_units) == 1 and next(iter(U_units)) in SUFFIX:
            name = f"{name}_{SUFFIX[next(iter(U_units))]}"
        out.append(name)
    return out


def write_book(result: dict, path: Path) -> Path:
    rows = result["rows"]
    book = Book("validation", "validation", "Validation — does the model hold on this machine? (ISO/TS 15530-4)")
    _instructions(book, result)
    last = FIRST + len(rows) - 1
    _rows(book, result, last)
    cached = _verdict(book, result, last)
    _report_page(book, result)
    out = book.save(path)
    from ..workbook import cache

    cache.store(out, "validation", {"rows": cached})
    return out


def _instructions(book: Book, result: dict) -> None:
    book.para("What this workbook is", bold=True)
    book.para("Calibrated workpieces measured on the machine (" + result["results_file"]["name"] + ") compared with "
              "the uncertainties the model gives for them (" + ", ".join(t["file"] for t in result["tasks"]) + "): "
              "per row E_n = |y - y_cal| / sqrt(U^2 + U_cal^2), the share of rows with E_n <= 1 against the "
              "coverage the model claims, whether the deviations are structured, and the verdict with its rule "
              "(docs/validate.md).")
    book.gap()
    book.para("Sheets", bold=True)
    book.para("Rows: the typed values (yellow: measured, calibrated, U_cal, k_cal, the task's U and k) and, as "
              "formulas of them, the deviation, U_c, E_n, the claimed coverage and z; the chart of the deviations "
              "with +-U and +-U_c per row.",
              "Verdict: the count of rows within E_n <= 1 and its binomial test, the chi-square of the rows, the "
              "structure's p-value (the core's: the mismatch locator on the length rows with probed points), the "
              "verdict under the rule, alpha (editable), the cause and the next step.",
              "Results: the count, the p-values and the verdict (1 = the model holds).")
    book.gap()
    book.para("Summary", bold=True)
    book.para(result["summary"])
    for n in result.get("notes", []):
        book.para(n)


def _rows(book: Book, result: dict, last: int) -> None:
    from openpyxl.chart import Reference

    ws = book.sheet(ROWS)
    book.text(ws, 1, 1, "One row per characteristic, workpiece and run; E_n <= 1 is the ISO/TS 15530-4 criterion")
    book.header(ws, 2, 1, headers(result), [NOTES.get(c) for c in COLUMNS])
    geo = set()
    loc = result.get("locator")
    if loc:
        for members in loc["rows_of_records"]:
            geo.update(members)
    for k, r in enumerate(result["rows"]):
        row = FIRST + k

        def ref(name: str) -> str:
            return cell(row, C[name], absolute=False)

        book.number(ws, row, C["row"], k + 1, fmt="0", computed=True)
        book.text(ws, row, C["characteristic"], r["label"])
        book.text(ws, row, C["workpiece"], r["workpiece"])
        book.text(ws, row, C["run"], r["run"])
        book.text(ws, row, C["unit"], r["unit"])
        book.input(ws, row, C["measured"], None, r["measured"], fmt="0.000000")
        book.number(ws, row, C["repeats"], r["repeats"], fmt="0", computed=True)
        book.input(ws, row, C["calibrated"], None, r["calibrated"], fmt="0.000000")
        book.text(ws, row, C["U_unit"], r["U_unit"])
        book.input(ws, row, C["U_cal"], None, r["U_cal"], lo=0.0, fmt="0.000")
        book.input(ws, row, C["k_cal"], None, r["k_cal"], lo=0.0, fmt="0.00")
        book.input(ws, row, C["U"], None, r["U"], lo=0.0, fmt="0.000")
        book.input(ws, row, C["k"], None, r["k"], lo=0.0, fmt="0.00")
        book.number(ws, row, C["U_per_unit"], result["records"][r["label"]]["U_per_unit"], fmt="General",
                    computed=True)
        book.formula(ws, row, C["deviation"], f"=({ref('measured')}-{ref('calibrated')})*{ref('U_per_unit')}",
                     fmt="0.000")
        book.formula(ws, row, C["U_c"], f"=SQRT({ref('U')}^2+{ref('U_cal')}^2)", fmt="0.000")
        book.formula(ws, row, C["E_n"], f"=ABS({ref('deviation')})/{ref('U_c')}", fmt="0.000")
        book.formula(ws, row, C["within"], f"=IF({ref('E_n')}<=1,1,0)", fmt="0")
        book.formula(ws, row, C["u_c"], f"=SQRT(({ref('U')}/{ref('k')})^2+({ref('U_cal')}/{ref('k_cal')})^2)",
                     fmt="0.000")
        book.formula(ws, row, C["claimed"], f"=2*{norm_s_dist(ref('U_c') + '/' + ref('u_c'))}-1", fmt="0.0000")
        book.formula(ws, row, C["z"], f"={ref('deviation')}/{ref('u_c')}", fmt="0.00")
        book.number(ws, row, C["probed"], 1 if k in geo else 0, fmt="0", computed=True)
        book.formula(ws, row, C["plus_U"], f"={ref('U')}", fmt="0.000")
        book.formula(ws, row, C["minus_U"], f"=-{ref('U')}", fmt="0.000")
        book.formula(ws, row, C["plus_U_c"], f"={ref('U_c')}", fmt="0.000")
        book.formula(ws, row, C["minus_U_c"], f"=-{ref('U_c')}", fmt="0.000")
    book.flag_unless(ws, f"{cell(FIRST, C['within'], absolute=False)}:{cell(last, C['within'], absolute=False)}", "1")
    x = Reference(ws, min_col=C["row"], min_row=FIRST, max_row=last)

    def ys(name: str):
        return Reference(ws, min_col=C[name], min_row=FIRST, max_row=last)

    unit = result["rows"][0]["U_unit"]
    book.scatter(ws, cell(last + 3, 1, absolute=False), "Deviations from the calibrated values", "row",
                 f"y - y_cal / {unit}",
                 [ChartSeries("y - y_cal", x, ys("deviation")),
                  ChartSeries("+U (model)", x, ys("plus_U"), symbol="dash", colour="2CA02C"),
                  ChartSeries("-U (model)", x, ys("minus_U"), symbol="dash", colour="2CA02C"),
                  ChartSeries("+sqrt(U² + U_cal²)", x, ys("plus_U_c"), symbol="dash", colour="D62728"),
                  ChartSeries("-sqrt(U² + U_cal²)", x, ys("minus_U_c"), symbol="dash", colour="D62728")],
                 width=24, height=12, page=book)
    ws.freeze_panes = ws.cell(row=FIRST, column=C["measured"])
    book.print_setup(ws, landscape=True, title_rows=2)


def _verdict(book: Book, result: dict, last: int) -> list[dict]:
    ws = book.sheet(VERDICT)

    def col(name: str) -> str:
        return block(FIRST, C[name], last - FIRST + 1, 1, ROWS)

    c = result["count"]
    v = result["verdict"]
    book.header(ws, 1, 1, ["quantity", "value", "meaning"])
    lines: list[tuple[str, str | float, str, str]] = []   # label, formula or value, meaning, name
    lines.append(("alpha", result["alpha"], "significance level of the verdict (alpha/2 count, alpha/2 structure); "
                  "editable", "alpha"))
    lines.append(("rows", Formula(f"=COUNT({col('E_n')})"), "rows (characteristic, workpiece, run)", "val_rows"))
    lines.append(("within", Formula(f"=SUM({col('within')})"), "rows with E_n <= 1", "val_within"))
    lines.append(("share", Formula("=val_within/val_rows"), "share of rows with E_n <= 1", "val_share"))
    lines.append(("claimed", Formula(f"=AVERAGE({col('claimed')})"), "mean coverage the model claims for the rows",
                  "val_claimed"))
    lines.append(("p_low_binomial", Formula("=BINOMDIST(val_within,val_rows,val_claimed,TRUE)"),
                  "P(within or fewer) for independent rows (binomial)", "val_p_low_binomial"))
    lines.append(("p_high_binomial",
                  Formula("=IF(val_within=0,1,1-BINOMDIST(val_within-1,val_rows,val_claimed,TRUE))"),
                  "P(within or more) for independent rows", "val_p_high_binomial"))
    corr = c["p_low_correlated"]
    lines.append(("p_low_correlated", corr if corr is not None else "—",
                  "P(within or fewer) with the rows' correlation under the model (the core's draws; — when no row "
                  "has probed points)", "val_p_low_correlated"))
    lines.append(("p_count", Formula("=val_p_low_correlated") if corr is not None else Formula("=val_p_low_binomial"),
                  "the count's p-value the verdict uses", "val_p_count"))
    lines.append(("chi2_rows", Formula(f"=SUMPRODUCT({col('z')},{col('z')})"),
                  "sum of z^2 over all rows (rows taken independent: a check, not the verdict's test)", "val_chi2"))
    lines.append(("p_chi2_rows", Formula("=CHIDIST(val_chi2,val_rows)"), "its chi-square tail", "val_p_chi2"))
    lines.append(("p_structure", result["p_structure"], "the structure's p-value (the core's): "
                  + result["structure_basis"], "val_p_structure"))
    lines.append(("holds", Formula("=IF(AND(val_p_count>=alpha/2,val_p_structure>=alpha/2),1,0)"),
                  "1: the model holds (rule below)", "val_holds"))
    cached = []
    r = 2
    for label, value, meaning, name in lines:
        book.text(ws, r, 1, label)
        if isinstance(value, Formula):
            book.formula(ws, r, 2, value, fmt="0" if name in ("val_rows", "val_within", "val_holds") else "0.000000",
                         name=name)
        elif isinstance(value, str):
            book.text(ws, r, 2, value)
            book.define(name, cell(r, 2, VERDICT))
        elif name == "alpha":
            book.input(ws, r, 2, name, value, lo=0.0, hi=1.0, fmt="0.000",
                       note="alpha: the verdict's significance level (docs/validate.md)")
        else:
            book.number(ws, r, 2, value, fmt="0.000000", computed=True)
            book.define(name, cell(r, 2, VERDICT))
        book.text(ws, r, 3, meaning)
        r += 1
    book.text(ws, r, 1, "verdict")
    book.formula(ws, r, 2, f'=IF(val_holds=1,"{_q(v_words(True))}","{_q(v_words(False))}")', fmt=None)
    book.flag_unless(ws, cell(r, 2, absolute=False), v_words(True))
    r += 2
    for label, text in (("rule", v["rule"]), ("count", result["count_words"]),
                        ("cause", v["cause"] or "—"), ("next step", v["next_step"])):
        book.text(ws, r, 1, label).alignment = Alignment(vertical="top")
        book.text(ws, r, 3, text, wrap=True).alignment = Alignment(wrap_text=True, vertical="top")
        ws.row_dimensions[r].height = 13 * (len(text) // 85 + 1)
        r += 1
    for row in range(2, r):
        meaning = ws.cell(row=row, column=3)
        if isinstance(meaning.value, str) and len(meaning.value) > 85:
            meaning.alignment = Alignment(wrap_text=True, vertical="top")
            for column in (1, 2):
                ws.cell(row=row, column=column).alignment = Alignment(vertical="top")
            ws.row_dimensions[row].height = max(ws.row_dimensions[row].height or 13,
                                                13 * (len(meaning.value) // 85 + 1))
    ws.column_dimensions["A"].width = 18
    ws.column_dimensions["B"].width = 16
    ws.column_dimensions["C"].width = 95
    book.print_setup(ws, fit_widths=False, landscape=True)
    rows_out = [["within", Formula("=val_within"), "rows"], ["share", Formula("=val_share"), "1"],
                ["claimed", Formula("=val_claimed"), "1"], ["p_count", Formula("=val_p_count"), "1"],
                ["p_structure", Formula("=val_p_structure"), "1"], ["holds", Formula("=val_holds"), "1"]]
    cached = [{"value": c["within"]}, {"value": c["share"]}, {"value": c["claimed"]}, {"value": c["p_low"]},
              {"value": result["p_structure"]}, {"value": 1.0 if v["holds"] else 0.0}]
    book.results(["quantity", "value", "unit"], rows_out,
                 ["the validation's results (validation.json count, p_structure, verdict)", "value", "unit"])
    return cached


def v_words(holds: bool) -> str:
    from cmmwb.xlfuncs.validation import VERDICT_WORDS

    return VERDICT_WORDS[holds]


def _q(text: str) -> str:
    return text.replace('"', '""')


def _report_page(book: Book, result: dict) -> None:
    """The ``Summary`` sheet: the files and the build, the three verdicts (the count, the
    structure, the model) as live formulas of the Verdict sheet, and the rows with the largest
    E_n: value ± U against y_cal -+ U_c, the decision E_n <= 1, live from the Rows sheet."""
    v = result["verdict"]
    lines = [("results file", f"{result['results_file']['name']}  SHA-256 {result['results_file']['sha256']}")]
    for t in result["tasks"]:
        lines.append(("task file", f"{t['file']} (kind {t['kind']})  SHA-256 {t['sha256']}"))
    lines.append(("built", f"{result['built_utc']} (UTC) by cmmwb {result['version']}"))
    lines.append(("rows", f"{len(result['rows'])} (characteristic, workpiece, run) of "
                          f"{len({(r['workpiece'], r['label']) for r in result['rows']})} calibrated characteristics"))
    if not v["holds"]:
        lines.append(("cause", v["cause"] or "—"))
        lines.append(("next step", v["next_step"]))
    header = PageHeader("Validation report — does the model hold on this machine? (ISO/TS 15530-4)", lines,
                        v["rule"] + f"; alpha = {v['alpha']:g}", notes=[
                            "Each row: the measured value ± the model's U against the calibrated value (nominal) "
                            "-+ sqrt(U^2 + U_cal^2) (the limits); 'decision' is E_n <= 1 or not, 'conformity' "
                            "the row's E_n. The rows with the largest E_n are listed; all rows: the Rows sheet.",
                            "Result statements: U rounded to two significant digits and the value to the same "
                            "decimal place (GUM 7.2.6)."])
    words = {True: v_words(True), False: v_words(False)}
    verdicts = [
        Verdict("count", result["count"]["share"], "p_count >= alpha/2 (share of rows with E_n <= 1)",
                "consistent with the claimed coverage" if result["count"]["p_low"] >= v["alpha"] / 2
                else "too few rows within their U", result["count_words"], value_cell="val_share",
                verdict_cell='IF(val_p_count>=alpha/2,"consistent with the claimed coverage",'
                             '"too few rows within their U")'),
        Verdict("structure", result["p_structure"], "p_structure >= alpha/2",
                "no structure found" if result["p_structure"] >= v["alpha"] / 2 else "structured",
                result["structure_basis"], value_cell="val_p_structure",
                verdict_cell='IF(val_p_structure>=alpha/2,"no structure found","structured")'),
        Verdict("the model", 1.0 if v["holds"] else 0.0, "holds = 1", words[v["holds"]],
                "it holds when the count and the structure both pass (the decision rule above)",
                value_cell="val_holds", verdict_cell=f'IF(val_holds=1,"{_q(words[True])}","{_q(words[False])}")'),
    ]
    rows = result["rows"]
    order = sorted(range(len(rows)), key=lambda i: (-rows[i]["E_n"], i))[:PAGE_ROWS]
    page = []
    for i in order:
        r = rows[i]
        rec = result["records"][r["label"]]
        row = FIRST + i

        def ref(name: str) -> str:
            return cell(row, C[name], ROWS)

        scale = rec["U_per_unit"]
        half = r["U_c"] / scale
        q = Quantity(label=r["label"], value=r["measured"], unit=r["unit"],
                     u=r["U"] / r["k"], u_unit=r["U_unit"], k=r["k"], U_unit=r["U_unit"], symbol=r["label"],
                     nominal=r["calibrated"], lsl=r["calibrated"] - half, usl=r["calibrated"] + half,
                     value_source=f"{r['workpiece']}, run {r['run']}: measured on the CMM "
                                  f"({result['results_file']['name']}, line {r['line']}"
                                  + (f", the mean of {r['repeats']} repeats" if r["repeats"] > 1 else "") + ")",
                     u_source=rec["u_source"])
        y = r["deviation"] / r["U_c"]
        bar = {"y": Live(f"{ref('deviation')}/{ref('U_c')}", y),
               "y_minus": Live(f"({ref('deviation')}-{ref('U')})/{ref('U_c')}", y - r["U"] / r["U_c"]),
               "y_plus": Live(f"({ref('deviation')}+{ref('U')})/{ref('U_c')}", y + r["U"] / r["U_c"]),
               "lsl": Live("-1", -1.0), "usl": Live("1", 1.0)}
        page.append(PageRow(
            q, value=Live(ref("measured"), r["measured"]), U=Live(ref("U"), r["U"]), k=Live(ref("k"), r["k"]),
            nominal=Live(ref("calibrated"), r["calibrated"]),
            lsl=Live(f"{ref('calibrated')}-{ref('U_c')}/{ref('U_per_unit')}", r["calibrated"] - half),
            usl=Live(f"{ref('calibrated')}+{ref('U_c')}/{ref('U_per_unit')}", r["calibrated"] + half),
            decision=Live(f'IF({ref("within")}=1,"E_n <= 1","E_n > 1")', "E_n <= 1" if r["within"] else "E_n > 1"),
            decision_note="(ISO/TS 15530-4)",
            conformity=Live(f'"E_n = "&FIXED({ref("E_n")},2,TRUE)', f"E_n = {r['E_n']:.2f}"),
            conformity_note=Live(f'"U_cal = "&FIXED({ref("U_cal")},3,TRUE)', f"U_cal = {r['U_cal']:.3f}"),
            bar=bar, source=["value: " + q.value_source + "; calibrated value and U_cal: the certificate",
                             "U: " + q.u_source]))
    write_report_page(book, header, page, verdicts, more=max(0, len(rows) - len(page)))
