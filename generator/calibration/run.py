"""The calibration behind ``cmmwb calibrate RECORDINGS.csv [more] --task TASK.toml --out DIR``
(docs/calibrate.md; the command is :mod:`generator.cli.calibrate`): reading and writing.

Reads the recordings (docs/recordings.md) and the MPE statement (:func:`parse_mpe`), has the core
compute the calibration (:mod:`xlfuncs.calibration`: the locator's effects, the REML fit of the six
factors' hyper-parameters, the feedback, chi-square, u(d) before/after and the MPE check) and
writes, all or nothing,

* ``DIR/calibration.json``  estimates with u, identifiability, MPE check, u(d) before/after, chi2
* ``DIR/fitted.toml``       the task with the fitted (and fed-back) [parameters]
* ``DIR/compensated_<file>.csv``  the recordings with the compensated coordinates (compensate)
* ``DIR/calibration.xlsx``  the workbook of the fit
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import calibration as cr
from cmmwb.xlfuncs import conformity as cf
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.errors import ModelError
from cmmwb.xlfuncs.limits import plausibility_problem
from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator.recordings import RecordingsError, write_recordings
from cmmwb.xlfuncs.model.hyperparameters import PROBE_OVERRIDES, in_table

from .. import __version__
from ..diagnosis.run import read_recordings
from ..errors import InputError, model_errors_named
from ..taskcloud import read_mpe
from ..taskfile import note
from ..workbook.atomic import Staging
from ..workbook.provenance import provenance

#: the u(d) grid and the MPE check use the pointcloud workbook's grid (the MPE sheet is shared)
GRID_POINTS = cr.GRID_POINTS
DEFAULT_L_MAX_MM = cr.DEFAULT_L_MAX_MM


def parse_mpe(text: str | None, doc: dict | None, probes, path: Path | None = None) -> dict | None:
    """The MPE statement: ``--mpe A,B[,K]`` or the task's [mpe] (its one reader,
    :func:`generator.taskcloud.read_mpe`; P_mm: the longest probe)."""
    longest = max((float(np.linalg.norm(p.offset_mm)) for p in probes), default=0.0)
    if text is not None:
        parts = [p.strip() for p in text.split(",")]
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise InputError(f"--mpe: expected A,B or A,B,K (numbers), got {text!r}") from None
        if len(vals) not in (2, 3) or not all(math.isfinite(v) and v > 0 for v in vals):
            raise InputError(f"--mpe: expected A,B or A,B,K (positive numbers), got {text!r}")
        for key, v in zip(("A_um", "B_mm"), vals):      # a unit mix-up (mm for µm) is warned about
            problem = plausibility_problem(key, v)
            if problem:
                note(problem, where="--mpe")
        return {"A_um": vals[0], "B_mm": vals[1], "K": vals[2] if len(vals) == 3 else 2.0,
                "P_mm": longest, "L_max_mm": DEFAULT_L_MAX_MM}
    m = read_mpe(path or Path("task.toml"), doc, probes) if doc else None
    return None if m is None else {"A_um": m.A_um, "B_mm": m.B_mm, "K": m.K, "P_mm": m.P_mm, "L_max_mm": m.L_max_mm}


def parse_rule(text: str | None) -> cf.DecisionRule:
    """The decision rule of the MPE verdict: ``--rule NAME[:VALUE]`` (``iso14253`` default,
    ``simple``, ``guarded_acceptance:R``, ``guarded_rejection:R``, ``specific_risk:MAX_PFA``;
    docs/conformity.md)."""
    if text is None:
        return cf.DecisionRule()
    name, _, value = text.partition(":")
    name = name.strip()
    if name not in cf.RULES:
        raise InputError(f"--rule: expected one of {', '.join(cf.RULES)} (with :R or :MAX_PFA), got {text!r}")
    try:
        v = float(value) if value.strip() else None
    except ValueError:
        raise InputError(f"--rule: the value after ':' must be a number, got {value!r}") from None
    if v is not None and name not in ("guarded_acceptance", "guarded_rejection", "specific_risk"):
        raise InputError(f"--rule: {name} takes no value, got {text!r}")
    with model_errors_named(where="--rule"):
        if name == "specific_risk":
            return cf.DecisionRule(name, max_pfa=0.05 if v is None else v)
        return cf.DecisionRule(name, r=1.0 if v is None else v)


def run_calibrate(paths: list[Path], model: dg.Model, out_dir: Path, *, task_path: Path | None = None,
                  task_label: str = "", effects: str = "auto", feedback: str = "compensate",
                  mpe: dict | None = None, alpha: float = 0.01, workbook: bool = True, force: bool = False,
                  profiles: str = "auto", covariance: str = "auto",
                  rule: cf.DecisionRule | None = None,
                  warnings: list[str] | tuple[str, ...] = ()) -> tuple[dict, list[Path]]:
    """Calibrate from ``paths`` into ``out_dir`` (all or nothing); returns the JSON and the files.
    ``covariance``: the record covariance of the fit, ``dense``, ``structured`` or ``auto`` (dense
    up to ``reml.DENSE_MAX_OBS`` observations per file, structured above).  ``profiles``: the
    likelihood profiles (about 9 refits per estimated hyper-parameter), ``yes``, ``no`` or
    ``auto`` (only when every file has the dense covariance: on a structured one each refit is a
    large fit of its own).  ``rule``: the decision rule of the MPE verdict (default ISO 14253-1).
    ``warnings``: what the task's readers noted (an implausible value); the JSON's ``warnings``
    add what was detected in each recordings file.  The computations are
    :mod:`xlfuncs.calibration`'s; this reads the files and writes the outputs."""
    from ..taskfile import read_toml

    if not (0.0 < alpha < 1.0):
        raise InputError(f"--alpha must be between 0 and 1, got {alpha!r}")
    if profiles not in ("auto", "yes", "no"):
        raise InputError(f"--profiles must be auto, yes or no, got {profiles!r}")
    doc = read_toml(task_path) if task_path is not None else None
    files: list[cr.FileFit] = []
    rec_notes: list[str] = []
    names = {}
    for path in paths:
        path = Path(path)
        stem = path.stem
        if stem in names:
            raise InputError(f"two recordings files named {stem!r}: give distinct file names", file=path)
        names[stem] = path
        rec = read_recordings(path)
        rec_notes.extend(f"{path}, {n}" for n in getattr(rec, "notes", ()))
        with model_errors_named(path):
            try:
                files.append(cr.prepare_file(stem, rec, model, effects=effects, alpha=alpha, covariance=covariance))
            except cr.EffectChoiceError as e:
                raise InputError(str(e), file=path, where="--effects") from None
            except RecordingsError as e:     # a ModelError too, named by the recordings' line
                raise InputError(e.message, file=path, where=e.where) from None
    try:
        cal = cr.fit(files, model.params)
    except ModelError as e:   # a file's own problem names that file, the others the task
        item = e.item if e.item is not None and e.item[0] == "sets" else None
        raise InputError(str(e), file=paths[item[1]] if item else (task_label or paths[0])) from None

    large = [f.name for f in files if f.set.structured]
    profiles_note = None
    if profiles == "no":
        profiles_note = "not computed (--profiles no)"
    elif profiles == "auto" and large:
        profiles_note = ("not computed: " + ", ".join(large) + " use the structured covariance, where each "
                         "profile point is a large refit (--profiles yes computes them)")
    try:
        run = cr.run(files, model.params, feedback=feedback, mpe=mpe, profiles=profiles_note is None, cal=cal,
                     rule=rule, workpiece=model.workpiece)
    except cr.FeedbackError as e:
        raise InputError(str(e), where="--feedback") from None
    by_stem = {Path(p).stem: Path(p) for p in paths}
    result = {"name": "calibration", "version": __version__, "simulation": task_label,
              "recordings": [Path(p).name for p in paths], **run.to_json(),
              "profiles_note": profiles_note, "residuals": run.residuals,
              "provenance": provenance(task_path, doc, read=[Path(p) for p in paths])}
    if result["indicated"] is not None:
        result["indicated"]["text"] = indicated_text(result)
    result["warnings"] = [*warnings, *rec_notes]
    result["summary"] = summary(result)
    with Staging(out_dir, force=force) as tmp:
        (tmp / "calibration.json").write_text(json.dumps(result, indent=1, ensure_ascii=False, allow_nan=False)
                                              + "\n", encoding="utf-8")
        made = [tmp / "calibration.json"]
        (tmp / "fitted.toml").write_text(fitted_toml(doc, run.final, result, run.workpiece), encoding="utf-8")
        made.append(tmp / "fitted.toml")
        pts = (doc or {}).get("points")
        if task_path is not None and isinstance(pts, dict) and isinstance(pts.get("file"), str):
            src = Path(task_path).parent / pts["file"]
            if not Path(pts["file"]).is_absolute() and src.is_file() and "/" not in pts["file"] \
                    and "\\" not in pts["file"]:
                # the fitted task refers to its points file by the same relative name: a copy beside it
                (tmp / src.name).write_bytes(src.read_bytes())
                made.append(tmp / src.name)
        for stem, rec in run.compensated:
            path = by_stem[stem]
            target = tmp / f"compensated_{stem}.csv"
            write_recordings(rec, target, comments=[f"cmmwb {__version__} calibrate: {path.name} with the "
                                                   "named effects compensated (measured - estimate)"])
            made.append(target)
        if workbook:
            from .book import write_book

            made.append(write_book(result, tmp / "calibration.xlsx", run.final, mpe))
    return result, [Path(out_dir) / p.name for p in made]


