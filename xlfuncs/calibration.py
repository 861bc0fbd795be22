"""The calibration of ``cmmwb calibrate`` from parsed recordings to its numbers (docs/calibrate.md):
each file's records with their fixed effects (:func:`prepare_file`: the locator's chosen effects,
none, or named ones), the REML fit of the six factors' hyper-parameters (:mod:`xlfuncs.calibrate`),
the effects' GLS estimates at the fitted model and their feedback (:mod:`xlfuncs.compensation`),
the chi-square of the records before and after, u(d) before and after (Forbes 2025 eq. 33), the MPE
check (eq. 36, :mod:`xlfuncs.calibration_checks`), the likelihood profiles and the standardized
residuals (:func:`run`, a :class:`CalibrationRun`).

The generator reads the files and the task and writes the JSON, the fitted task and the workbook
(``generator/calibration/``); this module knows neither files nor spreadsheets.  numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import calibrate as cb
from . import calibration_checks as checks
from . import compensation as cp
from . import conformity as cf
from . import pointcloud as pc
from . import reml
from .errors import ModelError
from .locator import diagnose as dg
from .locator import effects as fx
from .locator.model import Prepared
from .locator.recordings import Recordings
from .locator.report import Diagnosis, effect_estimates
from .model.hyperparameters import in_use
from .model.workpiece import Workpiece

#: the u(d) grid and the MPE check: the pointcloud workbook's grid (the MPE sheet is shared)
GRID_POINTS = 101
DEFAULT_L_MAX_MM = 1000.0
#: the coverage factor of U(C_max) = k·u(C_max) in the MPE decision
DECISION_K = 2.0
#: the limit of the MPE check: the fitted model meets the MPE statement where C(d) <= 1 everywhere
C_LIMIT = 1.0


class EffectChoiceError(ModelError):
    """A named effect (``--effects``) that is unknown, periodic or not applicable to the records."""


class FeedbackError(ModelError):
    """The effects cannot be fed back as asked (an unknown mode; ``factor`` with an effect outside
    the six factors)."""


@dataclass
class FileFit:
    """One recordings file prepared for the fit: the locator's preparation, its diagnosis
    (``--effects auto``), the effects chosen and the labels (effect, column) of the fixed effects."""

    name: str
    rec: Recordings
    prep: Prepared
    diag: Diagnosis | None
    chosen: list[str]
    labels: list[tuple[str, str]]
    set: reml.RecordSet
    beta: np.ndarray | None = None
    cov: np.ndarray | None = None
    chi2: dict = field(default_factory=dict)


def effect_columns(prep, names: list[str]) -> tuple[np.ndarray, list[tuple[str, str]]]:
    """The fixed-effect columns: the alignment of the records and the named effects'
    sensitivities (docs/recordings.md section 4), with their labels (effect, column)."""
    X, labels = [prep.A], [("alignment", a) for a in prep.A_labels]
    for name in names:
        if name not in fx.BY_NAME:
            raise EffectChoiceError(f"unknown effect {name!r}; choose from {', '.join(fx.NAMES)}")
        if name in fx.PERIODIC:
            raise EffectChoiceError(f"{name}: the period is found by the locator's scan; use --effects auto")
        try:
            cols = fx.columns(prep.design, name)
        except fx.NotApplicable as e:
            raise EffectChoiceError(f"{name}: {e}") from None
        X.append(cols.X)
        labels += [(name, lb) for lb in cols.labels]
    return np.column_stack(X), labels


def prepare_file(name: str, rec, model: dg.Model, *, effects: str = "auto", alpha: float = 0.01,
                 covariance: str = "auto") -> FileFit:
    """One file's records for the fit: the record covariance (dense or structured,
    :func:`xlfuncs.reml.use_structured`; a dense file over the cap is refused here, before the
    search), and the fixed effects: ``auto`` those ``diagnose`` chooses (outliers' mean-shift
    columns included), ``none``, or a comma-separated list of effect names."""
    structured = reml.use_structured(rec, covariance)
    prep = dg.prepare(rec, model, structured)
    op = reml.record_covariance(prep, structured)   # refuses a dense file over the cap, before the search
    chosen: list[str] = []
    diag = None
    if effects == "auto":
        diag = dg.diagnose_prepared(prep, alpha)
        chosen = list(diag.chosen)
        X, labels = diag.X_sel, list(diag.sel_labels)
    elif effects == "none":
        X, labels = effect_columns(prep, [])
    else:
        chosen = [e.strip() for e in effects.split(",") if e.strip()]
        X, labels = effect_columns(prep, chosen)
    s = reml.RecordSet(name, prep, X, [f"{a} {b}" for a, b in labels], op)
    return FileFit(name, rec, prep, diag, chosen, labels, s)


@dataclass
class CalibrationRun:
    """What :func:`run` computes: the fit, the fitted (fed back) parameters, the effects, the
    chi-square, u(d), the MPE check, profiles and residuals; :meth:`to_json` gives the numbers of
    calibration.json."""

    cal: cb.Calibration
    files: list[FileFit]
    feedback: str
    final: pc.Parameters
    findings: list[cp.Finding]
    effect_rows: list[dict]
    changes: list[cp.Change]
    notes: list[str]
    chi2: dict
    compensated: list[tuple[str, Recordings]]      #: (file name, recordings with the effects removed)
    u_d: dict
    mpe_check: dict | None
    profiles: list[dict]
    residuals: list[dict]
    indicated: dict | None = None
    #: the artefact's [workpiece] after a compensated ``thermal_expansion`` (its alpha; None: unchanged)
    workpiece: Workpiece | None = None

    def to_json(self) -> dict:
        return {"records": [{"file": f.set.name, "kind": f.prep.design.kind, "records": int(f.prep.rec.n),
                             "observations": int(len(f.set.y)), "fixed_effects": f.set.X_labels}
                            for f in self.files],
                **self.cal.to_json(),
                "effects": self.effect_rows,
                "feedback": self.feedback,
                "changes": [{"parameter": c.parameter, "before": c.before, "after": c.after, "effects": c.effects,
                             "how": c.how} for c in self.changes],
                "notes": self.notes,
                "fitted_parameters": {k: float(getattr(self.final, k)) for k in in_use(self.final)},
                "chi2": self.chi2,
                "u_d": self.u_d,
                "mpe_check": self.mpe_check, "profiles": self.profiles, "indicated": self.indicated}


def fit(files: list[FileFit], start: pc.Parameters) -> cb.Calibration:
    """The REML fit of the hyper-parameters over every file (independent sessions)."""
    return cb.calibrate([f.set for f in files], start)


def effects_at_fit(cal: cb.Calibration, files: list[FileFit]) -> tuple[list[cp.Finding], list[dict]]:
    """The chosen effects' GLS estimates and u at the fitted model; a factor the effects take
    over is left out of C for their estimates (:func:`xlfuncs.compensation.absorbed`)."""
    findings, effect_rows = [], []
    for f in files:
        gone = cp.absorbed(f.chosen)
        p_eff = replace(cal.params, **{k: 0.0 for k in gone})
        beta, cov, _, _ = checks.gls_fit(f.set, p_eff)
        f.beta, f.cov = beta, cov
        for name in f.chosen:
            idx = [j for j, (e, _) in enumerate(f.labels) if e == name]
            est = [float(beta[j]) for j in idx]
            u = [float(math.sqrt(max(cov[j, j], 0.0))) for j in idx]
            unit = fx.BY_NAME[name].unit
            findings.append(cp.Finding(name, est, u, unit))
            effect_rows.append({"file": f.set.name, "name": name, "unit": unit,
                                "labels": [f.labels[j][1] for j in idx], "estimate": est, "u": u,
                                "locator": effect_estimates(f.diag, name) if f.diag is not None else None})
    return findings, effect_rows


def chi2_before_after(files: list[FileFit], task: pc.Parameters, final: pc.Parameters,
                      feedback: str) -> tuple[dict, list[tuple[str, Recordings]]]:
    """chi-square of the records before (the task, records as measured) and after (the fitted
    task, records as fed back), summed and per file (``FileFit.chi2``), and the compensated
    recordings (``compensate``)."""
    chi2 = {"before": 0.0, "dof_before": 0, "after": 0.0, "dof_after": 0}
    compensated = []
    for f in files:
        s = f.set
        A = f.prep.A
        _, _, c0, d0 = checks.gls_fit(s, task, X=A)
        y = s.y
        if feedback == "compensate" and f.chosen:
            assert f.beta is not None
            eff = [j for j, (e, _) in enumerate(f.labels) if e in f.chosen]
            Xe, be = s.X[:, eff], f.beta[eff]
            y = s.y - Xe @ be
            compensated.append((f.name, cp.corrected_records(f.rec, f.prep, Xe, be)))
        _, _, c1, d1 = checks.gls_fit(s, final, y=y, X=A)
        f.chi2 = {"before": c0, "dof_before": d0, "after": c1, "dof_after": d1}
        chi2["before"] += c0
        chi2["dof_before"] += d0
        chi2["after"] += c1
        chi2["dof_after"] += d1
    return chi2, compensated


def u_of_d(files: list[FileFit], task: pc.Parameters, cal: cb.Calibration, final: pc.Parameters,
           findings: list[cp.Finding], changes: list[cp.Change], feedback: str, mpe: dict | None,
           workpiece: Workpiece | None = None) -> dict:
    """u(d) of eq. (33) on the grid 0 .. L_max (the MPE statement's, else 1000 mm) before (the
    task), after (the fitted task) and, for ``compensate``, of the same machine with the effects
    not corrected (carried as a factor); P_mm the MPE statement's or the longest probe offset."""
    probes = [p for f in files for p in f.prep.cloud.probes]
    P_mm = mpe["P_mm"] if mpe else max((float(np.linalg.norm(p.offset_mm)) for p in probes), default=0.0)
    L_max = mpe["L_max_mm"] if mpe else DEFAULT_L_MAX_MM
    d = L_max * np.arange(GRID_POINTS) / (GRID_POINTS - 1)
    u_before = pc.summary_components_um(d, task, P_mm)["u"]
    u_after = pc.summary_components_um(d, final, P_mm)["u"]
    u_uncomp = None
    if feedback == "compensate" and changes and all(f.name in cp.EFFECT_FACTOR for f in findings):
        # the same machine, the effects not corrected: they must be carried as a factor
        u_uncomp = pc.summary_components_um(d, cp.feed_back(cal.params, findings, "factor", workpiece=workpiece)[0],
                                            P_mm)["u"].tolist()
    return {"P_mm": P_mm, "d_mm": d.tolist(), "before_um": u_before.tolist(), "after_um": u_after.tolist(),
            "uncompensated_um": u_uncomp}


