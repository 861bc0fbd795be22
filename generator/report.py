"""What ties an output to its inputs, and the page a person signs: provenance, the optional
``[report]`` table and the one-page ``Summary`` sheet.

* provenance (every build): SHA-256 of the task file and of every file it reads (``file`` keys
  of the task, e.g. ``[points] file``), the build time (UTC) and the cmmwb version; in the JSON
  (``"provenance"``), on the Summary sheet and so in the PDF.  ``SOURCE_DATE_EPOCH`` (seconds
  since 1970, the reproducible-builds convention) fixes the build time, e.g. for templates.
* ``[report]``: ``lab``, ``operator``, ``cmm``, ``artefact``, ``job_id`` (text) and ``notes``
  (text or a list of texts), shown on the Summary sheet and in the JSON (``"report"``).
* the Summary sheet: the task and its inputs' identity, each characteristic's value and U as a
  rounded statement (GUM 7.2.6; live formulas of the Results/Decision cells: ROUND, FIXED), the
  decision and the decision rule spelled out; printed on one page.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import textwrap
from pathlib import Path
from typing import Any

from cmmwb.xlfuncs.statement import coverage_text, statement

from . import __version__
from .decision import BONUS_CONDITIONS, column, margin_label, symbol
from .errors import InputError
from .taskfile import check_keys
from .workbook.atomic import sha256
from .workbook.book import Book
from .workbook.styles import HEADER_FONT, TITLE_FONT
from .workbook.xlref import cell, quote_sheet

SHEET = "Summary"
REPORT_KEYS = ("lab", "operator", "cmm", "artefact", "job_id", "notes")
#: at most this many characteristics on the one-page Summary (the rest: see Results)
MAX_ROWS = 24
TEXT_WIDTH = 92               #: characters per line of the text beside a label (columns B-D)


def _files_of(doc, out: list[str]) -> None:
    if isinstance(doc, dict):
        for k, v in doc.items():
            if k == "file" and isinstance(v, str):
                out.append(v)
            else:
                _files_of(v, out)
    elif isinstance(doc, list):
        for v in doc:
            _files_of(v, out)


def build_time_utc() -> str:
    """Now (UTC, ISO 8601, seconds), or ``SOURCE_DATE_EPOCH`` when set."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch and epoch.strip().isdigit():
        t = _dt.datetime.fromtimestamp(int(epoch), _dt.timezone.utc)
    else:
        t = _dt.datetime.now(_dt.timezone.utc)
    return t.replace(microsecond=0).isoformat().replace("+00:00", "Z")


def provenance(task_path: Path, doc: dict, built_utc: str | None = None) -> dict:
    """``{"task_file": {"name", "sha256"}, "input_files": [{"name", "sha256"}], "built_utc",
    "cmmwb_version"}``."""
    task_path = Path(task_path)
    names: list[str] = []
    _files_of(doc, names)
    inputs = []
    for name in dict.fromkeys(names):
        p = task_path.parent / name
        if p.is_file():
            inputs.append({"name": name, "sha256": sha256(p)})
    return {"task_file": {"name": task_path.name, "sha256": sha256(task_path)}, "input_files": inputs,
            "built_utc": built_utc or build_time_utc(), "cmmwb_version": __version__}


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


# -- what the Summary lists --------------------------------------------------------------------------

def summary_items(kind: str, results: dict, k_feature: float = 2.0) -> list[dict]:
    """The characteristics a person reads: (label, symbol, value, unit, U, U unit, unit ratio,
    k, Results row, Results column names) in the order of the Results sheet."""
    items = []
    if kind == "budget":
        k = float(results["mpe"]["k"])
        for i, c in enumerate(results["characteristics"]):
            items.append(dict(label=c["name"], value=c["value_mm"], unit="mm", U=c["U_um"], U_unit="µm",
                              ratio=1000.0, k=k, row=i + 2, value_col="value_mm", U_col="U_um", u_col=None))
    elif kind == "pointcloud":
        k = float(results.get("K", 2.0))
        for i, d in enumerate(results["distances"]):
            items.append(dict(label=f"{d['from']}→{d['to']}", value=d["d_mm"], unit="mm", U=d["U_um"], U_unit="µm",
                              ratio=1000.0, k=k, row=i + 2, value_col="d_mm", U_col="U_um", u_col=None))
    elif kind == "feature":
        fe = results["feature"]
        for i, n in enumerate(fe["parameter_names"]):
            unit = "mm" if n.endswith("_mm") else ("rad" if n.endswith("_rad") else "")
            if not unit:
                continue          # unit-vector components: in the Results sheet
            scale = 1000.0 if unit == "mm" else 1.0
            items.append(dict(label=n, value=fe["parameters"][n], unit=unit, U=k_feature * fe["u"][n] * scale,
                              U_unit="µm" if unit == "mm" else "rad", ratio=scale, k=k_feature, row=i + 2,
                              value_col="value", U_col=None, u_col="u"))
    elif kind == "characteristic":
        # lengths: u in µm, U = k·u µm; angles: value in deg, u in µrad, U stated in deg
        for i, c in enumerate(results["characteristics"]):
            deg = c["unit"] == "deg"
            u_factor = 180 / math.pi * 1e-6 if deg else 1.0       # deg per µrad, or µm per µm
            items.append(dict(label=c["name"], value=c["value"], unit=c["unit"], U=k_feature * c["u"] * u_factor,
                              U_unit="deg" if deg else "µm", ratio=1.0 if deg else 1000.0, u_factor=u_factor,
                              k=k_feature, row=i + 2, value_col="value", U_col=None, u_col="u"))
            if c["margin_mm"] is not None and c["material_condition"] in BONUS_CONDITIONS:
                items.append(dict(label=margin_label(c["name"]), value=c["margin_mm"], unit="mm",
                                  U=k_feature * c["u_margin_um"], U_unit="µm", ratio=1000.0, u_factor=1.0,
                                  k=k_feature, row=i + 2, value_col="margin_mm", U_col=None, u_col="u_margin_um",
                                  sheet="Characteristics"))
    # a quantity with U = 0 (a parameter the fit holds fixed) has no statement to round
    return [it for it in items if it["U"] > 0 and math.isfinite(it["U"])]


