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
from . import pointcloud as pc
from . import reml
from .errors import ModelError
from .locator import diagnose as dg
from .locator import effects as fx
from .locator.model import Prepared
from .locator.recordings import Recordings
from .locator.report import Diagnosis, effect_estimates

#: the u(d) grid and the MPE check: the pointcloud workbook's grid (the MPE sheet is shared)
GRID_POINTS = 101
DEFAULT_L_MAX_MM = 1000.0


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
                "fitted_parameters": {k: float(getattr(self.final, k)) for k in pc.Parameters.__dataclass_fields__},
                "chi2": self.chi2,
                "u_d": self.u_d,
                "mpe_check": self.mpe_check, "profiles": self.profiles}


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
           findings: list[cp.Finding], changes: list[cp.Change], feedback: str, mpe: dict | None) -> dict:
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
        u_uncomp = pc.summary_components_um(d, cp.feed_back(cal.params, findings, "factor")[0], P_mm)["u"].tolist()
    return {"P_mm": P_mm, "d_mm": d.tolist(), "before_um": u_before.tolist(), "after_um": u_after.tolist(),
            "uncompensated_um": u_uncomp}


def mpe_checks(task: pc.Parameters, cal: cb.Calibration, final: pc.Parameters, changes: list[cp.Change],
               feedback: str, mpe: dict, P_mm: float) -> dict:
    """The MPE check (Forbes 2025 eq. 36) of the fitted task and of the task's own values."""
    A, B, K, L_max = mpe["A_um"], mpe["B_mm"], mpe["K"], mpe["L_max_mm"]
    return {"fitted": checks.mpe_consistency(final, A, B, K, P_mm, L_max,
                                             cal if feedback == "none" or not changes else None, GRID_POINTS),
            "task": checks.mpe_consistency(task, A, B, K, P_mm, L_max, None, GRID_POINTS)}


def residuals(cal: cb.Calibration) -> list[dict]:
    """Each file's GLS residuals after the fixed effects, their u and z under the fitted model."""
    out = []
    for s in cal.sets:
        e, u, z = checks.standardized_residuals(s, cal.params)
        out.append({"file": s.name, "residual_um": e.tolist(), "u_um": u.tolist(), "z": z.tolist()})
    return out


def run(files: list[FileFit], task: pc.Parameters, *, feedback: str = "compensate", mpe: dict | None = None,
        profiles: bool = True, cal: cb.Calibration | None = None) -> CalibrationRun:
    """The calibration of ``files`` (module docstring) starting from the task's ``task``
    parameters; ``mpe``: the MPE statement (``A_um``, ``B_mm``, ``K``, ``P_mm``, ``L_max_mm``)
    or None; ``profiles``: compute the likelihood profiles (about 9 refits per estimate);
    ``cal``: the fit of :func:`fit`, when already done."""
    cal = fit(files, task) if cal is None else cal
    findings, effect_rows = effects_at_fit(cal, files)
    changes: list[cp.Change] = []
    notes: list[str] = []
    if feedback == "none" or not findings:
        final = cal.params
    else:
        try:
            final, changes, notes = cp.feed_back(cal.params, findings, feedback)
        except ModelError as e:
            raise FeedbackError(str(e)) from None
    chi2, compensated = chi2_before_after(files, task, final, feedback)
    u_d = u_of_d(files, task, cal, final, findings, changes, feedback, mpe)
    mpe_json = mpe_checks(task, cal, final, changes, feedback, mpe, u_d["P_mm"]) if mpe else None
    prof = [checks.profile(cal, n) for n in cal.free] if profiles else []
    return CalibrationRun(cal, files, feedback, final, findings, effect_rows, changes, notes, chi2, compensated,
                          u_d, mpe_json, prof, residuals(cal))
