"""The calibration behind ``cmmwb calibrate RECORDINGS.csv [more] --task TASK.toml --out DIR``
(docs/calibrate.md; the command is :mod:`generator.cli.calibrate`).

Reads the recordings (docs/recordings.md), lets the locator name the systematic effects
(``diagnose`` with the task's model; ``--effects none`` skips it), estimates the hyper-parameters
of the six factors by REML with those effects as fixed effects (:mod:`xlfuncs.calibrate`), feeds
the effects back (``--feedback compensate|factor|none``, :mod:`xlfuncs.compensation`), checks the
fitted model against the MPE statement (Forbes 2025 eq. 36) and writes, all or nothing,

* ``DIR/calibration.json``  estimates with u, identifiability, MPE check, u(d) before/after, chi2
* ``DIR/fitted.toml``       the task with the fitted (and fed-back) [parameters]
* ``DIR/compensated_<file>.csv``  the recordings with the compensated coordinates (compensate)
* ``DIR/calibration.xlsx``  the workbook of the fit
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import calibrate as cb
from cmmwb.xlfuncs import calibration_checks as checks
from cmmwb.xlfuncs import compensation as cp
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs import reml
from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import effects as fx
from cmmwb.xlfuncs.locator.recordings import RecordingsError, write_recordings
from cmmwb.xlfuncs.locator.report import effect_estimates
from cmmwb.xlfuncs.model.hyperparameters import PROBE_OVERRIDES, in_table, in_use

from .. import __version__
from ..diagnosis.run import read_recordings
from ..errors import InputError, model_errors_named
from ..workbook.atomic import Staging

#: the u(d) grid and the MPE check use the pointcloud workbook's grid (the MPE sheet is shared)
GRID_POINTS = 101
DEFAULT_L_MAX_MM = 1000.0


def parse_mpe(text: str | None, doc: dict | None, probes) -> dict | None:
    """The MPE statement: ``--mpe A,B[,K]`` or the task's [mpe] (P_mm: the longest probe)."""
    longest = max((float(np.linalg.norm(p.offset_mm)) for p in probes), default=0.0)
    if text is not None:
        parts = [p.strip() for p in text.split(",")]
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise InputError(f"--mpe: expected A,B or A,B,K (numbers), got {text!r}") from None
        if len(vals) not in (2, 3) or not all(math.isfinite(v) and v > 0 for v in vals):
            raise InputError(f"--mpe: expected A,B or A,B,K (positive numbers), got {text!r}")
        return {"A_um": vals[0], "B_mm": vals[1], "K": vals[2] if len(vals) == 3 else 2.0,
                "P_mm": longest, "L_max_mm": DEFAULT_L_MAX_MM}
    if doc and isinstance(doc.get("mpe"), dict):
        m = doc["mpe"]
        try:
            return {"A_um": float(m["A_um"]), "B_mm": float(m["B_mm"]), "K": float(m.get("K", 2.0)),
                    "P_mm": float(m.get("P_mm", longest)), "L_max_mm": float(m.get("L_max_mm", DEFAULT_L_MAX_MM))}
        except (KeyError, TypeError, ValueError):
            raise InputError("[mpe] needs numbers A_um and B_mm") from None
    return None


def _effect_columns(prep, names: list[str], path: Path):
    X, labels = [prep.A], [("alignment", a) for a in prep.A_labels]
    for name in names:
        if name not in fx.BY_NAME:
            raise InputError(f"unknown effect {name!r}; choose from {', '.join(fx.NAMES)}", file=path,
                             where="--effects")
        if name in fx.PERIODIC:
            raise InputError(f"{name}: the period is found by the locator's scan; use --effects auto",
                             where="--effects")
        try:
            cols = fx.columns(prep.design, name)
        except fx.NotApplicable as e:
            raise InputError(f"{name}: {e}", file=path, where="--effects") from None
        X.append(cols.X)
        labels += [(name, lb) for lb in cols.labels]
    return np.column_stack(X), labels