def summary(result: dict) -> str:
    est = [h for h in result["hyper_parameters"] if h["status"] == "estimated"]
    non = [h for h in result["hyper_parameters"] if h["status"] == "not identifiable"]
    zero = [h for h in result["hyper_parameters"] if h["status"] == "zero"]
    parts = ["Estimated: " + (", ".join(f"{h['name']} = {h['estimate']:.3g} ± {h['u']:.2g} {h['unit']}"
                                         for h in est) or "nothing") + "."]
    if result.get("multimodal"):
        parts.append(result["multimodal"])
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
        parts.append(mpe_verdict_text(m["fitted"]))
    if (result.get("indicated") or {}).get("text"):
        parts.append(result["indicated"]["text"])
    return " ".join(parts)


def mpe_verdict_text(f: dict) -> str:
    """The MPE verdict in words: C_max with its U, the rule and its outcome, what C_max and U
    prove (docs/calibrate.md section 3)."""
    d = f["decision"]
    head = f"MPE check of the fitted model: C_max = {f['C_max']:.3f} at d = {f['d_at_max_mm']:.0f} mm"
    if d["U"] is None:
        return (head + f" ({'within' if d['within_limit'] else 'above'} the limit 1; no u(C_max): nothing was "
                "estimated, so no decision rule could be applied).")
    return (head + f", U = {d['U']:.2g} (dimensionless, as C_max; k = {d['k']:g}) against C_max <= 1, "
            f"{d['rule_name']} rule: "
            f"{d['outcome']}; {d['conformity']} ({d['conformity_zone']}; p_c = {d['p_c']:.3f}).")


