"""Simulated validation sets as files (``cmmwb simulate --validation WORKPIECES --out DIR``,
docs/validate.md section 5): the workpieces of :mod:`cmmwb.xlfuncs.validation_sets` measured by a
CMM drawn from the task's model (Forbes 2025 Table 3 MPE1 without ``--task``) with the planted
effects, written as

* ``DIR/validation_lengths.toml`` (+ ``_points.csv``): a ``pointcloud`` task of the ball plate's
  and step gauges' probed points with their distances (when there are length workpieces);
* ``DIR/validation_features.toml`` (+ ``_points.csv``): a ``characteristic`` task of the rings
  and spheres, their features and characteristics as fit (when there are);
* ``DIR/results.csv``: the results file of ``cmmwb validate`` (measured values per run, the
  certificates, the probed points of the lengths);
* ``DIR/truth.json``: what was simulated (the machine, the planted effects, the true values).

The tasks carry the simulated machine's own [parameters] and [[probes]]: validating them is the
case "the model is right"; a planted effect is one they do not model.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs import validation_sets as vsm
from cmmwb.xlfuncs.model.hyperparameters import in_table

from .. import __version__
from ..workbook.atomic import Staging

LENGTHS = "validation_lengths"
FEATURES = "validation_features"


def _task_head(kind: str, name: str, params: pc.Parameters, probes, note: str) -> dict:
    return {"task": {"kind": kind, "name": name, "notes": [note]},
            "parameters": {k: float(getattr(params, k)) for k in in_table("parameters")},
            "probes": [{"id": p.id, "offset_mm": [float(v) for v in p.offset_mm]} for p in probes],
            "points": {"file": f"{name}_points.csv"}}


def _points_csv(vs: vsm.ValidationSet, idx) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["id", "x", "y", "z", "nx", "ny", "nz", "probe"])
    for i in idx:
        w.writerow([vs.ids[i], *(f"{v:.9f}" for v in vs.X[i]), *(f"{v:.12f}" for v in vs.N[i]),
                    vs.probes[vs.k[i]].id])
    return out.getvalue()


def results_csv(vs: vsm.ValidationSet, meas: vsm.Measured, comments: list[str]) -> str:
    """The results file: one row per characteristic and run; lengths with their probed points."""
    out = io.StringIO()
    for c in comments:
        out.write(f"# {c}\n")
    w = csv.writer(out, lineterminator="\n")
    geo = ["x1", "y1", "z1", "x2", "y2", "z2", "n1x", "n1y", "n1z", "n2x", "n2y", "n2z",
           "p1x", "p1y", "p1z", "p2x", "p2y", "p2z", "probe1", "probe2"]
    w.writerow(["characteristic", "workpiece", "run", "measured_mm", "calibrated_mm", "U_cal_um", "k_cal"]
               + (geo if vs.lengths else []))
    by_len = {c.label: c for c in vs.lengths}
    for r in range(len(meas.X_indicated)):
        for lab in vs.labels:
            c = by_len.get(lab)
            row = [lab, c.workpiece if c else vs.workpiece_of_char[lab], str(r + 1),
                   f"{meas.values[lab][r]:.7f}", f"{meas.calibrated[lab]:.7f}", f"{meas.U_cal[lab]:.4f}",
                   f"{vsm.K_CAL:g}"]
            if vs.lengths:
                if c is None:
                    row += [""] * len(geo)
                else:
                    i, j = c.i, c.j
                    row += [f"{v:.6f}" for v in (*vs.X[i], *vs.X[j])]
                    row += [f"{v:.9f}" for v in (*vs.N[i], *vs.N[j])]
                    row += [f"{v:.6f}" for v in (*vs.probes[vs.k[i]].offset_mm, *vs.probes[vs.k[j]].offset_mm)]
                    row += [vs.probes[vs.k[i]].id, vs.probes[vs.k[j]].id]
            w.writerow(row)
    return out.getvalue()


def write_set(out_dir: Path, workpieces: list[str], params: pc.Parameters, probes, planted: dict, seed: int,
              runs: int, label: str, force: bool = False) -> tuple[vsm.ValidationSet, vsm.Measured, list[Path]]:
    """Simulate and write a validation set into ``out_dir`` (all or nothing)."""
    import tomli_w

    vs = vsm.build(tuple(workpieces), tuple(probes))
    meas = vsm.measure(vs, params, planted, seed=seed, runs=runs)
    note = (f"cmmwb {__version__} simulate --validation {','.join(workpieces)} --seed {seed}: the simulated "
            f"machine's own model ({label}); planted: "
            + (", ".join(f"{k}={v}" for k, v in planted.items()) or "nothing") + " (not in this model)")
    files: dict[str, str] = {}
    if vs.lengths:
        doc = _task_head("pointcloud", LENGTHS, params, probes, note)
        doc["distances"] = [{"from": vs.ids[c.i], "to": vs.ids[c.j], "group": c.workpiece} for c in vs.lengths]
        files[f"{LENGTHS}.toml"] = tomli_w.dumps(doc)
        idx = sorted({i for c in vs.lengths for i in (c.i, c.j)})
        files[f"{LENGTHS}_points.csv"] = _points_csv(vs, idx)
    if vs.characteristics:
        doc = _task_head("characteristic", FEATURES, params, probes, note)
        doc["features"] = [{"name": f.name, "type": f.element, "ids": [vs.ids[vs.fit_points[i]] for i in f.indices],
                            **({"circle_plane": f.circle_plane} if f.element == "circle" else {})}
                           for f in vs.features]
        doc["characteristics"] = [{"name": c.name, "type": c.type, "features": list(c.features)}
                                  for c in vs.characteristics]
        files[f"{FEATURES}.toml"] = tomli_w.dumps(doc)
        files[f"{FEATURES}_points.csv"] = _points_csv(vs, vs.fit_points)
    files["results.csv"] = results_csv(vs, meas, [note, "calibrated values: the true value plus a draw of the "
                                                  "certificate's u_cal = U_cal/k_cal (one per characteristic)"])
    files["truth.json"] = json.dumps({
        "machine": {k: float(getattr(params, k)) for k in in_table("parameters")},
        "probes": [{"id": p.id, "offset_mm": list(p.offset_mm)} for p in probes], "planted": _jsonable(planted),
        "seed": seed, "runs": runs, "workpieces": list(workpieces), "true_values_mm": meas.truth}, indent=1) + "\n"
    with Staging(out_dir, force=force) as tmp:
        for name, text in files.items():
            (tmp / name).write_text(text, encoding="utf-8", newline="\n")
    return vs, meas, [Path(out_dir) / n for n in files]


def _jsonable(v):
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_jsonable(x) for x in v]
    return float(v) if isinstance(v, (int, float, np.floating)) else v