def mpe_checks(task: pc.Parameters, cal: cb.Calibration, final: pc.Parameters, changes: list[cp.Change],
               feedback: str, mpe: dict, P_mm: float, rule: cf.DecisionRule | None = None,
               k: float = DECISION_K) -> dict:
    """The MPE check (Forbes 2025 eq. 36) of the fitted task and of the task's own values.  The
    fitted task's u(C_max) is the estimates' (delta method in log); the parameters the feedback
    replaced are held at their new values (their own uncertainty, of the corrections' u, is not in
    it).  ``rule``: the decision of C_max <= 1 with that u (:func:`mpe_decision`; default ISO
    14253-1 with U = ``k``·u)."""
    A, B, K, L_max = mpe["A_um"], mpe["B_mm"], mpe["K"], mpe["L_max_mm"]
    changed = {c.parameter for c in changes} if feedback != "none" else set()
    fitted = checks.mpe_consistency(final, A, B, K, P_mm, L_max, cal, GRID_POINTS, held=changed)
    used = [n for n in cal.free if n not in changed]
    fitted["u_C_max_from"] = (
        ("the covariance of the REML estimates of " + ", ".join(used) + " (delta method in log)"
         + ("; " + ", ".join(sorted(changed & set(cal.free))) + " replaced by the feedback, held"
            if changed & set(cal.free) else "")
         + ("; the fed-back " + ", ".join(sorted(changed)) + " held at their values (the corrections' own "
            "uncertainty is not included)" if changed else ""))
        if used else "nothing was estimated: no uncertainty of C_max")
    fitted["decision"] = mpe_decision(fitted["C_max"], fitted["u_C_max"], rule or cf.DecisionRule(), k)
    return {"fitted": fitted, "task": checks.mpe_consistency(task, A, B, K, P_mm, L_max, None, GRID_POINTS)}


