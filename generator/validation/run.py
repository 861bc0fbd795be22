"""The validation behind ``cmmwb validate RESULTS.csv --task TASK.toml --out DIR``
(docs/validate.md; the command is :mod:`generator.cli.validate`).

The task (as ``build`` takes it, or the fitted task ``calibrate`` wrote; several with repeated
``--task``) gives the model's U of every characteristic through its result records
(:meth:`generator.taskkind.TaskKind.quantities`: label, value, u, k, U); the results file
(:mod:`generator.validation.results`) the measured and calibrated values; the core
(:func:`cmmwb.xlfuncs.validation.validate`) the E_n rows, the count, the structure (the locator
on the length rows with probed points, under the task's ``[parameters]`` and ``[[probes]]``) and
the verdict.  Writes, all or nothing,

* ``DIR/validation.json``  rows with their parts, count, structure, verdict with its rule, cause
  and next step
* ``DIR/validation.xlsx``  the workbook: live E_n, count, chi-square and verdict, the chart of
  the deviations against +-U and +-sqrt(U^2 + U_cal^2)
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from cmmwb.xlfuncs import validation as va

from .. import __version__
from ..build import load_task
from ..errors import InputError, model_errors_named
from ..quantities import Quantity
from ..workbook.atomic import Staging, sha256
from ..workbook.provenance import build_time_utc
from .results import read_results, rows_and_geometry


def task_records(task_paths: list[Path]) -> tuple[dict[str, Quantity], dict[str, Path], list[dict]]:
    """Every task's result records by label (the ``[decision] k`` of a task where its kind's U is
    k u); which task each comes from; the tasks described for the JSON."""
    records: dict[str, Quantity] = {}
    origin: dict[str, Path] = {}
    described = []
    for path in task_paths:
        path = Path(path)
        kind, mod, doc, task = load_task(path)
        with model_errors_named(path):
            results = mod.compute(task)
        dec = doc.get("decision") if isinstance(doc.get("decision"), dict) else {}
        k = dec.get("k", 2.0)
        if isinstance(k, bool) or not isinstance(k, (int, float)) or not (k > 0 and math.isfinite(k)):
            raise InputError(f"must be a positive number, got {k!r}", file=path, where="[decision] k")
        qs = mod.quantities(task, results, float(k))
        for q in qs:
            if q.label in records:
                raise InputError(f"the result {q.label!r} is in {origin[q.label].name} too: the tasks of one "
                                 "validation name their results apart", file=path)
            records[q.label] = q
            origin[q.label] = path
        described.append({"file": path.name, "sha256": sha256(path), "kind": kind, "name": results.get("name"),
                          "results": len(qs), "has_parameters": "parameters" in doc})
    return records, origin, described


def run_validate(results_path: Path, task_paths: list[Path], out_dir: Path, *, alpha: float = va.ALPHA,
                 workbook: bool = True, force: bool = False, built_utc: str | None = None) -> tuple[dict, list[Path]]:
    """Validate the task(s) against ``results_path`` into ``out_dir`` (all or nothing); returns the
    JSON and the files written."""
    from ..diagnosis.run import load_model

    results_path = Path(results_path)
    if not (0.0 < alpha < 1.0):
        raise InputError(f"--alpha must be between 0 and 1, got {alpha!r}")
    if not task_paths:
        raise InputError("give the task: --task TASK.toml")
    records, origin, tasks = task_records([Path(p) for p in task_paths])
    rows, notes = read_results(results_path, records)
    core, geo = rows_and_geometry(results_path, rows)
    model = None
    if geo is not None:
        sources = {origin[core.label[i]] for i in geo.rows}
        src = next(p for p in [Path(t) for t in task_paths] if p in sources)
        described = next(t for t in tasks if t["file"] == src.name)
        if described["has_parameters"]:
            model, _ = load_model(str(src), None)
            if len(sources) > 1:
                notes.append(f"the length rows come from {len(sources)} tasks: the locator uses the machine model "
                             f"([parameters], [[probes]]) of {src.name}")
        else:
            notes.append(f"{src.name} has no [parameters] (no point-cloud model): the probed points are not used, "
                         "every row is taken independent")
            geo = None
    try:
        with model_errors_named(results_path):
            v = va.validate(core, geo, model, alpha)
    except va.ResultsError as e:
        raise InputError(e.message, file=results_path, where=f"line {e.line}" if e.line else None) from None
    result = {"name": "validation", "kind": "validation", "version": __version__,
              "results_file": {"name": results_path.name, "sha256": sha256(results_path)}, "tasks": tasks,
              "built_utc": built_utc or build_time_utc(), **v.to_json()}
    used = {r.label: r.record for r in rows}
    result["records"] = {label: {"value": q.value, "unit": q.unit, "U": q.U, "U_unit": q.U_unit, "k": q.k,
                                 "U_per_unit": q.unit_ratio, "u_source": q.u_source, "value_source": q.value_source}
                         for label, q in used.items()}
    result["notes"] = notes + _notes(core)
    result["summary"] = va.summary(v)
    with Staging(out_dir, force=force) as tmp:
        (tmp / "validation.json").write_text(json.dumps(result, indent=1, ensure_ascii=False, allow_nan=False)
                                             + "\n", encoding="utf-8")
        made = [tmp / "validation.json"]
        if workbook:
            from .book import write_book

            made.append(write_book(result, tmp / "validation.xlsx"))
    return result, [Path(out_dir) / p.name for p in made]


def _notes(rows: va.Rows) -> list[str]:
    out = []
    if (rows.n > 1).any():
        out.append("rows with repeats: the measured value is their mean, compared with the task's U of one "
                   "measurement (conservative for the mean; the locator's covariance takes the mean's smaller "
                   "repeatability)")
    if (rows.U_cal == 0).any():
        out.append("a row with U_cal = 0: its calibrated value is taken as exact")
    return out
