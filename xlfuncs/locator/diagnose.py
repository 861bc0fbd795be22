"""Mismatch locator: do the recordings agree with the simulation, where not, and which physics
was left out (``docs/recordings.md`` sections 2-6).

The simulation predicts ``measured = reference`` (length records) or ``measured = nominal`` after
a rigid alignment (point records), with the covariance C of the records built from the Forbes 2025
point-cloud model V_X (eq. 28) of the task's hyper-parameters:

* length records: C = G V_X G^T with G the distance sensitivities of eq. (29) (g = [-n; n]),
  evaluated factor by factor in kernel form (:func:`length_covariance`): every entry involves
  only the four point pairs of two records, so V_X (6n x 6n for n records) is never formed;
* point records: C = V_X of the measured points (:func:`xlfuncs.pointcloud.V_X`), restricted to
  x, y in 2-D data.

Then (docs/recordings.md section 3):

1. chi-square of the residuals against C (GLS, alignment projected out for points), p-value,
   ``mismatch = p < alpha``;
2. standardized residuals of the records; chi-square of groups of records (``group``, probe,
   uni/bidirectional probing, direction, temperature and time bands);
3. forward selection over the candidate effects of :mod:`xlfuncs.locator.effects` by generalized least
   squares: the likelihood-ratio statistic of adding a candidate is the drop of chi-square
   (Δχ², C known), its p-value the chi-square tail with df = parameters added; the best candidate
   is added while its Bonferroni-adjusted p-value (times the number of candidates tested in that
   step) is below alpha.  Candidates without sensitivity, absorbed by the alignment, or aliased
   (largest canonical correlation above 0.98 after projecting out the alignment and the other
   chosen effects) are reported, never chosen; among exact aliases the first in the table wins;
4. the refit with the chosen effects: estimates, standard uncertainties (GLS covariance),
   chi-square and RMS before and after.

Second edition (docs/recordings.md section 7, docs/diagnose.md section 6): two gates (omnibus or
targeted, alpha/2 each), single-record outliers as candidates of the search (left out by their
own mean-shift columns), ``p_after``/``explained`` and where the rest concentrates, and the noise
level (the search repeated with F-tests when the refit is not explained).

numpy only; the chi-square tail is the regularized incomplete gamma function (series and
continued fraction), in logarithms so that p-values far below 1e-308 still rank.

The parts live in :mod:`xlfuncs.locator` (statistics, model of the records, linear algebra,
search, report); this module puts them together and is the public entry point.
"""

from __future__ import annotations

import math

import numpy as np

from ..distributions import chi2_logsf, chi2_sf, f_logcdf, f_logsf
from ..errors import ModelError
from . import effects as fx
from .linalg import Whitener, cancorr, gls, orth, project_out, structured_whitener
from .model import (
    STRUCTURED_MIN_OBS,
    Model,
    Prepared,
    direction_label,
    is_structured,
    kabsch,
    length_covariance,
    prepare,
    resolve_probes,
    uses_structured,
)
from .recordings import LengthRecords, PointRecords
from .report import (
    Diagnosis,
    diagnosis_json,
    effect_estimates,
    groups_of,
    indicated_report,
    locate_groups,
    locate_records,
    outlier_report,
    summary_text,
    unexplained_rest,
)
from .search import (
    EXACT_ALIAS,
    GATE_SHARE,
    Candidate,
    Search,
    alias_reason,
    candidate_rows,
    copy_candidate,
    labels_coef,
    outliers_searchable,
    refit,
    search,
    why_zero,
)

__all__ = ["diagnose", "diagnose_prepared", "effect_covariance", "check_alphas", "NAME_SHARE",
           "Model", "Prepared", "prepare", "resolve_probes", "kabsch", "uses_structured", "is_structured",
           "STRUCTURED_MIN_OBS", "length_covariance", "Whitener", "Diagnosis",
           "Candidate", "diagnosis_json", "effect_estimates", "locate_groups", "locate_records",
           "unexplained_rest", "summary_text", "direction_label", "chi2_logsf", "chi2_sf", "f_logsf",
           "f_logcdf", "ModelError", "LengthRecords", "PointRecords"]