def run_calibrate(paths: list[Path], model: dg.Model, out_dir: Path, *, task_path: Path | None = None,
                  task_label: str = "", effects: str = "auto", feedback: str = "compensate",
                  mpe: dict | None = None, alpha: float = 0.01, workbook: bool = True, force: bool = False,
                  profiles: str = "auto", covariance: str = "auto") -> tuple[dict, list[Path]]:
    """Calibrate from ``paths`` into ``out_dir`` (all or nothing); returns the JSON and the files.
    ``covariance``: the record covariance of the fit, ``dense``, ``structured`` or ``auto`` (dense
    up to ``reml.DENSE_MAX_OBS`` observations per file, structured above).  ``profiles``: the
    likelihood profiles (about 9 refits per estimated hyper-parameter), ``yes``, ``no`` or
    ``auto`` (only when every file has the dense covariance: on a structured one each refit is a
    large fit of its own)."""
    from ..taskfile import read_toml

    if not (0.0 < alpha < 1.0):
        raise InputError(f"--alpha must be between 0 and 1, got {alpha!r}")
    if profiles not in ("auto", "yes", "no"):
        raise InputError(f"--profiles must be auto, yes or no, got {profiles!r}")
    doc = read_toml(task_path) if task_path is not None else None
    sets, per_file = [], []
    names = {}
    for path in paths:
        path = Path(path)
        stem = path.stem
        if stem in names:
            raise InputError(f"two recordings files named {stem!r}: give distinct file names", file=path)
        names[stem] = path
        rec = read_recordings(path)
        with model_errors_named(path):
            try:
                structured = reml.use_structured(rec, covariance)
                prep = dg.prepare(rec, model, structured)
                op = reml.record_covariance(prep, structured)   # refuses a dense file over the cap, before the search
                chosen, diag = [], None
                if effects == "auto":
                    diag = dg.diagnose_prepared(prep, alpha)
                    chosen = list(diag.chosen)
                    X, labels = diag.X_sel, list(diag.sel_labels)
                elif effects == "none":
                    X, labels = _effect_columns(prep, [], path)
                else:
                    chosen = [e.strip() for e in effects.split(",") if e.strip()]
                    X, labels = _effect_columns(prep, chosen, path)
                s = reml.RecordSet(stem, prep, X, [f"{a} {b}" for a, b in labels], op)
            except RecordingsError as e:     # a ModelError too, named by the recordings' line
                raise InputError(e.message, file=path, where=e.where) from None
        sets.append(s)
        per_file.append({"path": path, "rec": rec, "prep": prep, "diag": diag, "chosen": chosen,
                         "labels": labels})
    with model_errors_named(task_label or paths[0]):
        cal = cb.calibrate(sets, model.params)

    # -- the effects at the fitted model, fed back ---------------------------------------------
    findings, effect_rows = [], []
    for f, s in zip(per_file, sets):
        # a factor the effects take over is left out of C for their estimates (compensation.absorbed)
        gone = cp.absorbed(f["chosen"])
        p_eff = replace(cal.params, **{k: 0.0 for k in gone})
        beta, cov, _, _ = checks.gls_fit(s, p_eff)
        f["beta"], f["cov"] = beta, cov
        for name in f["chosen"]:
            idx = [j for j, (e, _) in enumerate(f["labels"]) if e == name]
            est = [float(beta[j]) for j in idx]
            u = [float(math.sqrt(max(cov[j, j], 0.0))) for j in idx]
            unit = fx.BY_NAME[name].unit
            findings.append(cp.Finding(name, est, u, unit))
            effect_rows.append({"file": s.name, "name": name, "unit": unit,
                                "labels": [f["labels"][j][1] for j in idx], "estimate": est, "u": u,
                                "locator": effect_estimates(f["diag"], name) if f["diag"] is not None else None})
    with model_errors_named(where="--feedback"):
        if feedback == "none" or not findings:
            final, changes, notes = cal.params, [], []
        else:
            final, changes, notes = cp.feed_back(cal.params, findings, feedback, workpiece=model.workpiece)
    part = cp.fed_back_workpiece(model.workpiece, findings, feedback)

    # -- chi2 of the records before (task) and after (fitted task, compensated records) ---------
    chi2 = {"before": 0.0, "dof_before": 0, "after": 0.0, "dof_after": 0}
    compensated = []
    for f, s in zip(per_file, sets):
        A = f["prep"].A
        _, _, c0, d0 = checks.gls_fit(s, model.params, X=A)
        y = s.y
        if feedback == "compensate" and f["chosen"]:
            eff = [j for j, (e, _) in enumerate(f["labels"]) if e in f["chosen"]]
            Xe, be = s.X[:, eff], f["beta"][eff]
            y = s.y - Xe @ be
            compensated.append((f["path"], cp.corrected_records(f["rec"], f["prep"], Xe, be)))
        _, _, c1, d1 = checks.gls_fit(s, final, y=y, X=A)
        f["chi2"] = {"before": c0, "dof_before": d0, "after": c1, "dof_after": d1}
        chi2["before"] += c0
        chi2["dof_before"] += d0
        chi2["after"] += c1
        chi2["dof_after"] += d1

    # -- u(d) before and after, the MPE check -----------------------------------------------------
    probes = [p for s in sets for p in s.op.cloud.probes]
    P_mm = mpe["P_mm"] if mpe else max((float(np.linalg.norm(p.offset_mm)) for p in probes), default=0.0)
    L_max = mpe["L_max_mm"] if mpe else DEFAULT_L_MAX_MM
    d = L_max * np.arange(GRID_POINTS) / (GRID_POINTS - 1)
    u_before = pc.summary_components_um(d, model.params, P_mm)["u"]
    u_after = pc.summary_components_um(d, final, P_mm)["u"]
    u_uncomp = None
    if feedback == "compensate" and changes and all(f.name in cp.EFFECT_FACTOR for f in findings):
        # the same machine, the effects not corrected: they must be carried as a factor
        u_uncomp = pc.summary_components_um(d, cp.feed_back(cal.params, findings, "factor",
                                                            workpiece=model.workpiece)[0], P_mm)["u"].tolist()
    mpe_json = None
    if mpe:
        mpe_json = {"fitted": checks.mpe_consistency(final, mpe["A_um"], mpe["B_mm"], mpe["K"], P_mm, L_max,
                                                 cal if feedback == "none" or not changes else None, GRID_POINTS),
                    "task": checks.mpe_consistency(model.params, mpe["A_um"], mpe["B_mm"], mpe["K"], P_mm, L_max,
                                               None, GRID_POINTS)}
    large = [s.name for s in sets if s.structured]
    profiles_note = None
    if profiles == "no":
        profiles_note = "not computed (--profiles no)"
    elif profiles == "auto" and large:
        profiles_note = ("not computed: " + ", ".join(large) + " use the structured covariance, where each "
                         "profile point is a large refit (--profiles yes computes them)")
    prof = [checks.profile(cal, n) for n in cal.free] if profiles_note is None else []

    resid = []
    for s in sets:
        e, u, z = checks.standardized_residuals(s, cal.params)
        resid.append({"file": s.name, "residual_um": e.tolist(), "u_um": u.tolist(), "z": z.tolist()})

    result = {"name": "calibration", "version": __version__, "simulation": task_label,
              "recordings": [Path(p).name for p in paths],
              "records": [{"file": s.name, "kind": s.prep.design.kind, "records": int(s.prep.rec.n),
                           "observations": int(len(s.y)), "fixed_effects": s.X_labels} for s in sets],
              **cal.to_json(),
              "effects": effect_rows,
              "feedback": feedback,
              "changes": [{"parameter": c.parameter, "before": c.before, "after": c.after, "effects": c.effects,
                           "how": c.how} for c in changes],
              "notes": notes,
              "fitted_parameters": {k: float(getattr(final, k)) for k in in_use(final)},
              "chi2": chi2,
              "u_d": {"P_mm": P_mm, "d_mm": d.tolist(), "before_um": u_before.tolist(),
                      "after_um": u_after.tolist(), "uncompensated_um": u_uncomp},
              "mpe_check": mpe_json, "profiles": prof,
              "profiles_note": profiles_note, "residuals": resid}
    result["summary"] = summary(result)
    with Staging(out_dir, force=force) as tmp:
        (tmp / "calibration.json").write_text(json.dumps(result, indent=1, ensure_ascii=False, allow_nan=False)
                                              + "\n", encoding="utf-8")
        made = [tmp / "calibration.json"]
        (tmp / "fitted.toml").write_text(fitted_toml(doc, final, result, part), encoding="utf-8")
        made.append(tmp / "fitted.toml")
        pts = (doc or {}).get("points")
        if task_path is not None and isinstance(pts, dict) and isinstance(pts.get("file"), str):
            src = Path(task_path).parent / pts["file"]
            if not Path(pts["file"]).is_absolute() and src.is_file() and "/" not in pts["file"] \
                    and "\\" not in pts["file"]:
                # the fitted task refers to its points file by the same relative name: a copy beside it
                (tmp / src.name).write_bytes(src.read_bytes())
                made.append(tmp / src.name)
        for path, rec in compensated:
            target = tmp / f"compensated_{Path(path).stem}.csv"
            write_recordings(rec, target, comments=[f"cmmwb {__version__} calibrate: {Path(path).name} with the "
                                                   "named effects compensated (measured - estimate)"])
            made.append(target)
        if workbook:
            from .book import write_book

            made.append(write_book(result, tmp / "calibration.xlsx", final, mpe))
    return result, [Path(out_dir) / p.name for p in made]