def mpe_decision(C_max: float, u_C_max: float | None, rule: cf.DecisionRule, k: float = DECISION_K) -> dict:
    """The MPE verdict as a decision (JCGM 106:2012, ISO 14253-1:2017; :func:`xlfuncs.conformity.decide`,
    the machinery of the task decisions): the quantity C_max with standard uncertainty u(C_max),
    U = k·u, against the one-sided specification C_max <= 1 (Forbes 2025 eq. 36: K u(d) <=
    E_MPE(d) at every d), under ``rule``.  Returns the rule's outcome (``rule_outcome``: accepted
    / rejected / cannot be decided; ``outcome`` and ``zone`` as the task decisions word them) and,
    separately, what C_max and U prove (``conformity``: conformity proven when C_max + U <= 1,
    non-conformity proven when C_max - U > 1, else neither), p_c = Φ((1 - C_max)/u), the guard
    band and the limits.  Without u (nothing estimated) only the comparison C_max <= 1 is made,
    and ``rule_outcome`` says that no rule could be applied."""
    base = {"quantity": "C_max", "limit": "C_max <= 1", "usl": C_LIMIT, "value": float(C_max), "k": float(k),
            "rule": rule.kind, "rule_name": cf.RULE_NAME[rule.kind], "r": rule.r, "max_pfa": rule.max_pfa,
            "rule_text": rule.text + f"; U = k·u(C_max) with k = {k:g}"}
    if u_C_max is None or not u_C_max > 0:
        return {**base, "u": u_C_max, "U": None, "w": None, "acceptance_limit": None, "conformance_limit": None,
                "non_conformance_limit": None, "p_c": None, "outcome": None, "zone": None,
                "rule_outcome": "not decided: no u(C_max)", "conformity": None, "conformity_zone": None,
                "within_limit": bool(C_max <= C_LIMIT)}
    # the core decision works in a value unit and a u unit a thousandth of it (mm and µm)
    d = cf.decide(C_max, u_C_max * cf.UM_PER_MM, cf.Tolerance(usl_mm=C_LIMIT), rule, k)
    return {**base, "u": float(u_C_max), "U": d.U_um / cf.UM_PER_MM, "w": d.w_um / cf.UM_PER_MM,
            "acceptance_limit": d.acceptance_mm[1], "conformance_limit": d.conformance_mm[1],
            "non_conformance_limit": d.rejection_mm[1], "p_c": float(d.p_c), "outcome": d.outcome, "zone": d.zone,
            "rule_outcome": d.rule_outcome, "conformity": d.conformity, "conformity_zone": d.conformity_zone,
            "within_limit": bool(C_max <= C_LIMIT)}