def diagnose(rec: LengthRecords | PointRecords, model: Model, alpha: float = 0.01,
             structured: bool | None = None, alpha_name: float | None = None, *, backend=None) -> Diagnosis:
    """The analysis of docs/recordings.md section 3 on validated recordings (``structured``: see
    :func:`prepare`; ``alpha_name``: see :func:`diagnose_prepared`; ``backend``: where the passes
    of the structured length covariance run, :mod:`xlfuncs.distributed`, same numbers)."""
    alpha_name = check_alphas(alpha, alpha_name)
    prep = prepare(rec, model, structured)
    if backend is None or not hasattr(prep.C, "backend"):
        return diagnose_prepared(prep, alpha, alpha_name)
    prep.C.backend = backend
    try:
        return diagnose_prepared(prep, alpha, alpha_name)
    finally:
        prep.C.backend = None          # the caller owns (and closes) the backend


#: a cause is named when its adjusted p-value is below alpha x NAME_SHARE (docs/recordings.md
#: section 7, "Naming a cause"): a mismatch is raised at alpha, a physical cause -- which sends
#: someone to the machine -- is held to a risk a hundred times smaller
NAME_SHARE = 0.01


def check_alphas(alpha: float, alpha_name: float | None) -> float:
    """Validate alpha and alpha_name (default alpha x NAME_SHARE); return alpha_name."""
    if not (0.0 < alpha < 1.0):
        raise ModelError(f"alpha must be between 0 and 1, got {alpha!r}")
    if alpha_name is None:
        return alpha * NAME_SHARE
    if not (0.0 < alpha_name <= alpha):
        raise ModelError(f"alpha_name must be above 0 and at most alpha ({alpha:g}), got {alpha_name!r}")
    return float(alpha_name)