def summary(result: dict) -> str:
    est = [h for h in result["hyper_parameters"] if h["status"] == "estimated"]
    non = [h for h in result["hyper_parameters"] if h["status"] == "not identifiable"]
    zero = [h for h in result["hyper_parameters"] if h["status"] == "zero"]
    parts = ["Estimated: " + (", ".join(f"{h['name']} = {h['estimate']:.3g} ± {h['u']:.2g} {h['unit']}"
                                         for h in est) or "nothing") + "."]
    if zero:
        parts.append("At zero (not seen in these records): " + ", ".join(h["name"] for h in zero) + ".")
    if non:
        parts.append("Not identifiable from these records (held at their starting values): "
                     + ", ".join(h["name"] for h in non) + ".")
    if result["effects"]:
        parts.append(f"Effects ({result['feedback']}): " + ", ".join(sorted({e['name'] for e in result['effects']}))
                     + ".")
    c = result["chi2"]
    parts.append(f"chi2 {c['before']:.1f}/{c['dof_before']} (task) -> {c['after']:.1f}/{c['dof_after']} (fitted).")
    ud = result["u_d"]
    mid = len(ud["d_mm"]) // 2
    parts.append(f"u(d) before -> after ({result['feedback']}): "
                 + ", ".join(f"{ud['before_um'][k]:.3f} -> {ud['after_um'][k]:.3f} µm at {ud['d_mm'][k]:.0f} mm"
                             for k in (0, mid, len(ud["d_mm"]) - 1)) + ".")
    m = result["mpe_check"]
    if m:
        f = m["fitted"]
        parts.append(f"MPE check: C_max = {f['C_max']:.3f} at d = {f['d_at_max_mm']:.0f} mm, margin "
                     f"{f['margin']:+.3f}: the fitted model {'meets' if f['conforms'] else 'does NOT meet'} the "
                     "specification.")
    return " ".join(parts)


