"""The diagnosis plots (PNG, ``cmmwb diagnose``): standardized residuals before and after the
refit, against the quantities that reveal effects, and one figure per chosen effect."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs.locator import effects as fx
from cmmwb.xlfuncs.locator.diagnose import Diagnosis, effect_estimates


def _plt():
    from ..workbook.plots import pyplot  # headless, '$' in record ids and groups taken literally

    return pyplot()


def revealing_quantities(diag: Diagnosis) -> list[tuple[str, np.ndarray, bool]]:
    """(label, value per observation row, categorical) of the quantities that reveal effects."""
    prep = diag.prep
    rec, D = prep.rec, prep.design
    rows = prep.obs_record
    out = []
    if D.kind == "length":
        out.append(("length d / mm", rec.reference_mm, False))
        from cmmwb.xlfuncs.locator.diagnose import direction_label
        out.append(("direction", np.array([direction_label(v) for v in D.na]), True))
        if D.N1 is not None:
            o = np.einsum("ij,ij->i", D.na, D.N1) * np.einsum("ij,ij->i", D.na, D.N2)
            out.append(("probing", np.where(o < -0.25, "bidirectional", np.where(o > 0.25, "unidirectional", "other")), True))
        if len(D.probe_ids) > 1:
            out.append(("probes", np.array([D.probe_ids[a] if a == b else f"{D.probe_ids[a]}-{D.probe_ids[b]}"
                                            for a, b in zip(D.k1, D.k2)]), True))
    else:
        r = np.linalg.norm(D.Y - D.c, axis=1)
        out.append(("distance from the centroid / mm", r, False))
        out.append(("axis", np.array(["xyz"[a] for a in prep.obs_axis]), True))
        if len(D.probe_ids) > 1:
            out.append(("probe", np.array([D.probe_ids[k] for k in D.k]), True))
    if D.T is not None:
        out.append(("temperature / °C", D.T, False))
    if D.t is not None:
        out.append(("time / h", D.t / 3600.0, False))
    # expand per observation row; drop quantities that do not vary (they reveal nothing)
    out = [(lab, (v[rows] if len(v) == rec.n and D.kind == "point" and lab != "axis" else v), cat)
           for lab, v, cat in out]
    return [(lab, v, cat) for lab, v, cat in out
            if (len(set(v.tolist())) > 1 if cat else float(np.ptp(v)) > 0)]


def _own_quantity(diag: Diagnosis, name: str) -> tuple[str, np.ndarray, bool]:
    """What shows a straightness (the ram coordinate of its carriage: the curve c2 P2 + c3 P3)
    or a reversal (the approach direction along its axis), per observation row."""
    D, rows = diag.prep.design, diag.prep.obs_record
    if name in fx.PERIODIC:             # the travel along its axis (lengths: the far end's)
        a = fx.AXES.index(name[-1])
        u = D.U2[:, a] if D.kind == "length" else D.U[rows, a]
        return (f"ram {name[-1]} / mm" + (" (end 2 of the length)" if D.kind == "length" else ""), u, False)
    if name in fx.STRAIGHTNESS:
        c = fx.CARRIAGE_AXIS[name[2]]
        u = 0.5 * (D.U1[:, c] + D.U2[:, c]) if D.kind == "length" else D.U[rows, c]
        return (f"ram {name[2].lower()} / mm" + (" (middle of the length)" if D.kind == "length" else ""), u, False)
    a = fx.AXES.index(name[-1])
    ax = name[-1]
    if D.kind == "length":
        w = fx.approach_sign(D.N2, a) - fx.approach_sign(D.N1, a)
        lab = np.where(w > 0, f"end 1 moving -{ax}, end 2 moving +{ax}",
                       np.where(w < 0, f"end 1 moving +{ax}, end 2 moving -{ax}", f"no reversal along {ax}"))
        return (f"probe motion along {ax} at the two ends", lab, True)
    w = fx.approach_sign(D.N, a)[rows]
    return (f"probe motion along {ax} when touching", np.where(w > 0, f"moving +{ax}", np.where(
        w < 0, f"moving -{ax}", f"across {ax}")), True)


def _periodic_values(diag: Diagnosis, name: str, t: np.ndarray) -> np.ndarray:
    """The fitted periodic error a sin + b cos of 2 pi (t - middle)/P at ram coordinates t (µm)."""
    e = effect_estimates(diag, name)
    a, b = (v or 0.0 for v in e["estimate"])
    w = fx.periodic_angle(diag.prep.design, fx.AXES.index(name[-1]), t, e["period_mm"])
    return a * np.sin(w) + b * np.cos(w)


def _periodic_curve(ax, diag: Diagnosis, name: str, x: np.ndarray) -> None:
    """The fitted a sin + b cos of the travel as a line."""
    t = np.linspace(float(np.min(x)), float(np.max(x)), 800)
    ax.plot(t, _periodic_values(diag, name, t), "-", lw=1.2, color="C1",
            label=f"fitted a sin + b cos, period {effect_estimates(diag, name)['period_mm']:.4g} mm")


def _scatter(ax, x, y, cat, **kw):
    if cat:
        cats = list(dict.fromkeys(x.tolist()))
        pos = np.array([cats.index(v) for v in x.tolist()], dtype=float)
        jitter = (np.random.default_rng(0).random(len(pos)) - 0.5) * 0.3
        ax.plot(pos + jitter, y, "o", ms=3, **kw)
        ax.set_xticks(range(len(cats)))
        ax.set_xticklabels(cats, rotation=45, ha="right", fontsize=7)
    else:
        ax.plot(x, y, "o", ms=3, **kw)


def write_plots(diag: Diagnosis, out_dir: Path) -> list[Path]:
    plt = _plt()
    out_dir = Path(out_dir)
    files = []
    n = len(diag.z_before)
    # 1. before/after
    fig, ax = plt.subplots(figsize=(8, 4), dpi=110)
    ax.plot(np.arange(n), diag.z_before, "o", ms=3, label=f"before (chi2/dof {diag.chi2_before / diag.dof_before:.2f})")
    ax.plot(np.arange(n), diag.z_after, "o", ms=3, label=f"after (chi2/dof {diag.chi2_after / max(diag.dof_after, 1):.2f})")
    for yv in (-2, 2):
        ax.axhline(yv, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("record" if diag.prep.design.kind == "length" else "coordinate row")
    ax.set_ylabel("standardized residual z")
    ax.set_title("Residuals against the simulation, before and after adding "
                 + (", ".join(diag.chosen) if diag.chosen else "nothing"), fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    p = out_dir / "residuals_before_after.png"
    fig.savefig(p)
    plt.close(fig)
    files.append(p)
    # 2. residuals against the revealing quantities
    qs = revealing_quantities(diag) or [("record", np.arange(n, dtype=float), False)]
    k = len(qs)
    ncol = 2 if k > 1 else 1
    nrow = math.ceil(k / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(5 * ncol, 3.2 * nrow), dpi=100, squeeze=False)
    for (lab, x, cat), ax in zip(qs, axes.flat):
        _scatter(ax, x, diag.z_before, cat, label="before")
        _scatter(ax, x, diag.z_after, cat, label="after", alpha=0.6)
        ax.set_xlabel(lab)
        ax.set_ylabel("z")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[k:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("Standardized residuals against the quantities that reveal effects", fontsize=10)
    fig.tight_layout()
    p = out_dir / "residuals_by_quantity.png"
    fig.savefig(p)
    plt.close(fig)
    files.append(p)
    # 3. one figure per chosen effect: partial residual against the revealing quantity and the column
    # by family (effects.EFFECTS): angular errors, by default, against the length or the distance
    reveal = {"scale": "length d / mm", "scale_axis": "direction", "squareness": "direction",
              "thermal_expansion": "temperature / °C", "probe_radius": "probing", "probe_qualification": "probes",
              "scale_drift": "time / h", "offset_drift": "time / h"}
    qmap = {lab: (x, cat) for lab, x, cat in qs}
    for name in diag.chosen:
        rows = diag.effect_rows(name)
        f = diag.X_sel[:, rows] @ diag.beta[rows]
        partial = diag.resid_after + f
        want = reveal.get(fx.BY_NAME[name].family, "length d / mm" if diag.prep.design.kind == "length" else "distance from the centroid / mm")
        if want not in qmap:
            want = {"probing": "length d / mm", "probes": "probe"}.get(want, qs[0][0])
            want = want if want in qmap else qs[0][0]
        x, cat = qmap[want]
        own = name in fx.STRAIGHTNESS or name in fx.REVERSAL or name in fx.PERIODIC
        if own:   # section 7: its own revealing quantity
            want, x, cat = _own_quantity(diag, name)
            if diag.prep.design.kind == "point":      # only the coordinate the effect moves
                keep = diag.prep.obs_axis == fx.AXES.index((name[1] if name in fx.STRAIGHTNESS else name[-1]).lower())
                x, partial, f = x[keep], partial[keep], f[keep]
                rows_x = diag.X_sel[keep][:, rows]
            else:
                rows_x = diag.X_sel[:, rows]
        else:
            rows_x = diag.X_sel[:, rows]
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8), dpi=100)
        if name in fx.PERIODIC and diag.prep.design.kind == "length":
            # the error at end 2: the length's residual along the axis plus the fitted error at end 1
            D = diag.prep.design
            k = fx.AXES.index(name[-1])
            seen = np.abs(D.na[:, k]) > fx.APPROACH_MIN
            near = _periodic_values(diag, name, D.U1[:, k])
            _scatter(a1, x[seen], partial[seen] / D.na[seen, k] + near[seen], cat,
                     label="error at end 2: residual / n_a (other effects out) + fitted error at end 1")
        else:
            _scatter(a1, x, partial, cat, label="residual without the other effects")
            _scatter(a1, x, f, cat, label=f"fitted {name}", alpha=0.7)
        if name in fx.PERIODIC:
            _periodic_curve(a1, diag, name, x)
        a1.set_xlabel(want)
        a1.set_ylabel("µm")
        a1.grid(alpha=0.3)
        a1.legend(fontsize=7)
        s = rows_x
        xs = s[:, 0] if s.shape[1] == 1 else f / max(np.max(np.abs(f)), 1e-300)
        a2.plot(xs, partial, "o", ms=3)
        order = np.argsort(xs)
        a2.plot(xs[order], f[order], "-", lw=1.5, color="C1")
        a2.set_xlabel(f"sensitivity to {name}" if s.shape[1] == 1 else "fitted (normalized)")
        a2.set_ylabel("µm")
        a2.grid(alpha=0.3)
        fig.suptitle(f"{name}: {fx.BY_NAME[name].plain}", fontsize=10)
        fig.tight_layout()
        p = out_dir / f"effect_{name}.png"
        fig.savefig(p)
        plt.close(fig)
        files.append(p)
    return files