def indicated_text(result: dict) -> str:
    """What the locator indicates and the calibration leaves out, and what that does to the
    fitted hyper-parameters (:func:`xlfuncs.calibration.indicated_effects`)."""
    ind = result.get("indicated") or {}
    if not ind.get("effects"):
        return ""
    names = []
    for e in ind["effects"]:
        unit = e["unit"].replace("um", "µm").replace("urad", "µrad")
        if isinstance(e["estimate"], list):
            val = ", ".join(f"{b:.3g} ± {u:.2g}" for b, u in zip(e["estimate"], e["u"]) if b is not None)
        else:
            val = f"{e['estimate']:.3g} ± {e['u']:.2g}"
        names.append(f"{e['name']} = {val} {unit} in {e['file']} (adjusted p = {e['p_adjusted']:.2g}, named only "
                     f"below {e['alpha_name']:.2g})")
    text = ("The locator indicates " + "; ".join(names) + ": not named, so not a fixed effect of this fit, and "
            "the factors absorb it")
    refit = ind.get("refit")
    if refit:
        moved = [f"{h['name']} {h['estimate']:.3g} -> {h['estimate_with']:.3g} {h['unit']}"
                 + (f" ({h['status_with']})" if h["status_with"] != h["status"] else "")
                 for h in refit["hyper_parameters"] if h["status"] == "estimated" or h["status_with"] == "estimated"]
        if moved:
            text += "; fitted with it as a fixed effect too: " + ", ".join(moved)
    elif ind.get("refit_note"):
        text += " (" + ind["refit_note"] + ")"
    return text + "."


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