def diagnose_prepared(prep: Prepared, alpha: float = 0.01, alpha_name: float | None = None) -> Diagnosis:
    """Gates at alpha/2 each; the first effect named at adjusted p < alpha_name (default alpha/100),
    a best one between alpha_name and alpha reported as ``indicated``; further effects at alpha
    (docs/recordings.md section 7)."""
    alpha_name = check_alphas(alpha, alpha_name)
    W = structured_whitener(prep) if is_structured(prep) else Whitener(prep.C)
    yw = W(prep.r_um)
    Aw = W(prep.A)
    Q0, keptA = orth(Aw)
    rankA = len(keptA)
    y0 = project_out(Q0, yw)
    chi2_before = float(y0 @ y0)
    dof_before = W.rank - rankA
    if dof_before < 1:
        raise ModelError("no degrees of freedom left after the alignment: more records are needed")
    logp_before = chi2_logsf(chi2_before, dof_before)

    # -- candidates: applicability, sensitivity, identifiability against the baseline --------
    cands: dict[str, Candidate] = {}
    white: dict[str, np.ndarray] = {}
    basis: dict[str, np.ndarray] = {}
    for eff in fx.EFFECTS:
        c = Candidate(eff.name)
        cands[eff.name] = c
        if eff.name in fx.PERIODIC and is_structured(prep):
            c.status, c.reason = "not identifiable", (
                f"the period scan needs the dense covariance of the records (fewer than "
                f"{STRUCTURED_MIN_OBS} observations); diagnose a section of the scan")
            continue
        try:
            cols = fx.columns(prep.design, eff.name)
        except fx.NotApplicable as e:
            c.status, c.reason = "not identifiable", str(e)
            continue
        c.cols = cols
        big = np.max(np.abs(cols.X), axis=0) > fx.REL_ZERO * cols.full_scale
        if not np.any(big):
            c.status, c.reason = "not identifiable", "no sensitivity: " + why_zero(prep, eff.name)
            continue
        Xw = W(cols.X)
        raw = np.linalg.norm(Xw, axis=0)
        Z = project_out(Q0, Xw)
        Z[:, ~big] = 0.0
        Qc, kept = orth(Z, raw)
        if not kept:
            c.status = "not identifiable"
            c.reason = ("absorbed by the rigid alignment of the point records" if prep.A.shape[1]
                        else "no sensitivity: " + why_zero(prep, eff.name))
            continue
        c.kept = kept
        white[eff.name] = Xw
        basis[eff.name] = Qc
    identifiable = [n for n in fx.NAMES if cands[n].status == "untested"]

    # -- exact aliases: the first in the table stands for all of them ------------------------
    for i, a in enumerate(identifiable):
        if cands[a].status != "untested":
            continue
        for b in identifiable[i + 1:]:
            if cands[b].status != "untested":
                continue
            rho = cancorr(basis[a], basis[b])
            if rho > EXACT_ALIAS:
                cb = cands[b]
                cb.status, cb.aliased_with = "aliased", a
                cb.reason = alias_reason(prep, b, a, rho)

    # -- the targeted gate (docs/recordings.md section 7): every identifiable candidate of the
    # first step, Bonferroni over them; omnibus and targeted share alpha (alpha/2 each) ---------
    first = candidate_rows(prep, W, Q0, Q0, y0, white, cands, identifiable, [], scaled=False)
    if first:
        K1 = len(first)
        logp_targeted = min(0.0, min(r["logp"] for r in first) + math.log(K1))
    else:
        logp_targeted = 0.0
    half = math.log(GATE_SHARE * alpha)
    omnibus, targeted = logp_before < half, logp_targeted < half
    gate = "both" if omnibus and targeted else "omnibus" if omnibus else "targeted" if targeted else None
    mismatch = gate is not None

    outlier_search = mismatch and outliers_searchable(prep, W)
    overflow = False
    noise = None
    kept_answer = None
    groups_scaled: list[dict] = []
    if mismatch:
        srch = search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=outlier_search)
        overflow = srch.overflow
        if overflow:
            srch = search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=False)
        fit = refit(prep, W, keptA, srch)
        if fit[2] < math.log(alpha):
            # not explained: is the rest uniformly larger than the simulation allows, with no
            # structure any candidate or group explains?  The same search with the scale of the
            # covariance estimated (F-tests), then the groups against the scaled covariance
            sc = search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=outlier_search,
                         scaled=True)
            if sc.overflow:
                sc = search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=False, scaled=True)
            sfit = refit(prep, W, keptA, sc)
            beta_s, cov_s, chi2_s, dof_s = sfit[3], sfit[4], sfit[0], sfit[1]
            if dof_s >= 1:
                s2 = chi2_s / dof_s
                groups_scaled = groups_of(prep, W, sfit[5], beta_s, cov_s, labels_coef(prep, W, keptA, sc),
                                           alpha, scale2=s2, dof_scale=dof_s)
                if s2 > 1.0 and not any(g["flagged"] for g in groups_scaled):
                    noise = {"estimate": math.sqrt(s2), "u": math.sqrt(s2 / (2.0 * dof_s)),
                             "chi2": chi2_s, "dof": dof_s}
                    srch, fit = sc, sfit
        if srch.outliers:
            alt = search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=False,
                          scaled=noise is not None)
            afit = refit(prep, W, keptA, alt)
            kept_answer = {"effects": list(alt.chosen), "chi2_after": afit[0], "dof_after": afit[1],
                           "p_after": math.exp(afit[2]), "explained": bool(afit[2] >= math.log(alpha))}
    else:
        srch = Search({n: copy_candidate(c) for n, c in cands.items()}, [], [], [], [], Q0, y0)
        for name in identifiable:
            srch.cands[name].status = "not tested"
    cands, chosen, steps = srch.cands, srch.chosen, srch.steps

    # -- refit: GLS with the alignment, the chosen effects and the outliers left out ----------
    chi2_after, dof_after, logp_after, beta, cov, X_sel, labels = refit(prep, W, keptA, srch)
    beta0, cov0, _ = gls(W, prep.A[:, keptA], prep.r_um)
    resid_before = prep.r_um - prep.A[:, keptA] @ beta0
    resid_after = prep.r_um - X_sel @ beta
    # standard uncertainty of each residual under the baseline (alignment projected out)
    A = prep.A[:, keptA]
    var = prep.C.diagonal() if is_structured(prep) else np.diag(prep.C).copy()
    if A.shape[1]:
        var = var - np.einsum("ij,jk,ik->i", A, cov0, A)
    u_obs = np.sqrt(np.maximum(var, 1e-30))
    diag = Diagnosis(prep=prep, alpha=alpha, whitener=W, chi2_before=chi2_before, dof_before=dof_before,
                     logp_before=logp_before, mismatch=mismatch, candidates=cands, chosen=chosen,
                     steps=steps, X_sel=X_sel, sel_labels=labels, beta=beta, cov_beta=cov, beta0=beta0,
                     chi2_after=chi2_after, dof_after=dof_after, z_before=resid_before / u_obs,
                     z_after=resid_after / u_obs, u_obs=u_obs, resid_before=resid_before,
                     resid_after=resid_after, groups=[], located=[])
    diag.logp_targeted, diag.gate, diag.targeted_K = logp_targeted, gate, len(first)
    diag.logp_after = logp_after
    diag.outlier_search = outlier_search
    diag.outliers_not_isolated = overflow
    diag.outliers = outlier_report(diag, srch)
    diag.noise_scale = noise
    diag.groups_scaled = groups_scaled
    diag.with_outliers = kept_answer
    diag.alpha_name = alpha_name
    diag.indicated = indicated_report(prep, W, keptA, srch)
    diag.groups = locate_groups(diag)
    diag.groups_after = (groups_of(prep, W, X_sel, beta, cov, labels_coef(prep, W, keptA, srch), alpha,
                                    z=diag.z_after) if mismatch and not diag.explained else [])
    diag.located = locate_records(diag)
    if mismatch and not diag.explained:
        from . import discrepancy as disc  # section 7: the discrepancy, last, only when not explained
        diag.discrepancy = disc.fit(prep, W, X_sel, beta, alpha, chi2_after, dof_after, chi2_logsf, gls,
                                    f_logsf if noise is not None else None)
        if noise is not None and diag.discrepancy and diag.discrepancy["chosen"]:
            diag.noise_scale = None        # a smooth structure, not a uniformly larger noise
    diag.summary = summary_text(diag)
    if diag.discrepancy:
        head = diag.summary.rstrip()
        diag.summary = (head + ("" if head.endswith(".") or not head else ".") + " "
                        + disc.sentence(diag.discrepancy)).strip()
    return diag


def effect_covariance(prep: Prepared, name: str, W: Whitener | None = None, period_mm: float | None = None):
    """GLS covariance of the parameters of candidate ``name`` fitted alone with the baseline:
    ``(cov, labels)`` over its identifiable columns (the standard uncertainty a planted effect is
    measured against; used to size effects in the simulator and the benchmark; ``period_mm``: of a
    periodic_* candidate)."""
    if W is None:
        W = structured_whitener(prep, [name]) if is_structured(prep) else Whitener(prep.C)
    cols = fx.columns(prep.design, name, period_mm)
    Q0, keptA = orth(W(prep.A))
    Xw = W(cols.X)
    big = np.max(np.abs(cols.X), axis=0) > fx.REL_ZERO * cols.full_scale
    Z = project_out(Q0, Xw)
    Z[:, ~big] = 0.0
    _, kept = orth(Z, np.linalg.norm(Xw, axis=0))
    if not kept:
        raise fx.NotApplicable("not identifiable")
    X = np.column_stack([prep.A[:, keptA], cols.X[:, kept]])
    _, cov, _ = gls(W, X, prep.r_um)
    p0 = len(keptA)
    return cov[p0:, p0:], [cols.labels[j] for j in kept]
