"""What ties an output to its inputs, and the page a person signs: provenance, the optional
``[report]`` table and the ``Summary`` sheet, the inspection report of a task.

* provenance (every build; :mod:`generator.workbook.provenance`, which ``diagnose`` and
  ``calibrate`` use too): SHA-256 of the task file and of every file it reads (``file`` keys of
  the task, e.g. ``[points] file``), the build time (UTC) and the cmmwb version; in the JSON
  (``"provenance"``), on the Summary sheet and so in the PDF.  ``SOURCE_DATE_EPOCH`` (seconds
  since 1970, the reproducible-builds convention) fixes the build time, e.g. for templates.
* ``[report]``: ``lab``, ``operator``, ``cmm``, ``artefact``, ``job_id`` (text) and ``notes``
  (text or a list of texts), shown on the Summary sheet and in the JSON (``"report"``).
* the Summary sheet (:mod:`generator.workbook.report_page`, written from the task's records and
  its decisions): per result its nominal, limits, value and its source, deviation, U, p_c, the
  rule's outcome and the conformity statement, a tolerance bar, the rounded statement with the
  coverage probability of its k; the MPE verdict where there is one; the rule in words.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from cmmwb.xlfuncs.statement import statement

from . import __version__
from .decision import SHEET as DECISION
from .decision import chart_scale_values, column
from .errors import InputError
from .quantities import Quantity, ToleranceKeys, Verdict
from .taskfile import check_keys
from .workbook.book import Book
from .workbook.report_page import Live, PageHeader, PageRow, write_report_page
from .workbook.xlref import cell

REPORT_KEYS = ("lab", "operator", "cmm", "artefact", "job_id", "notes")


def read_report(path: Path, doc: dict) -> dict | None:
    """The ``[report]`` table, validated: text fields (``notes`` may be a list of texts)."""
    tbl = doc.get("report")
    if tbl is None:
        return None
    if not isinstance(tbl, dict):
        raise InputError("must be a table", file=path, where="[report]")
    check_keys(path, tbl, "report", set(REPORT_KEYS))
    out: dict[str, Any] = {}
    for key in REPORT_KEYS:
        if key not in tbl:
            continue
        v = tbl[key]
        if key == "notes" and isinstance(v, list) and all(isinstance(x, str) for x in v):
            out[key] = list(v)
        elif isinstance(v, str):
            if len(v) > 500:
                raise InputError("at most 500 characters", file=path, where=f"[report] {key}")
            out[key] = v
        else:
            raise InputError(f"must be text{' (or a list of texts)' if key == 'notes' else ''}, got {v!r}",
                             file=path, where=f"[report] {key}")
    return out


# -- the Summary sheet: the report page of the task's records -----------------------------------------

#: at most this many results are listed on the report page (every decided one is; the rest: Results)
MAX_ROWS = 200
REPORT_LABELS = {"lab": "laboratory", "operator": "operator", "cmm": "CMM", "artefact": "artefact / part",
                 "job_id": "job id"}


def header(results: dict, keys: ToleranceKeys | None = None) -> PageHeader:
    """The report page's header: the task, its files' SHA-256, the build, the ``[report]`` fields,
    the decision rule."""
    prov = results.get("provenance", {})
    rep = results.get("report") or {}
    lines = [("task", f"{results['name']} (kind {results['kind']})"),
             ("task file", f"{prov.get('task_file', {}).get('name', '')}  SHA-256 "
                           f"{prov.get('task_file', {}).get('sha256', '')}")]
    for f in prov.get("input_files", []):
        lines.append(("input file", f"{f['name']}  SHA-256 {f['sha256']}"))
    lines.append(("built", f"{prov.get('built_utc', '')} (UTC) by cmmwb {prov.get('cmmwb_version', __version__)}"))
    for key, label in REPORT_LABELS.items():
        if key in rep:
            lines.append((label, rep[key]))
    notes = rep.get("notes")
    for note in ([notes] if isinstance(notes, str) else notes or []):
        lines.append(("note", note))
    rule = results.get("decision_rule")
    rule_text = None
    if rule:
        rule_text = rule["text"] + (f"; U = k·u with k = {rule['k']:g} (decision_k on the Decision sheet)"
                                    if "k" in rule else "")
        if keys is not None and keys.note:
            lines.append(("tolerances", keys.note))
    return PageHeader(f"Summary — {results['name']}", lines, rule_text, notes=[
        "Result statements: U rounded to two significant digits and the value to the same decimal place "
        "(GUM 7.2.6), with the coverage probability of k (2Φ(k) − 1, or Student's t with ⌊ν_eff⌋ degrees of "
        "freedom: GUM G.1.3, G.3.2); full precision on the Results and Decision sheets.",
        "'decision' is the outcome of the decision rule named under it; 'conformity' is what the value and U "
        "prove whatever the rule (ISO 14253-1:2017: conformity proven in [T_L + U, T_U − U], non-conformity "
        "proven outside [T_L − U, T_U + U], else neither: the uncertainty range)."])


def listed(quantities: list[Quantity], decided: set[str], most: int = MAX_ROWS) -> tuple[list[Quantity], int]:
    """The records the report page lists, in their order: every decided one, then the others up
    to ``most`` in all (a record with U = 0, a parameter the fit holds, has no statement); and how
    many are left out."""
    shown = [q for q in quantities if q.U > 0 and math.isfinite(q.U)]
    if len(shown) <= most:
        return shown, 0
    room = max(0, most - sum(q.label in decided for q in shown))
    keep = []
    for q in shown:
        if q.label in decided:
            keep.append(q)
        elif room > 0:
            keep.append(q)
            room -= 1
    return keep, len(shown) - len(keep)


def page_rows(quantities: list[Quantity], decisions: list[dict], decision_rows: dict[str, int] | None,
              k_cell: str | None) -> tuple[list[PageRow], int]:
    """The rows of the report page: a decided record from its Decision row (live: a k or measured
    value typed there changes the statement), the others from their own cells.  ``k_cell``: the
    Decision sheet's ``decision_k`` (U = k·u of records without their own U), or None."""
    by_label = {d["characteristic"]: d for d in decisions}
    rows_of = decision_rows or {}
    shown, more = listed(quantities, set(by_label) & set(rows_of))
    out = []
    for q in shown:
        d = by_label.get(q.label)
        dr = rows_of.get(q.label)
        out.append(decided_row(q, d, dr) if d is not None and dr is not None else task_row(q, k_cell))
    return out, more