def fitted_toml(doc: dict | None, params: pc.Parameters, result: dict, workpiece=None) -> str:
    """The task with the fitted [parameters] (probe overrides of the fitted sigmas removed: the fit
    is task-wide) and, with a [workpiece], its u(alpha), u(T) and the artefact's alpha a compensated
    ``thermal_expansion`` gives (``workpiece``), the calibration stated in comments and in [task]
    notes."""
    import tomli_w

    doc = json.loads(json.dumps(doc)) if doc else {}
    doc["parameters"] = {k: float(getattr(params, k)) for k in in_table("parameters")}
    if isinstance(doc.get("workpiece"), dict):      # the artefact's u(alpha), u(T) (the factor W)
        doc["workpiece"].update({k: float(getattr(params, k)) for k in in_table("workpiece")})
        if workpiece is not None and workpiece.alpha_corr_ppm_per_K is not None:
            doc["workpiece"].pop("material", None)   # thermal_expansion compensated: the fitted alpha
            doc["workpiece"]["alpha_ppm_per_K"] = workpiece.alpha_ppm_per_K
            doc["workpiece"]["alpha_corr_ppm_per_K"] = workpiece.alpha_corr_ppm_per_K
    dropped = []
    for p in doc.get("probes", []) or []:
        for k in PROBE_OVERRIDES:
            if k in p:
                dropped.append(f"{p.get('id', '?')}.{k}")
                del p[k]
    note = ("cmmwb calibrate: [parameters] estimated by REML from " + ", ".join(result["recordings"])
            + "; estimated: " + (", ".join(result["estimated"]) or "none") + "; the others held at the task's "
            "values or at zero (calibration.json); effects fed back: " + result["feedback"])
    if isinstance(doc.get("task"), dict):
        notes = list(doc["task"].get("notes", []))
        notes.append(note)
        notes += result["notes"]
        if dropped:
            notes.append("per-probe overrides replaced by the fitted task-wide values: " + ", ".join(dropped))
        doc["task"]["notes"] = notes
    head = [f"# {note}"] + [f"# {n}" for n in result["notes"]]
    return "\n".join(head) + "\n" + tomli_w.dumps(doc)