def residuals(cal: cb.Calibration) -> list[dict]:
    """Each file's GLS residuals after the fixed effects, their u and z under the fitted model."""
    out = []
    for s in cal.sets:
        e, u, z = checks.standardized_residuals(s, cal.params)
        out.append({"file": s.name, "residual_um": e.tolist(), "u_um": u.tolist(), "z": z.tolist()})
    return out


def run(files: list[FileFit], task: pc.Parameters, *, feedback: str = "compensate", mpe: dict | None = None,
        profiles: bool = True, cal: cb.Calibration | None = None, rule: cf.DecisionRule | None = None,
        indicated: bool = True, workpiece: Workpiece | None = None) -> CalibrationRun:
    """The calibration of ``files`` (module docstring) starting from the task's ``task``
    parameters; ``mpe``: the MPE statement (``A_um``, ``B_mm``, ``K``, ``P_mm``, ``L_max_mm``)
    or None; ``profiles``: compute the likelihood profiles (about 9 refits per estimate);
    ``cal``: the fit of :func:`fit`, when already done; ``rule``: the decision rule of the MPE
    verdict (default ISO 14253-1); ``indicated``: refit with the effects the locator indicates
    but does not name (:func:`indicated_effects`); ``workpiece``: the artefact of the task's
    [workpiece] (the factor W: ``thermal_expansion`` is fed back into it, docs/workpiece.md)."""
    cal = fit(files, task) if cal is None else cal
    prof: list[dict] = []
    if profiles:     # a profile that reaches a higher peak moves the fit there (checks.profiles_at_maximum)
        cal, prof = checks.profiles_at_maximum(cal)
    findings, effect_rows = effects_at_fit(cal, files)
    changes: list[cp.Change] = []
    notes: list[str] = []
    if feedback == "none" or not findings:
        final = cal.params
    else:
        try:
            final, changes, notes = cp.feed_back(cal.params, findings, feedback, workpiece=workpiece)
        except ModelError as e:
            raise FeedbackError(str(e)) from None
    part = cp.fed_back_workpiece(workpiece, findings, feedback)
    chi2, compensated = chi2_before_after(files, task, final, feedback)
    u_d = u_of_d(files, task, cal, final, findings, changes, feedback, mpe, workpiece)
    mpe_json = mpe_checks(task, cal, final, changes, feedback, mpe, u_d["P_mm"], rule) if mpe else None
    ind = indicated_effects(cal, files, task, refit=not any(f.set.structured for f in files)) if indicated else None
    return CalibrationRun(cal, files, feedback, final, findings, effect_rows, changes, notes, chi2, compensated,
                          u_d, mpe_json, prof, residuals(cal), ind, part)