def decided_row(q: Quantity, d: dict, dr: int) -> PageRow:
    def D(name: str) -> str:
        return cell(dr, column(name), DECISION)

    def live(name: str, key: str | None = None) -> Live:
        return Live(D(name), d[key or name])

    nominal = None
    if d.get("nominal_mm") is not None:
        if q.cells is not None and "nominal" in q.cells.limits:
            nominal = Live(q.cells.limits["nominal"], d["nominal_mm"])
        elif d["lsl_mm"] is not None and d["usl_mm"] is not None and \
                math.isclose(d["nominal_mm"], (d["lsl_mm"] + d["usl_mm"]) / 2, rel_tol=1e-12, abs_tol=1e-12):
            nominal = Live(f"({D('lsl_mm')}+{D('usl_mm')})/2", d["nominal_mm"])
        else:
            nominal = Live(repr(float(d["nominal_mm"])), d["nominal_mm"])
    y_rel, half_U = _rel(d, d["value_mm"]), d["U_um"] / 1000 / chart_scale_values(d)[2]
    bar = {"y": Live(D("y_rel"), y_rel), "y_minus": Live(D("y_minus_U_rel"), y_rel - half_U),
           "y_plus": Live(D("y_plus_U_rel"), y_rel + half_U)}
    for key, name, j in (("lsl", "lsl_mm", 0), ("usl", "usl_mm", 1)):
        if d[name] is not None:
            bar[key] = Live(D(f"{key}_rel"), _rel(d, d[name]))
            bar["a_l" if j == 0 else "a_u"] = Live(D("A_L_rel" if j == 0 else "A_U_rel"),
                                                    _rel(d, d["acceptance_limits_mm"][j]))
    source = ["value: " + d["value_source_text"], "U: " + u_words(q, d)]
    return PageRow(q, value=live("value_mm"), U=live("U_um"), k=live("k"),
                   nu_eff=live("nu_eff") if d["nu_eff"] is not None else None, nominal=nominal,
                   lsl=live("lsl_mm") if d["lsl_mm"] is not None else None,
                   usl=live("usl_mm") if d["usl_mm"] is not None else None,
                   p_c=live("p_c"), decision=live("outcome"), decision_note=f"({d['rule_name']})",
                   conformity=live("conformity"),
                   conformity_note=Live(f'"("&{D("conformity_zone")}&")"', f"({d['conformity_zone']})"),
                   bar=bar, source=source)


