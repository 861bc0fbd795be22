"""The answer (docs/recordings.md sections 3.2, 5 and 7): the ``Diagnosis``, where the mismatch
concentrates (records and groups, before and after the refit), the estimates of the chosen and
indicated effects, outliers, diagnosis.json and the plain-language summary."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..distributions import chi2_logsf, f_logcdf, f_logsf
from . import effects as fx
from .linalg import Whitener, gls, psd_chi2
from .model import Prepared, group_labels, is_structured
from .search import Candidate, Search, record_obs, refit


@dataclass
class Diagnosis:
    prep: Prepared
    alpha: float
    whitener: Whitener
    chi2_before: float
    dof_before: int
    logp_before: float
    mismatch: bool
    candidates: dict[str, Candidate]
    chosen: list[str]
    steps: list[list[dict]]
    X_sel: np.ndarray                 # baseline + chosen columns (n_obs x p)
    sel_labels: list[tuple[str, str]]  # (effect name or "alignment", parameter label)
    beta: np.ndarray
    cov_beta: np.ndarray
    beta0: np.ndarray                 # baseline-only estimates (alignment)
    chi2_after: float
    dof_after: int
    z_before: np.ndarray              # per observation row
    z_after: np.ndarray
    u_obs: np.ndarray                 # sqrt(diag C_e): standard uncertainty of each row's residual
    resid_before: np.ndarray          # r - A theta0
    resid_after: np.ndarray
    groups: list[dict]
    located: list[dict]
    summary: str = ""
    # second edition (docs/recordings.md section 7)
    logp_targeted: float = 0.0        # log of the Bonferroni-adjusted targeted p-value
    gate: str | None = None           # "omnibus", "targeted", "both" or None
    targeted_K: int = 0               # candidates of the targeted test
    logp_after: float = 0.0
    outlier_search: bool = False
    outliers_not_isolated: bool = False
    outliers: list[dict] = field(default_factory=list)
    noise_scale: dict | None = None
    groups_scaled: list[dict] = field(default_factory=list)
    groups_after: list[dict] = field(default_factory=list)   # only when not explained
    with_outliers: dict | None = None
    discrepancy: dict | None = None   # the last candidate, when not explained (xlfuncs/locator/discrepancy.py)
    alpha_name: float = 0.0           # adjusted p a cause must beat to be named (section 7)
    indicated: list[dict] = field(default_factory=list)   # significant at alpha, not at alpha_name

    @property
    def explained(self) -> bool:
        """The remaining chi-square after the refit passes: p_after >= alpha (section 7)."""
        return bool(self.logp_after >= math.log(self.alpha))

    # -- derived ---------------------------------------------------------------------------
    @property
    def rms_before_um(self) -> float:
        return float(np.sqrt(np.mean(self.resid_before**2)))

    @property
    def rms_after_um(self) -> float:
        return float(np.sqrt(np.mean(self.resid_after**2)))

    def effect_rows(self, name: str) -> list[int]:
        return [q for q, (e, _) in enumerate(self.sel_labels) if e == name]

    def to_json(self) -> dict:
        return diagnosis_json(self)


def indicated_report(prep: Prepared, W, keptA, S: Search) -> list[dict]:
    """``indicated`` of diagnosis.json: the effect the search found significant at alpha but not
    at alpha_name, with the estimate it would have in a refit with it (not applied)."""
    from dataclasses import replace

    out = []
    for name in S.indicated:
        c = S.cands[name]
        _, _, _, beta, cov, _, labels = refit(prep, W, keptA, replace(S, chosen=S.chosen + [name]))
        out.append({"name": name, **_estimates(prep, c, labels, beta, cov), "unit": fx.BY_NAME[name].unit,
                    "delta_chi2": c.delta_chi2, "p_value": math.exp(c.logp), "p_adjusted": c.p_adjusted,
                    "df": c.df, "step": c.step})
    return out


def outlier_report(diag: Diagnosis, S: Search) -> list[dict]:
    """``outliers`` of diagnosis.json: id, residual (after the baseline), z and the adjusted
    p-value of the record's likelihood-ratio test when it was flagged, and the gross error
    estimated by the refit (µm; a point: per coordinate)."""
    prep = diag.prep
    out = []
    obs = record_obs(prep)
    for a, row in zip(S.outliers, S.outlier_rows):
        rows = [q for q, (e, l) in enumerate(diag.sel_labels) if e == "outlier" and l == prep.rec.ids[a]]
        if prep.design.kind == "point":
            rows = [q for q, (e, l) in enumerate(diag.sel_labels) if e == "outlier" and
                    l.rsplit(".", 1)[0] == prep.rec.ids[a]]
        e = diag.resid_before[obs[a]]
        est = [float(diag.beta[q]) for q in rows]
        unc = [float(math.sqrt(max(diag.cov_beta[q, q], 0.0))) for q in rows]
        item = {"id": prep.rec.ids[a], "residual_um": float(e[0]) if len(e) == 1 else float(np.linalg.norm(e)),
                "z": math.copysign(math.sqrt(row["delta_chi2"]), float(e[0])) if len(e) == 1
                else math.sqrt(row["delta_chi2"]),
                "p_adjusted": math.exp(row["log_p_adjusted"]), "p_value": math.exp(row["logp"]),
                "df": row["df"], "step": row["step"],
                "estimate_um": est[0] if len(est) == 1 and prep.design.kind == "length" else est,
                "u_um": unc[0] if len(unc) == 1 and prep.design.kind == "length" else unc}
        if prep.design.kind == "point":
            item["axes"] = [diag.sel_labels[q][1].rsplit(".", 1)[1] for q in rows]
        out.append(item)
    return out


def locate_records(diag: Diagnosis, top: int = 10) -> list[dict]:
    """Records with the largest |z| (points: Mahalanobis length of the point's residual)."""
    prep = diag.prep
    rec = prep.rec
    if prep.design.kind == "length":
        z = diag.z_before
        order = np.argsort(-np.abs(z), kind="stable")[:top]
        return [{"id": rec.ids[a], "residual_um": float(diag.resid_before[a]), "z": float(z[a])} for a in order]
    dims = prep.design.dims
    e = diag.resid_before.reshape(rec.n, dims)
    zc = diag.z_before.reshape(rec.n, dims)
    # Mahalanobis length with the baseline-adjusted covariance of the point's coordinates
    A = prep.A
    cov0 = gls(diag.whitener, A, prep.r_um)[1] if A.shape[1] else None
    zm = np.empty(rec.n)
    blocks = prep.C.point_blocks() if is_structured(prep) else None
    for i in range(rec.n):
        sl = slice(dims * i, dims * i + dims)
        B = blocks[i] if blocks is not None else prep.C[sl, sl]
        if cov0 is not None:
            B = B - A[sl] @ cov0 @ A[sl].T
        zm[i] = math.sqrt(psd_chi2(e[i], B)[0])
    order = np.argsort(-zm, kind="stable")[:top]
    return [{"id": rec.ids[i], "residual_um": float(np.linalg.norm(e[i])), "z": float(zm[i]),
             "residual_xyz_um": [float(v) for v in e[i]], "z_xyz": [float(v) for v in zc[i]]}
            for i in order]


def groups_of(prep: Prepared, W, X: np.ndarray, beta: np.ndarray, cov: np.ndarray, X_coef, alpha: float,
               *, scale2: float = 1.0, dof_scale: int | None = None, z: np.ndarray | None = None) -> list[dict]:
    """Chi-square of the records of every group (section 3.2 groupings) for the residual
    e = r - X beta of a GLS fit, with the covariance of that residual, C - X cov X'.  With
    ``dof_scale``: judged against the covariance scaled by ``scale2`` (estimated on dof_scale
    degrees of freedom), an F-test; flagged when p < alpha / (number of groups)."""
    labels = group_labels(prep)
    structured = is_structured(prep)
    e = prep.r_um - X @ beta if X.shape[1] else prep.r_um.copy()
    if structured:
        e_coef = np.zeros(W.B.shape[1])
        e_coef[0] = 1.0
        if X.shape[1]:
            e_coef = e_coef - X_coef @ beta
    else:
        Ce = prep.C - X @ cov @ X.T if X.shape[1] else prep.C
    def chi2_of(by, g, idx):
        if structured:
            return W.group_chi2((by, g), e_coef, cov, X_coef), len(idx)
        return psd_chi2(e[idx], Ce[np.ix_(idx, idx)])

    def logp_of(chi2, dof):
        if not dof_scale:
            return chi2_logsf(chi2, dof)
        # uniform inflation: neither larger nor smaller than the common scale (two-sided)
        F = chi2 / dof / scale2
        return min(0.0, math.log(2.0) + min(f_logsf(F, dof, dof_scale), f_logcdf(F, dof, dof_scale)))

    extra = None if z is None else (lambda idx: {"rms_z": float(np.sqrt(np.mean(z[idx] ** 2)))})
    return _group_table(prep, labels, chi2_of, logp_of, extra, alpha)


def _group_table(prep: Prepared, labels: dict, chi2_of, logp_of, extra, alpha: float) -> list[dict]:
    """The rows of a group table: for every grouping and group, chi2_of(by, group, observation
    indices) -> (chi2, dof), its log p by logp_of, ``extra(idx)`` fields; flagged when p < alpha /
    (number of groups), sorted by p."""
    rows = []
    for by, lab in labels.items():
        lab_obs = [lab[a] for a in prep.obs_record]
        for g in dict.fromkeys(lab):
            idx = np.array([q for q, v in enumerate(lab_obs) if v == g])
            chi2, dof = chi2_of(by, g, idx)
            if dof == 0:
                continue
            item = {"by": by, "group": g, "records": int(len(set(prep.obs_record[idx]))),
                    "chi2": chi2, "dof": dof, "logp": logp_of(chi2, dof)}
            if extra is not None:
                item.update(extra(idx))
            rows.append(item)
    K = max(len(rows), 1)
    for r in rows:
        r["p_value"] = math.exp(r["logp"])
        r["flagged"] = bool(r["logp"] + math.log(K) < math.log(alpha))
    rows.sort(key=lambda r: r["logp"])
    return rows


def locate_groups(diag: Diagnosis) -> list[dict]:
    """Chi-square of the records of every group (docs/recordings.md section 3.2), with the baseline-adjusted
    covariance; flagged when p < alpha / (number of groups tested)."""
    prep = diag.prep
    labels = group_labels(prep)
    A = prep.A
    C = prep.C
    structured = is_structured(prep)
    cov0 = np.zeros((0, 0))
    if A.shape[1]:
        cov0 = gls(diag.whitener, A, prep.r_um)[1]
        if not structured:
            C = C - A @ cov0 @ A.T
    e = diag.resid_before
    if structured:   # e = r - A beta0 and A as combinations of the whitener's columns
        W = diag.whitener
        c = W.B.shape[1]
        p0 = A.shape[1]
        A_coef = np.zeros((c, p0))
        A_coef[1:1 + p0] = np.eye(p0)
        e_coef = np.zeros(c)
        e_coef[0] = 1.0
        if p0:
            e_coef[1:1 + p0] = -gls(W, A, prep.r_um)[0]
    def chi2_of(by, g, idx):
        if structured:
            return W.group_chi2((by, g), e_coef, cov0, A_coef), len(idx)
        return psd_chi2(e[idx], C[np.ix_(idx, idx)])

    def extra(idx):
        z = diag.z_before[idx]
        return {"mean_z": float(np.mean(z)), "rms_z": float(np.sqrt(np.mean(z**2)))}

    return _group_table(prep, labels, chi2_of, chi2_logsf, extra, diag.alpha)


# ---------------------------------------------------------------------------------------------
# reporting
# ---------------------------------------------------------------------------------------------

def effect_estimates(diag: Diagnosis, name: str) -> dict:
    """estimate/u of a chosen effect in its unit (vector effects: lists, None where a
    component is not identifiable; probe_qualification also per probe)."""
    return _estimates(diag.prep, diag.candidates[name], diag.sel_labels, diag.beta, diag.cov_beta)


def _estimates(prep: Prepared, c: Candidate, sel_labels, beta, cov_beta) -> dict:
    name = c.name
    rows = [q for q, (e, _) in enumerate(sel_labels) if e == name]
    est = {sel_labels[q][1]: float(beta[q]) for q in rows}
    unc = {sel_labels[q][1]: float(math.sqrt(max(cov_beta[q, q], 0.0))) for q in rows}
    eff = fx.BY_NAME[name]
    if not eff.vector:
        return {"estimate": est[name], "u": unc[name]}
    labels = c.cols.labels
    out = {"estimate": [est.get(l) for l in labels], "u": [unc.get(l) for l in labels]}
    if c.period_mm is not None:       # periodic_*: the period of the scan (section 7) and its u
        # the scan's period plus the refit's step for it (about 0: the scan's optimum)
        out["period_mm"] = c.period_mm + est.get("period_mm", 0.0)
        out["u_period_mm"] = unc.get("period_mm")
        out["periods_searched"] = c.n_periods
    if name == "probe_qualification":
        per = []
        for pid in prep.design.probe_ids[1:]:
            ls = [f"{pid}.d{a}" for a in fx.AXES]
            per.append({"probe": pid, "estimate": [est.get(l) for l in ls], "u": [unc.get(l) for l in ls]})
        out["per_probe"] = per
    return out


def unexplained_rest(diag: Diagnosis, top: int = 5) -> dict | None:
    """Where the chi-square that remains after the refit concentrates (None when explained):
    the groups of section 3.2 by their chi-square after the refit (with the refit's residual
    covariance C - X cov X'), largest first, and the records with the largest |z| after."""
    if not diag.mismatch or diag.explained:
        return None
    groups = [{k: v for k, v in g.items() if k != "logp"} for g in diag.groups_after[:top]]
    z = diag.z_after
    prep = diag.prep
    if prep.design.kind == "length":
        order = np.argsort(-np.abs(z), kind="stable")[:top]
        recs = [{"id": prep.rec.ids[a], "residual_um": float(diag.resid_after[a]), "z": float(z[a])}
                for a in order]
    else:
        dims = prep.design.dims
        zz = np.sqrt(np.sum(z.reshape(prep.rec.n, dims) ** 2, axis=1))
        order = np.argsort(-zz, kind="stable")[:top]
        e = diag.resid_after.reshape(prep.rec.n, dims)
        recs = [{"id": prep.rec.ids[i], "residual_um": float(np.linalg.norm(e[i])), "z": float(zz[i])}
                for i in order]
    return {"chi2_after": diag.chi2_after, "dof_after": diag.dof_after, "groups": groups, "records": recs}


def diagnosis_json(diag: Diagnosis) -> dict:
    prep = diag.prep
    out = {
        "records": prep.rec.n, "kind": prep.design.kind, "alpha": diag.alpha,
        "chi2_before": diag.chi2_before, "dof_before": diag.dof_before,
        "p_before": math.exp(diag.logp_before), "mismatch": diag.mismatch,
        "rms_before_um": diag.rms_before_um, "rms_after_um": diag.rms_after_um,
        "chi2_after": diag.chi2_after, "dof_after": diag.dof_after,
        "effects": [], "not_identifiable": [], "located": diag.located,
    }
    for name in diag.chosen:
        c = diag.candidates[name]
        e = {"name": name, **effect_estimates(diag, name), "unit": fx.BY_NAME[name].unit,
             "delta_chi2": c.delta_chi2, "p_value": math.exp(c.logp), "p_adjusted": c.p_adjusted,
             "df": c.df, "step": c.step, "log10_p_value": c.logp / math.log(10)}
        out["effects"].append(e)
    for name in fx.NAMES:
        c = diag.candidates[name]
        if c.status in ("not identifiable", "aliased"):
            item = {"name": name, "reason": c.reason}
            if c.aliased_with:
                item["aliased_with"] = c.aliased_with
            out["not_identifiable"].append(item)
    # extensions (spec: new keys welcome)
    out["p_after"] = math.exp(chi2_logsf(diag.chi2_after, diag.dof_after)) if diag.dof_after > 0 else None
    # second edition (docs/recordings.md section 7)
    out["p_targeted"] = math.exp(diag.logp_targeted) if diag.targeted_K else None
    out["gate"] = diag.gate
    out["explained"] = diag.explained
    out["outliers"] = diag.outliers if (diag.outlier_search or not diag.mismatch) else None
    out["outliers_not_isolated"] = diag.outliers_not_isolated
    out["with_outliers"] = diag.with_outliers
    out["noise_scale"] = diag.noise_scale
    out["unexplained"] = unexplained_rest(diag)
    out["discrepancy"] = diag.discrepancy
    out["alpha_name"] = diag.alpha_name
    out["indicated"] = diag.indicated
    out["log10_p_before"] = diag.logp_before / math.log(10)
    out["covariance_rank"] = diag.whitener.rank
    if is_structured(diag.prep):
        C = diag.prep.C
        out["approximation"] = {
            "method": "structured covariance D + U U^T (Woodbury), GP factors by pivoted-Cholesky "
                      "Nystrom factors", "pivot_tol": C.pivot_tol, "rank": dict(C.ranks),
            "covariance_error_bound_um2": C.eps_C, "chi2_relative_error_bound": C.chi2_bound()}
    out["candidates"] = [{
        "name": n, "status": c.status, "step": c.step, "df": c.df,
        "delta_chi2": c.delta_chi2, "p_value": None if c.logp is None else math.exp(c.logp),
        "p_adjusted": c.p_adjusted, "reason": c.reason} for n, c in diag.candidates.items()]
    out["steps"] = [[{"name": r["name"], "df": r["df"], "delta_chi2": r["delta_chi2"],
                      "p_value": math.exp(r["logp"]), "p_adjusted": math.exp(r["log_p_adjusted"])}
                     for r in sorted(s, key=lambda r: r["logp"])] for s in diag.steps]
    out["groups"] = [{k: v for k, v in g.items() if k != "logp"} for g in diag.groups]
    if prep.design.kind == "point":
        al = {lab: (float(diag.beta[q]), float(math.sqrt(diag.cov_beta[q, q])))
              for q, (e, lab) in enumerate(diag.sel_labels) if e == "alignment"}
        out["alignment"] = {
            "dims": prep.design.dims,
            "initial_rotation": prep.R0.tolist(), "initial_translation_mm": prep.t0.tolist(),
            "refit": {k: {"estimate": v[0], "u": v[1]} for k, v in al.items()},
        }
    out["summary"] = diag.summary
    return _json_safe(out)


def _json_safe(v):
    """Plain JSON: numpy scalars to Python, non-finite numbers to None."""
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if math.isfinite(v) else None
    return v


PLAIN_UNITS = {"um/m": "µm/m", "urad": "µrad", "ppm/K": "ppm/K", "um": "µm", "urad/m": "µrad/m",
               "um/m/h": "µm/m per hour", "um/h": "µm/h", "ppm/K/m": "ppm/K per m"}


def _fmt_pm(est: float, u: float) -> str:
    digits = max(0, min(6, 1 - int(math.floor(math.log10(abs(u)))) if u > 0 else 2))
    return f"{est:.{digits}f} ± {u:.{digits}f}"


def _period_words(est: dict) -> str:
    """', period 71.97 ± 0.20 mm' of a periodic error ('' for other effects)."""
    if est.get("period_mm") is None:
        return ""
    u = est.get("u_period_mm")
    return f", period {_fmt_pm(est['period_mm'], u) if u else format(est['period_mm'], '.4g')} mm"


def where_seen(diag: Diagnosis, name: str) -> str:
    """Plain words for where the fitted effect concentrates (the smallest share of the records
    carrying 80 % of its standardized signal)."""
    prep = diag.prep
    rows = diag.effect_rows(name)
    f = diag.X_sel[:, rows] @ diag.beta[rows]
    s_obs = (f / diag.u_obs) ** 2
    n = prep.rec.n
    s = np.bincount(prep.obs_record, weights=s_obs, minlength=n)
    total = s.sum()
    if total <= 0:
        return ""
    best = None
    labels = group_labels(prep)
    pref = ["direction", "probing", "probe", "temperature", "time", "group"]
    for by in sorted(labels, key=lambda b: pref.index(b) if b in pref else len(pref)):
        lab = labels[by]
        shares: dict[str, float] = {}
        counts: dict[str, int] = {}
        for a, g in enumerate(lab):
            shares[g] = shares.get(g, 0.0) + s[a]
            counts[g] = counts.get(g, 0) + 1
        acc, sel = 0.0, []
        for g in sorted(shares, key=lambda g: -shares[g] / counts[g]):
            sel.append(g)
            acc += shares[g]
            if acc >= 0.8 * total:
                break
        frac = sum(counts[g] for g in sel) / n
        rest = max(total - acc, 0.0) / total
        # concentrated: the selected records carry the signal at least 4 times as densely
        dense = rest <= 1e-12 or (acc / total / frac) >= 4.0 * (rest / (1.0 - frac))
        if frac <= 0.75 and dense and (best is None or frac < best[0] - 1e-12):
            best = (frac, by, sel)
    if best is None:
        return "spread over all records"
    _, by, sel = best
    if by == "direction":
        if all(sum(ch in fx.AXES for ch in g) >= 2 for g in sel):
            return "seen in the diagonal lengths (" + ", ".join(sel[:4]) + ("…" if len(sel) > 4 else "") + ")"
        return "seen in the lengths along " + ", ".join(sel[:4])
    if by == "probing":
        return f"seen in the {' and '.join(sel)} lengths"
    if by == "probe":
        return "seen in the records with probe " + ", ".join(sel[:4])
    if by == "temperature":
        return "seen in the records at " + ", ".join(sel)
    if by == "time":
        return "seen in the records at " + ", ".join(sel) + " into the session"
    return "seen in group " + ", ".join(sel[:4])


def summary_text(diag: Diagnosis) -> str:
    """The short plain-language answer printed on the terminal."""
    r = diag.chi2_before / diag.dof_before
    if not diag.mismatch:
        return (f"the records agree with the simulation (chi2/dof {r:.2f}, p = "
                f"{math.exp(diag.logp_before):.2g}); no effect is needed")
    head = f"the records disagree with the simulation (chi2/dof {r:.2f}"
    if diag.gate == "targeted":
        head += f"; the omnibus test alone would pass, the targeted test fires: p = {math.exp(diag.logp_targeted):.2g}"
    head += ")"
    pieces = []
    for o in diag.outliers:
        pieces.append(f"record {o['id']} is a gross outlier (residual {o['residual_um']:.3g} µm, "
                      f"z = {o['z']:.1f}, adjusted p = {o['p_adjusted']:.2g}) and is left out of the effect search")
    if diag.noise_scale:
        ns = diag.noise_scale
        pieces.append(f"the residuals are uniformly larger than the simulation allows, with no structure a "
                      f"candidate or group explains: the declared uncertainties are too small by a factor "
                      f"{_fmt_pm(ns['estimate'], ns['u'])}" + ("" if diag.chosen else "; no physical effect is chosen"))
    for ind in diag.indicated:
        eff = fx.BY_NAME[ind["name"]]
        if eff.vector:
            c = diag.candidates[ind["name"]]
            val = "; ".join(f"{l} {_fmt_pm(e, u)}" for l, e, u in zip(c.cols.labels, ind["estimate"], ind["u"])
                            if e is not None) + f" {PLAIN_UNITS[eff.unit]}" + _period_words(ind)
        else:
            val = f"{_fmt_pm(ind['estimate'], ind['u'])} {PLAIN_UNITS[eff.unit]}"
        pieces.append(f"{eff.plain} of {val} is indicated (adjusted p = {ind['p_adjusted']:.2g}) but not "
                      f"named: a cause is named only at adjusted p < {diag.alpha_name:.2g}, so it is not "
                      f"applied; more records that see it would tell")
    if not diag.chosen and not pieces:
        loc = diag.located[0] if diag.located else None
        tail = f"; the largest is {loc['id']} (z = {loc['z']:.1f})" if loc else ""
        return (head + "; none of the candidate effects explains it significantly: look at the records "
                "listed under 'located'" + tail)
    # "x % of the excess" only where it means that: an excess chi2 - dof > 0 that the chosen
    # effects' delta chi2 do not overrun.  A mismatch the targeted test found while chi2/dof <= 1
    # (no excess at all), or effects worth more than the excess, are told by their delta chi2.
    excess = diag.chi2_before - diag.dof_before
    deltas = [float(diag.candidates[n].delta_chi2 or 0.0) for n in diag.chosen]
    by_share = excess > 0 and sum(deltas) <= excess * (1 + 1e-9)
    parts = []
    for name, delta in zip(diag.chosen, deltas):
        c = diag.candidates[name]
        eff = fx.BY_NAME[name]
        est = effect_estimates(diag, name)
        if eff.vector:
            comp = [(l, e, u) for l, e, u in zip(c.cols.labels, est["estimate"], est["u"]) if e is not None]
            val = "; ".join(f"{l} {_fmt_pm(e, u)}" for l, e, u in comp) + f" {PLAIN_UNITS[eff.unit]}" \
                + _period_words(est)
        else:
            val = f"{_fmt_pm(est['estimate'], est['u'])} {PLAIN_UNITS[eff.unit]}"
        seen = where_seen(diag, name)
        if by_share:
            lead = f"{delta / excess * 100:.0f} % of the excess is explained by {eff.plain} of {val}"
        else:
            p = f", adjusted p = {c.p_adjusted:.2g}" if c.p_adjusted is not None else ""
            lead = f"{eff.plain} of {val} (delta chi2 = {delta:.1f} on {c.df} dof{p})"
            if not parts:
                lead = ("the test aimed at the candidates finds " if diag.gate == "targeted"
                        else "the search finds ") + lead
        parts.append(lead + (f", {seen}" if seen else ""))
    after = diag.chi2_after / max(diag.dof_after, 1)
    text = head + "; " + "; ".join(pieces + (["; then ".join(parts)] if parts else []))
    if diag.chosen or diag.outliers:
        what = ("it" if len(diag.chosen) + len(diag.outliers) == 1 else "them")
        text += f"; after {f'leaving {what} out' if not diag.chosen else f'adding {what}'} chi2/dof is {after:.2f}"
    if not diag.explained and not diag.noise_scale:
        rest = unexplained_rest(diag)
        where = ""
        if rest and rest["groups"] and rest["groups"][0]["flagged"]:
            g = rest["groups"][0]
            where = f"; the rest concentrates in {g['by']} {g['group']} (chi2 {g['chi2']:.1f} on {g['dof']} dof)"
        elif rest and rest["records"]:
            where = f"; no group stands out, the largest is {rest['records'][0]['id']} (z = {rest['records'][0]['z']:.1f})"
        text += (f". This is not the whole story: what remains still fails (p_after = "
                 f"{math.exp(diag.logp_after):.2g}){where}")
    if diag.with_outliers is not None and diag.with_outliers["effects"] != diag.chosen:
        kept = diag.with_outliers["effects"]
        text += (". With the outliers kept the search would choose " + (", ".join(kept) if kept else "nothing"))
    groups: dict[tuple[str, str], list[str]] = {}
    for c in diag.candidates.values():
        if c.status == "aliased" and c.aliased_with in diag.chosen:
            groups.setdefault((c.aliased_with, c.reason.rsplit("; ", 1)[-1]), []).append(c.name)
    for (other, hint), names in list(groups.items())[:3]:
        who = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
        text += f". {who} cannot be told apart from {other} with these records: {hint}"
    return text