def indicated_effects(cal: cb.Calibration, files: list[FileFit], start: pc.Parameters, refit: bool = True) -> dict:
    """What the locator indicates and the calibration leaves out (``--effects auto``): the effects
    ``diagnose`` finds significant at alpha but not at alpha_name (docs/recordings.md section 7:
    indicated, not named, so not fixed effects of the fit), each with its estimate and u, and
    what leaving them out does to the fitted hyper-parameters: the REML fit again with them as
    fixed effects too (``refit``: each parameter's estimate and u with them, beside the
    calibration's; not with ``refit`` False: ``refit_note`` says why).  A systematic effect
    left out of X is absorbed by the factors whose covariance can mimic it."""
    rows = []
    for f in files:
        if f.diag is None:
            continue
        for ind in f.diag.indicated:
            rows.append({"file": f.name, "name": ind["name"], "unit": ind["unit"], "estimate": ind["estimate"],
                         "u": ind["u"], "p_adjusted": ind["p_adjusted"], "alpha_name": f.diag.alpha_name})
    out: dict = {"effects": rows, "refit": None, "refit_note": None}
    if not rows:
        return out
    if not refit:
        out["refit_note"] = ("not refitted: a file uses the structured covariance, where the fit with the indicated "
                             "effects is a large fit of its own")
        return out
    sets = []
    for f in files:
        if f.diag is None or not f.diag.indicated:
            sets.append(f.set)
            continue
        X, labels = [f.set.X], list(f.set.X_labels)
        for ind in f.diag.indicated:
            c = f.diag.candidates[ind["name"]]
            assert c.cols is not None
            X.append(c.cols.X[:, c.kept])     # the identifiable columns, as the locator's refit
            labels += [f"{c.name} {c.cols.labels[j]}" for j in c.kept]
        sets.append(reml.RecordSet(f.name, f.prep, np.column_stack(X), labels, f.set.op))
    again = cb.calibrate(sets, start)
    params = []
    for name, e in cal.estimates.items():
        e2 = again.estimates[name]
        if e.status == "off" and e2.status == "off":
            continue
        params.append({"name": name, "unit": e.unit, "estimate": e.value, "u": e.u, "status": e.status,
                       "estimate_with": e2.value, "u_with": e2.u, "status_with": e2.status})
    out["refit"] = {"hyper_parameters": params, "loglik": again.loglik, "estimated": list(again.free)}
    return out