def _rel(d: dict, x: float) -> float:
    """A limit's position on the Decision chart's scale of the row (decision.sheet.chart_scale)."""
    off, ref, scale = chart_scale_values(d)
    return off + (x - ref) / scale


def u_words(q: Quantity, d: dict | None = None) -> str:
    """Where U comes from, in words."""
    text = q.u_source
    if d is not None and d.get("u_A_um") is not None:
        text += (" (the task's Results: U without the repeatability), combined with the repeatability of the "
                 "repeated measurements, u_A = s/√n (type A, GUM 4.2.3; Decision sheet: s_um, n_repeats); "
                 + ("k = t_95.45(ν_eff) (GUM G.6.4)" if d.get("distribution") == "t" else "k as the task's"))
    if not q.own_U:
        text += "; U = k·u"
    return text


def task_row(q: Quantity, k_cell: str | None) -> PageRow:
    assert q.cells is not None, q.label
    c = q.cells
    factor = c.u_scale * q.U_per_u
    times = "" if factor == 1 else f"*{factor!r}"
    if q.own_U and c.U is not None:
        U = Live(c.U, q.U)
        k = Live(c.k, q.k) if c.k else Live(f"{c.U}/({c.u}{times})", q.k)
    else:
        kref = k_cell if k_cell else repr(float(q.k))
        k = Live(kref, q.k)
        U = Live(f"{kref}*{c.u}{times}", q.U)
    note = ("decided on its margin (below)" if q.decided_as else "not decided (see below)" if q.not_decided
            else "no tolerance given")
    source = ["value: " + q.value_source, "U: " + u_words(q)]
    if q.not_decided:
        source.append("tolerance not decided: " + q.not_decided)

    def const(v: float | None) -> Live | None:
        return None if v is None else Live(repr(float(v)), v)

    return PageRow(q, value=Live(c.value, q.value), U=U, k=k, nu_eff=None if math.isinf(q.nu_eff) else
                   Live(repr(q.nu_eff), q.nu_eff), nominal=const(q.nominal), lsl=const(q.lsl), usl=const(q.usl),
                   note=note, source=source)


def write_sheet(book: Book, results: dict, quantities: list[Quantity], verdicts: list[Verdict], *,
                keys: ToleranceKeys | None = None, decision_rows: dict[str, int] | None = None,
                k_cell: str | None = None) -> None:
    """The ``Summary`` sheet: the report page of the task's records (:func:`page_rows`)."""
    rows, more = page_rows(quantities, results.get("decisions", []), decision_rows, k_cell)
    write_report_page(book, header(results, keys), rows, verdicts, more=more)


def statements(quantities: list[Quantity], decisions: list[dict], most: int = MAX_ROWS) -> list[str]:
    """The rounded result statements (GUM 7.2.6) of the results the report page lists: a decided
    one's with its decided value and U (the JSON ``decisions`` statement), the others' from
    the record."""
    by_label = {d["characteristic"]: d for d in decisions}
    shown, _ = listed(quantities, set(by_label), most)
    return [by_label[q.label]["statement"] if q.label in by_label else
            statement(q.symbol, q.value, q.unit, q.U, q.U_unit, q.k, nu=q.nu_eff, unit_ratio=q.unit_ratio)
            for q in shown]


def summary_lines(results: dict, most: int = 4) -> list[str]:
    """Rounded result statements (GUM 7.2.6) and decisions for the console (``build``/``demo``):
    every decision, or else the first ``most`` statements of the results."""
    out = []
    rule = results.get("decision_rule")
    if rule:
        out.append(f"decisions ({rule['rule']}):")
        for d in results.get("decisions", []):
            out.append(f"  {d['statement']}: {d['outcome']} ({d['rule_name']}, {d['zone']}; {d['conformity']}, "
                       f"p_c = {d['p_c']:.4f})")
        for d in results.get("not_decided", []):
            out.append(f"  {d['characteristic']}: not decided ({d['reason']})")
        return out
    lines = results.get("statements", [])
    out += lines[:most]
    if len(lines) > most:
        out.append(f"... {len(lines) - most} more in the Results sheet and the JSON")
    return out
