"""The candidates and the search (docs/recordings.md sections 3-4 and 7, docs/diagnose.md sections
3 and 6): likelihood-ratio tests of every candidate effect and of every single record as a gross
outlier, the forward selection (Bonferroni per step; the first cause named only below alpha_name),
aliases and why a candidate has no sensitivity, and the refit with what was chosen."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..distributions import chi2_logsf, f_logsf
from . import effects as fx
from .linalg import Whitener, cancorr, gls, orth, project_out
from .model import Prepared, is_structured

ALIAS_CORR = 0.98           # docs/recordings.md section 3.3
EXACT_ALIAS = 1.0 - 1e-5    # "exact" aliases: canonical correlation 1 up to the noise of indicated
MAX_STEPS = 12


# ---------------------------------------------------------------------------------------------
# the candidates, their tests and the forward search
# ---------------------------------------------------------------------------------------------

@dataclass
class Candidate:
    name: str
    cols: fx.Columns | None = None
    kept: list[int] = field(default_factory=list)     # identifiable columns
    reason: str | None = None                         # not identifiable / aliased
    aliased_with: str | None = None
    status: str = "untested"                          # chosen | indicated | tested | aliased | not identifiable
    step: int | None = None
    delta_chi2: float | None = None
    df: int = 0
    logp: float | None = None
    p_adjusted: float | None = None
    # periodic_*: the period found by the scan and log M, M the periods of the scan's grid (the
    # look-elsewhere correction, added to logp: docs/diagnose.md section 6)
    period_mm: float | None = None
    n_periods: int | None = None
    lin_ab: tuple[float, float] | None = None    # (a, b) the period column is linearized at

    @property
    def look_elsewhere(self) -> float:
        """log M (0 for a candidate without a scanned period)."""
        return math.log(self.n_periods) if self.n_periods else 0.0


GATE_SHARE = 0.5           # each of the two gates judged at alpha/2 (docs/recordings.md section 7)
MAX_OUTLIER_SHARE = 0.03   # isolated outliers: at most this share of the records (and at least 2);
                           # when more look gross, it is a structure and no record is called an outlier
OUTLIER_MAX_OBS = 4000     # the outlier search needs the dense whitener (n_obs^2 numbers)


def outliers_searchable(prep: Prepared, W) -> bool:
    """Single-record outliers are searched with the dense whitener (W as a matrix)."""
    return isinstance(W, Whitener) and W.W.shape[1] <= OUTLIER_MAX_OBS


@dataclass
class Search:
    cands: dict[str, Candidate]
    chosen: list[str]
    steps: list[list[dict]]
    outliers: list[int]              # record indices, in the order flagged
    outlier_rows: list[dict]         # their statistics when flagged
    Q: np.ndarray
    resid: np.ndarray
    outlier_cols: list[tuple[int, list[int]]] = field(default_factory=list)  # (record, kept rows)
    overflow: bool = False           # more records than MAX_OUTLIER_SHARE looked gross: structure
    indicated: list[str] = field(default_factory=list)   # best effect between alpha_name and alpha


def copy_candidate(c: Candidate) -> Candidate:
    from dataclasses import replace

    return replace(c, kept=list(c.kept))


def _test_logp(dchi: float, df: int, rest: float, nu: int, scaled: bool) -> float | None:
    """log p of adding df columns that lower chi-square by dchi: chi-square with C known, or the
    F-test with the scale of C estimated from the rest (nu - df degrees of freedom)."""
    if not scaled:
        return chi2_logsf(dchi, df)
    d2 = nu - df
    if d2 < 1:
        return None
    rest_after = max(rest - dchi, 1e-300)
    return f_logsf((dchi / df) / (rest_after / d2), df, d2)


def candidate_rows(prep, W, Q0, Q, resid, white, cands, identifiable, chosen, scaled=False, mutate=False):
    """The candidates of one step: Δχ², df, log p for every contender (``mutate``: mark aliased)."""
    rows = []
    nu = W.rank - Q.shape[1]
    rest = float(resid @ resid)
    for name in identifiable:
        c = cands[name]
        if c.status not in ("untested", "tested"):
            continue
        if name in fx.PERIODIC:
            scan_period(prep, W, Q0, Q, resid, white, c)
            if not c.kept:
                continue
        Xk = white[name][:, c.kept]
        if chosen:
            alias = _alias_with_chosen(Q0, white, cands, chosen, name)
            if alias is not None:
                if mutate:
                    other, rho = alias
                    c.status, c.aliased_with = "aliased", other
                    c.reason = alias_reason(prep, name, other, rho)
                continue
        Z = project_out(Q, Xk)
        Qz, kz = orth(Z, np.linalg.norm(project_out(Q0, Xk), axis=0))
        if not kz:
            if mutate:
                c.status, c.aliased_with = "aliased", " + ".join(chosen)
                c.reason = alias_reason(prep, name, " + ".join(chosen), 1.0)
            continue
        dchi = float(np.sum((Qz.T @ resid) ** 2))
        df = len(kz)
        logp = _test_logp(dchi, df, rest, nu, scaled)
        if logp is None:
            continue
        logp = min(0.0, logp + c.look_elsewhere)
        rows.append({"name": name, "df": df, "delta_chi2": dchi, "logp": logp, "kz": kz, "Qz": Qz})
    return rows


PERIOD_REFINE_STEPS = 40     # golden-section steps of the period between the grid's neighbours
PERIOD_TIE = 1e-9            # relative: equally good alias periods, the longest taken


def _period_dchi(Z: np.ndarray, resid: np.ndarray) -> np.ndarray:
    """Δχ² of every (sin, cos) pair of columns of Z (n x 2G, already projected): b' G^+ b."""
    n2 = Z.shape[1] // 2
    Zs, Zc = Z[:, 0::2], Z[:, 1::2]
    g11, g22, g12 = np.sum(Zs * Zs, 0), np.sum(Zc * Zc, 0), np.sum(Zs * Zc, 0)
    b1, b2 = Zs.T @ resid, Zc.T @ resid
    det = g11 * g22 - g12**2
    scale = np.maximum(g11 * g22, 1e-300)
    full = det > 1e-9 * scale
    out = np.zeros(n2)
    out[full] = (g22 * b1**2 - 2 * g12 * b1 * b2 + g11 * b2**2)[full] / det[full]
    one = ~full                     # the pair is (nearly) one column: its larger one alone
    big = np.where(g11 >= g22, b1**2 / np.maximum(g11, 1e-300), b2**2 / np.maximum(g22, 1e-300))
    out[one] = big[one]
    return out


