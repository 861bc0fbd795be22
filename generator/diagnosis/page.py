"""The diagnosis book's report page (``Summary``, :mod:`generator.workbook.report_page`): the
header (the recordings and the task with their SHA-256, the time, the version), the two verdicts
of the locator as live formulas of the GLS sheet (do the records agree with the simulation; does
the refit with the named effects explain them), and one record per estimated effect parameter
(value, U = 2u, what it rests on) from the Results sheet."""

from __future__ import annotations

from cmmwb.xlfuncs.locator import effects as fx
from cmmwb.xlfuncs.locator.diagnose import Diagnosis

from ..quantities import Quantity, Verdict
from ..workbook.book import Book
from ..workbook.report_page import Live, PageHeader, PageRow, write_report_page
from .records import display_unit

AGREE = "the records agree with the simulation"
DISAGREE = "the records disagree with the simulation (mismatch)"
EXPLAINED = "explained by the named effects"
UNEXPLAINED = "not explained by the named effects"


def write_page(book: Book, diag: Diagnosis, provenance: dict | None, stats: dict[str, str],
               results_rows: dict[str, int], recordings: str) -> None:
    """The report page; ``stats``: the GLS sheet's cells (chi2_before, mismatch, ...),
    ``results_rows``: the Results row of each estimated quantity."""
    js = diag.to_json()
    prov = provenance or {}
    lines = [("task", f"diagnosis of {recordings} against the simulation (cmmwb diagnose)")]
    tf = prov.get("task_file")
    if tf:
        lines.append(("task file", f"{tf['name']}  SHA-256 {tf['sha256']}"))
    for f in prov.get("input_files", []):
        lines.append(("input file", f"{f['name']}  SHA-256 {f['sha256']}"))
    if prov:
        lines.append(("built", f"{prov.get('built_utc', '')} (UTC) by cmmwb {prov.get('cmmwb_version', '')}"))
    lines.append(("answer", diag.summary))
    verdicts = [
        Verdict("chi-square test", js["chi2_before"] / js["dof_before"], "χ²/dof",
                DISAGREE if js["mismatch"] else AGREE,
                "mismatch when p_before (the chi-square of the residuals against the simulation's covariance) or "
                "p_targeted (the best candidate's likelihood-ratio test) is below alpha/2 (GLS sheet; "
                "docs/diagnose.md section 2)",
                value_cell=f"{stats['chi2_before']}/{stats['dof_before']}",
                verdict_cell=f'IF({stats["mismatch"]}="yes","{DISAGREE}","{AGREE}")')]
    if js["p_after"] is not None and diag.chosen:
        verdicts.append(Verdict(
            "after the refit", js["chi2_after"] / js["dof_after"], "χ²/dof",
            EXPLAINED if js["explained"] else UNEXPLAINED,
            "explained when p_after, the chi-square tail of what remains after the GLS refit with the named "
            "effects, is at least alpha (GLS sheet; docs/diagnose.md section 3)",
            value_cell=f"{stats['chi2_after']}/{stats['dof_after']}",
            verdict_cell=f'IF({stats["explained"]}="yes","{EXPLAINED}","{UNEXPLAINED}")'))
    rows = []
    for j, (e, lb) in enumerate(diag.sel_labels):
        if e == "alignment":
            continue
        label = e if lb == e else f"{e} {lb}"
        r = results_rows.get(label)
        u = float(diag.cov_beta[j, j]) ** 0.5 if diag.cov_beta[j, j] > 0 else 0.0
        if r is None or not u > 0:
            continue
        unit = "µm" if e == "outlier" else display_unit(fx.BY_NAME[e].unit)
        value = float(diag.beta[j])
        if e in fx.PERIODIC and lb == "period_mm":
            unit = "mm"
        q = Quantity(label, value, unit, u, unit, 2.0, unit,
                     value_source=(f"GLS estimate from {recordings} with the simulation's covariance "
                                   "(Forbes 2025 eq. 28; GLS sheet)" if e != "outlier" else
                                   f"the gross error of record {lb.split('.')[0]} (mean-shift column, GLS sheet)"),
                     u_source="the GLS covariance (X' C^-1 X)^-1")
        rows.append(PageRow(q, value=Live(f"'Results'!$B${r}", value), U=Live(f"2*'Results'!$C${r}", 2 * u),
                            k=Live("2", 2.0), note="effect (no tolerance)" if e != "outlier" else "outlier",
                            source=["value: " + q.value_source, "U: " + q.u_source]))
    if diag.noise_scale and "noise_scale" in results_rows:
        r = results_rows["noise_scale"]
        ns = js["noise_scale"]
        q = Quantity("noise_scale", ns["estimate"], "", ns["u"], "", 2.0, "",
                     value_source="sqrt(chi2/dof) after the refit: the declared uncertainties are too small by it",
                     u_source="s / sqrt(2 dof)")
        rows.append(PageRow(q, value=Live(f"'Results'!$B${r}", ns["estimate"]),
                            U=Live(f"2*'Results'!$C${r}", 2 * ns["u"]), k=Live("2", 2.0), note="noise level",
                            source=["value: " + q.value_source, "U: " + q.u_source]))
    header = PageHeader("Summary — diagnosis", lines, None, notes=[
        "Result statements: U = 2u rounded to two significant digits and the value to the same decimal place "
        "(GUM 7.2.6); full precision on the Results sheet. An effect's estimate has no tolerance: it says what "
        "the records show, with units of docs/recordings.md section 4.",
        "The verdicts are live: they follow alpha on the Inputs sheet and the record cells."])
    write_report_page(book, header, rows, verdicts)