# -- the Summary sheet ------------------------------------------------------------------------------

def write_sheet(book: Book, kind: str, results: dict, *, decision_rows: dict[str, int] | None = None,
                k_feature: float = 2.0) -> dict[str, dict[str, Any]]:
    """The one-page ``Summary`` sheet; returns the values to cache in its formula cells.
    ``decision_rows``: characteristic label -> row of the Decision sheet (outcome column N, p_c M,
    value C, U E)."""
    ws = book.sheet(SHEET)
    cache: dict[str, Any] = {}
    prov = results.get("provenance", {})
    rep = results.get("report") or {}
    book.text(ws, 1, 1, f"Summary — {results['name']}", font=TITLE_FONT)
    r = 2
    lines = [("task", f"{results['name']} (kind {kind})"),
             ("task file", f"{prov.get('task_file', {}).get('name', '')}  SHA-256 "
                           f"{prov.get('task_file', {}).get('sha256', '')}")]
    for f in prov.get("input_files", []):
        lines.append(("input file", f"{f['name']}  SHA-256 {f['sha256']}"))
    lines.append(("built", f"{prov.get('built_utc', '')} (UTC) by cmmwb {prov.get('cmmwb_version', __version__)}"))
    labels = {"lab": "laboratory", "operator": "operator", "cmm": "CMM", "artefact": "artefact / part",
              "job_id": "job id"}
    for key, label in labels.items():
        if key in rep:
            lines.append((label, rep[key]))
    notes = rep.get("notes")
    for note in ([notes] if isinstance(notes, str) else notes or []):
        lines.append(("note", note))
    rule = results.get("decision_rule")
    if rule:
        lines.append(("decision rule", rule["text"] + (f"; U = {rule['k']:g}u" if "k" in rule else "")))
    if rule and kind == "characteristic":
        lines.append(("tolerances", "the drawing's, on 'Characteristics': size and distance two-sided (lsl, usl); "
                                    "form, orientation, position one-sided (value <= tolerance_mm); a position at "
                                    "MMC/LMC on its margin = tolerance + bonus - value >= 0 (u with the size's); "
                                    "angles not decided yet"))
    for label, text in lines:
        book.text(ws, r, 1, label, font=HEADER_FONT)
        for part in textwrap.wrap(str(text), TEXT_WIDTH) or [""]:
            book.text(ws, r, 2, part)
            r += 1
    r += 1
    for part in textwrap.wrap("Results: U rounded to two significant digits and the value to the same decimal "
                              "place (GUM 7.2.6); full precision in the Results sheet.", TEXT_WIDTH + 18):
        book.text(ws, r, 1, part)
        r += 1
    head = r
    book.header(ws, head, 1, ["characteristic", "result statement", "decision", "p_c"])
    items = summary_items(kind, results, k_feature)
    decisions = {d["characteristic"]: d for d in results.get("decisions", [])}
    if decision_rows:
        chosen = [it for it in items if it["label"] in decision_rows]
        chosen += [it for it in items if it["label"] not in decision_rows]
    else:
        chosen = list(items)
    if kind == "characteristic":      # the drawing's order: a position beside its margin
        chosen = list(items)
    shown = chosen[:MAX_ROWS]
    from openpyxl.utils import get_column_letter

    cols = {name: {str(c.value): get_column_letter(c.column) for c in book.wb[name][1] if c.value is not None}
            for name in {it.get("sheet", "Results") for it in shown}}
    not_decided = {d["characteristic"]: d["reason"] for d in results.get("not_decided", [])}
    for j, it in enumerate(shown):
        sheet = it.get("sheet", "Results")
        res, rcols = quote_sheet(sheet), cols[sheet]
        rr = head + 1 + j
        book.text(ws, rr, 1, it["label"])
        dec = decisions.get(it["label"])
        drow = (decision_rows or {}).get(it["label"])
        k = it["k"]
        k_part = f'" ({coverage_text(k)})"'
        if drow is not None and dec is not None:
            y = cell(drow, column("value_mm"), "Decision")
            U = cell(drow, column("U_um"), "Decision")
            value, Uv, k = dec["value_mm"], dec["U_um"], dec["k"]
            if dec.get("distribution") == "t":      # k = t_95.45(ν_eff): live, two decimals
                k_part = (f'" (k = "&FIXED({cell(drow, column("k"), "Decision")},2,TRUE)&", coverage probability '
                          f'≈ 95 %)"')
        else:
            y = f"{res}!${rcols[it['value_col']]}${it['row']}"
            if it["U_col"] is not None:
                U = f"{res}!${rcols[it['U_col']]}${it['row']}"
            else:
                f = it.get("u_factor", it["ratio"])
                U = f"{it['k']:g}*{res}!${rcols[it['u_col']]}${it['row']}" + ("" if f == 1 else
                                                                              f"*{f:g}" if f == round(f) else f"*{f!r}")
            value, Uv = it["value"], it["U"]
        shift = {1000.0: 3, 1.0: 0}[it["ratio"]]
        # U to two significant digits: ROUND(U, 1-INT(LOG10(U))); its decimals again after rounding
        # (9.96 -> 10); the value to the same decimal place (GUM 7.2.6)
        Ur = f"ROUND({U},1-INT(LOG10({U})))"
        dU = f"(1-INT(LOG10({Ur})))"
        text = (f'="{symbol(kind, it["label"])} = "&FIXED({y},{dU}+{shift},TRUE)&" {it["unit"]}, U = "'
                f'&FIXED({Ur},{dU},TRUE)&" {it["U_unit"]}"&{k_part}')
        book.formula(ws, rr, 2, text, fmt=None, note="rounded statement of the Results (or Decision) cells; "
                                                     "GUM 7.2.6")
        cache[cell(rr, 2, absolute=False)] = statement(symbol(kind, it["label"]), value, it["unit"], Uv,
                                                      it["U_unit"], k, unit_ratio=it["ratio"])
        if drow is not None and dec is not None:
            book.formula(ws, rr, 3, f"={cell(drow, column('outcome'), 'Decision')}", fmt=None)
            book.formula(ws, rr, 4, f"={cell(drow, column('p_c'), 'Decision')}", fmt="0.0000")
            cache[cell(rr, 3, absolute=False)] = dec["outcome"]
            cache[cell(rr, 4, absolute=False)] = dec["p_c"]
        elif it["label"] in not_decided:
            book.text(ws, rr, 3, "not decided (angle)")
            book.note(ws.cell(row=rr, column=3), not_decided[it["label"]])
        elif margin_label(it["label"]) in (decision_rows or {}):
            book.text(ws, rr, 3, "on its margin")
            book.note(ws.cell(row=rr, column=3), "a position at MMC/LMC is decided on its margin "
                      "(tolerance + bonus - value >= 0): the row of that name")
        else:
            book.text(ws, rr, 3, "no tolerance given")
    r = head + 1 + len(shown)
    if len(chosen) > len(shown):
        book.text(ws, r, 1, f"... and {len(chosen) - len(shown)} more: see the Results sheet.")
        r += 1
    ws.column_dimensions["A"].width = 18
    ws.column_dimensions["B"].width = 70
    ws.column_dimensions["C"].width = 18
    ws.column_dimensions["D"].width = 9
    book.print_setup(ws, landscape=False, title_rows=None, fit_widths=False, one_page=True, area=f"A1:D{r}")
    return {SHEET: cache}


def summary_lines(results: dict, most: int = 4) -> list[str]:
    """Rounded result statements (GUM 7.2.6) and decisions for the console (``build``/``demo``):
    every decision, or else the first ``most`` characteristics."""
    out = []
    rule = results.get("decision_rule")
    if rule:
        out.append(f"decisions ({rule['rule']}):")
        for d in results.get("decisions", []):
            out.append(f"  {d['statement']}: {d['outcome']} ({d['zone']}, "
                       f"p_c = {d['p_c']:.4f})")
        for d in results.get("not_decided", []):
            out.append(f"  {d['characteristic']}: not decided ({d['reason']})")
        return out
    items = summary_items(results["kind"], results)
    for it in items[:most]:
        out.append(statement(symbol(results["kind"], it["label"]), it["value"], it["unit"], it["U"], it["U_unit"],
                             it["k"], unit_ratio=it["ratio"]))
    if len(items) > most:
        out.append(f"... {len(items) - most} more in the Results sheet and the JSON")
    return out