def scan_period(prep, W, Q0, Q, resid, white, c: Candidate) -> None:
    """The period of a ``periodic_*`` candidate given what is fitted already (Q, resid): the
    largest drop of chi-square over the grid of :func:`xlfuncs.locator.effects.period_grid` (the longest
    of equally good alias periods), refined by golden section between the grid's neighbours.
    Sets the candidate's columns, its whitened columns in ``white``, the kept columns (against
    the baseline Q0, as for every candidate) and the look-elsewhere term log M."""
    D = prep.design
    a = fx.AXES.index(c.name[-1])
    periods, M = fx.period_grid(D, a)
    X = np.column_stack([fx.periodic_columns(D, c.name, float(P)).X for P in periods])
    Z = project_out(Q, W(X))
    d = _period_dchi(Z, resid)
    best = int(np.flatnonzero(d >= d.max() * (1.0 - PERIOD_TIE))[0])   # grid is longest first

    def dchi_at(f: float) -> float:
        Zp = project_out(Q, W(fx.periodic_columns(D, c.name, 1.0 / f).X))
        return float(_period_dchi(Zp, resid)[0])

    f = 1.0 / periods
    lo, hi = f[max(best - 1, 0)], f[min(best + 1, len(f) - 1)]
    g = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    d1, d2 = dchi_at(x1), dchi_at(x2)
    for _ in range(PERIOD_REFINE_STEPS):
        if d1 >= d2:
            hi, x2, d2 = x2, x1, d1
            x1 = hi - g * (hi - lo)
            d1 = dchi_at(x1)
        else:
            lo, x1, d1 = x1, x2, d2
            x2 = lo + g * (hi - lo)
            d2 = dchi_at(x2)
    f_best, d_best = (x1, d1) if d1 >= d2 else (x2, d2)
    P = float(1.0 / f_best) if d_best > d[best] else float(periods[best])
    cols = fx.periodic_columns(D, c.name, P)
    Xw = W(cols.X)
    _, kept = orth(project_out(Q0, Xw), np.linalg.norm(Xw, axis=0))
    c.cols, c.kept, white[c.name] = cols, kept, Xw
    c.period_mm, c.n_periods = P, M


def record_obs(prep: Prepared) -> list[np.ndarray]:
    n = prep.rec.n
    order = np.argsort(prep.obs_record, kind="stable")
    bounds = np.searchsorted(prep.obs_record[order], np.arange(n + 1))
    return [order[bounds[a]:bounds[a + 1]] for a in range(n)]


def _outlier_rows(prep, W, Q, resid, skip, scaled=False):
    """Likelihood-ratio test of a gross error in every single record (a point: its coordinates):
    the drop of chi-square when that record's own mean-shift columns are added (the record left
    out), with C known or (``scaled``) as an F-test.  Bonferroni over the records tested.  A
    column whose whitened remainder after Q is below 1e-3 of its norm is not testable."""
    Wm = W.W
    nu = W.rank - Q.shape[1]
    rest = float(resid @ resid)
    n = prep.rec.n
    d = len(prep.r_um) // n                      # observations per record (1, 2 or 3)
    todo = np.array([a for a in range(n) if a not in skip], dtype=int)
    rows = []
    chunk = max(1, 768 // d)
    for q0 in range(0, len(todo), chunk):
        recs = todo[q0:q0 + chunk]
        cols = (recs[:, None] * d + np.arange(d)[None, :]).reshape(-1)   # obs of record a: d*a + axis
        Wc = Wm[:, cols]
        Z = project_out(Q, Wc)
        ok = np.linalg.norm(Z, axis=0) > 1e-3 * np.linalg.norm(Wc, axis=0)
        Z = Z * ok
        b = (Z.T @ resid).reshape(len(recs), d)
        Zr = Z.reshape(Z.shape[0], len(recs), d)
        G = np.einsum("kia,kib->iab", Zr, Zr)
        lam, V = np.linalg.eigh(G)
        keep = lam > 1e-9 * np.maximum(lam.max(axis=1, keepdims=True), 1e-300)
        proj = np.einsum("iab,ia->ib", V, b)
        dchis = np.sum(np.where(keep, proj**2 / np.where(keep, lam, 1.0), 0.0), axis=1)
        dfs = keep.sum(axis=1)
        for t, a in enumerate(recs):
            df = int(dfs[t])
            if df == 0:
                continue
            dchi = float(dchis[t])
            logp = _test_logp(dchi, df, rest, nu, scaled)
            if logp is None:
                continue
            rows.append({"record": int(a), "df": df, "delta_chi2": dchi, "logp": logp, "chunk": (Zr, t),
                         "rows": [int(d * a + j) for j in range(d) if ok.reshape(len(recs), d)[t, j]]})
    K = max(len(rows), 1)
    for r in rows:
        r["log_p_adjusted"] = min(0.0, r["logp"] + math.log(K))
    best = min(rows, key=lambda r: (r["log_p_adjusted"], r["record"])) if rows else None
    if best is not None:        # the orthonormal columns of the best one only
        Zr, t = best["chunk"]
        best["Qz"], _ = orth(Zr[:, t, :])
    for r in rows:
        r.pop("chunk")
    return rows


def search(prep, W, Q0, y0, white, cands_in, identifiable, alpha, alpha_name, *, outliers=False,
            scaled=False):
    """Forward selection (docs/recordings.md section 3.3 and section 7): in every step the best
    candidate effect (Bonferroni over the candidates of that step) and, with ``outliers``, the
    record whose gross error would lower chi-square most (Bonferroni over the records); the one
    with the smaller adjusted p-value is taken while that is below alpha -- the first effect only
    below alpha_name: one between alpha_name and alpha is ``indicated`` and the search stops.
    ``scaled``: F-tests with the scale of the covariance estimated from what remains (the
    noise-level answer)."""
    cands = {n: copy_candidate(c) for n, c in cands_in.items()}
    S = Search(cands, [], [], [], [], Q0, y0)
    order = {n: i for i, n in enumerate(fx.NAMES)}
    max_out = max(2, math.ceil(MAX_OUTLIER_SHARE * prep.rec.n))
    for step in range(1, MAX_STEPS + 1):
        rows = candidate_rows(prep, W, Q0, S.Q, S.resid, white, cands, identifiable, S.chosen, scaled,
                            mutate=True)
        out_rows = (_outlier_rows(prep, W, S.Q, S.resid, set(S.outliers), scaled)
                    if outliers and not S.overflow else [])
        if not rows and not out_rows:
            break
        best = None
        if rows:
            K = len(rows)
            for row in rows:
                row["log_p_adjusted"] = min(0.0, row["logp"] + math.log(K))
                c = cands[row["name"]]
                c.status, c.step = "tested", step
                c.delta_chi2, c.df, c.logp = row["delta_chi2"], row["df"], row["logp"]
                c.p_adjusted = math.exp(row["log_p_adjusted"])
            best = min(rows, key=lambda r: (r["logp"], -r["delta_chi2"], order[r["name"]]))
            # exact aliases given what is chosen already: the first in the table of section 4
            ties = [r for r in rows if order[r["name"]] < order[best["name"]]
                    and cancorr(r["Qz"], best["Qz"]) > EXACT_ALIAS]
            if ties:
                best = min(ties, key=lambda r: order[r["name"]])
            S.steps.append([{k: v for k, v in r.items() if k not in ("kz", "Qz")} for r in rows])
        best_out = min(out_rows, key=lambda r: (r["log_p_adjusted"], r["record"])) if out_rows else None
        wants_out = best_out is not None and best_out["log_p_adjusted"] < math.log(alpha) and (
            best is None or best_out["log_p_adjusted"] <= best["log_p_adjusted"])
        if wants_out and len(S.outliers) >= max_out:
            # more gross records than isolated outliers can be: a structure, not outliers
            S.overflow, wants_out = True, False
            break
        if wants_out:
            # outliers before physics: the record is left out of the rest of the search
            S.outliers.append(best_out["record"])
            S.outlier_rows.append({k: v for k, v in best_out.items() if k != "Qz"} | {"step": step})
            best_out["rows"] = [q for q in best_out["rows"]]
            S.outlier_cols.append((best_out["record"], best_out["rows"]))
            S.Q = np.column_stack([S.Q, best_out["Qz"]])
            S.resid = project_out(best_out["Qz"], S.resid)
        elif best is not None and best["log_p_adjusted"] < math.log(alpha):
            if S.outliers and not S.chosen and not _still_mismatch(W, S, best, alpha, scaled):
                break     # the outliers explain the mismatch: no gate opens for physics
            c = cands[best["name"]]
            if not S.chosen and best["log_p_adjusted"] >= math.log(alpha_name):
                # the first cause: significant, but not at the level a cause is named at --
                # indicated, not chosen (once one is named the records do differ, and further
                # effects are chosen at alpha as in section 3)
                c.status = "indicated"
                c.kept = [c.kept[j] for j in best["kz"]]
                S.indicated.append(best["name"])
                break
            c.status = "chosen"
            c.kept = [c.kept[j] for j in best["kz"]]
            S.chosen.append(best["name"])
            S.Q = np.column_stack([S.Q, best["Qz"]])
            S.resid = project_out(best["Qz"], S.resid)
        else:
            break
        if W.rank - S.Q.shape[1] < 2:
            break
    for name in identifiable:
        if cands[name].status == "untested":
            cands[name].status = "not tested"
    return S


def _still_mismatch(W, S: Search, best: dict, alpha: float, scaled: bool) -> bool:
    """With the outliers left out, do the records still disagree by the two gates (omnibus on
    what remains, or the best candidate of this step, alpha/2 each)?  (Scaled search: the
    targeted gate only, the omnibus has no meaning when the scale is estimated.)"""
    half = math.log(GATE_SHARE * alpha)
    if best["log_p_adjusted"] < half:
        return True
    nu = W.rank - S.Q.shape[1]
    return (not scaled) and nu > 0 and chi2_logsf(float(S.resid @ S.resid), nu) < half


def refit(prep, W, keptA, S: Search):
    """GLS with the alignment, the chosen effects and the outliers' mean-shift columns:
    (chi2, dof, log p, beta, cov, X_sel, labels).  A chosen ``periodic_*`` adds its period's
    column (:func:`xlfuncs.locator.effects.period_column`, label "period_mm") linearized at the fit
    with the period fixed (``Candidate.lin_ab``): the period is a fitted parameter too."""
    with_period = [n for n in S.chosen if n in fx.PERIODIC and len(S.cands[n].kept) == 2]
    if with_period:
        _, _, _, beta0, _, _, labels0 = _refit_columns(prep, W, keptA, S, {})
        lin = {n: tuple(float(beta0[labels0.index((n, p))]) for p in ("a", "b")) for n in with_period}
        for n, ab in lin.items():
            S.cands[n].lin_ab = ab
        return _refit_columns(prep, W, keptA, S, lin)
    return _refit_columns(prep, W, keptA, S, {})


def _refit_columns(prep, W, keptA, S: Search, lin: dict):
    X_parts = [prep.A[:, keptA]]
    labels = [("alignment", prep.A_labels[j]) for j in keptA]
    for name in S.chosen:
        c = S.cands[name]
        X_parts.append(c.cols.X[:, c.kept])
        labels += [(name, c.cols.labels[j]) for j in c.kept]
        if name in lin:
            X_parts.append(fx.period_column(prep.design, name, c.period_mm, *lin[name])[:, None])
            labels.append((name, "period_mm"))
    n_obs = len(prep.r_um)
    for a, rows in S.outlier_cols:
        E = np.zeros((n_obs, len(rows)))
        E[rows, np.arange(len(rows))] = 1.0
        X_parts.append(E)
        rid = prep.rec.ids[a]
        if prep.design.kind == "length":
            labels.append(("outlier", rid))
        else:
            labels += [("outlier", f"{rid}.{fx.AXES[int(prep.obs_axis[q])]}") for q in rows]
    X_sel = np.column_stack(X_parts) if X_parts else np.zeros((n_obs, 0))
    beta, cov, chi2 = gls(W, X_sel, prep.r_um)
    dof = W.rank - X_sel.shape[1]
    logp = chi2_logsf(chi2, dof) if dof > 0 else 0.0
    return chi2, dof, logp, beta, cov, X_sel, labels


def labels_coef(prep, W, keptA, S: Search):
    """X_sel of :func:`refit` as combinations of the structured whitener's columns (None: dense)."""
    if not is_structured(prep):
        return None
    c = W.B.shape[1]
    cols = [1 + j for j in keptA]
    for name in S.chosen:
        cols += [W.where[name] + j for j in S.cands[name].kept]
    M = np.zeros((c, len(cols)))
    M[cols, np.arange(len(cols))] = 1.0
    return M


def _alias_with_chosen(Q0, white, cands, chosen, name):
    """(chosen effect, canonical correlation) when ``name`` is aliased (> 0.98) with one chosen
    effect after projecting out the alignment and the other chosen effects, or with all of them
    together after projecting out the alignment."""
    if not chosen:
        return None
    Xc = white[name][:, cands[name].kept]
    best = (None, 0.0)
    for e in chosen:
        others = [white[o][:, cands[o].kept] for o in chosen if o != e]
        Qo = Q0
        if others:
            Qo, _ = orth(np.column_stack([Q0, *others]))
        Qa, _ = orth(project_out(Qo, Xc), np.linalg.norm(project_out(Q0, Xc), axis=0))
        Qb, _ = orth(project_out(Qo, white[e][:, cands[e].kept]))
        rho = cancorr(Qa, Qb) if Qa.shape[1] else 1.0
        if rho > best[1]:
            best = (e, rho)
    if len(chosen) > 1:
        Qa, _ = orth(project_out(Q0, Xc))
        Qb, _ = orth(project_out(Q0, np.column_stack([white[o][:, cands[o].kept] for o in chosen])))
        rho = cancorr(Qa, Qb)
        if rho > ALIAS_CORR and rho > best[1] + 1e-9:
            best = (" + ".join(chosen), rho)
    return best if best[1] > ALIAS_CORR else None


def why_zero(prep: Prepared, name: str) -> str:
    D = prep.design
    if name.startswith("scale_") and name[-1] in fx.AXES:
        return f"the records do not extend along {name[-1]}"
    if name.startswith("squareness_"):
        return f"no record extends along both {name[-2]} and {name[-1]} (diagonals in that plane)"
    if name == "probe_qualification":
        return ("every length is probed with one probe at both ends, so a probe offset error cancels"
                if D.kind == "length" else "the probes' offsets cancel in these records")
    if name in fx.ANGULAR:
        return (f"the probe offsets are parallel to the rotation axis of {name} or the {name[2]} "
                "carriage does not move")
    if name == "probe_radius":
        return "every length is probed in one direction at both ends (unidirectional), so a radius error cancels"
    if name in fx.STRAIGHTNESS:
        return (f"no record sees its {name[1].lower()} coordinate change along the {name[2]} travel "
                f"(lengths along {name[2].lower()} only, or no {name[1].lower()} coordinate)")
    if name == "probe_lobing":
        return "no point is approached from a direction around the stylus axis that lobing would move"
    if name in fx.REVERSAL:
        return (f"no length is probed from opposite sides along {name[-1]} at its two ends"
                if D.kind == "length" else f"the records have no {name[-1]} coordinate")
    return "these records do not respond to it"


def alias_reason(prep: Prepared, name: str, other: str, rho: float) -> str:
    """'aliased with scale_x (canonical correlation 1.000000): one probe offset only; a second
    probe offset would separate them (Forbes 2025 section 3.3)'."""
    D = prep.design
    a, b = fx.BY_NAME.get(name), fx.BY_NAME.get(other.split(" + ")[0])
    why = ""
    hint = a.hint if a is not None else ""
    pair = {name, *other.split(" + ")}
    n_offsets = len({tuple(np.round(p, 6)) for p in (np.vstack([D.P1, D.P2]) if D.kind == "length" else D.P)})
    if pair & set(fx.ANGULAR):
        if n_offsets == 1:
            why = "one probe offset only; "
        hint = fx.BY_NAME["EAX"].hint
    elif "thermal_expansion" in pair:
        why = "the temperatures do not vary enough; "
        hint = fx.BY_NAME["thermal_expansion"].hint
    elif pair & {"scale_drift", "offset_drift"}:
        why = "time order follows length or position; "
        hint = fx.BY_NAME["scale_drift"].hint
    elif "probe_radius" in pair or "probe_qualification" in pair:
        hint = fx.BY_NAME["probe_radius"].hint if "probe_radius" in pair else fx.BY_NAME["probe_qualification"].hint
    elif b is not None and b.hint:
        hint = a.hint if a is not None else b.hint
    return (f"aliased with {other} (canonical correlation {rho:.6f}): {why}these records cannot tell "
            f"them apart; {hint} would separate them")
