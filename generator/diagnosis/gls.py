"""The generalized least-squares sheets of the diagnosis workbook: Cov and Cinv (the covariance
of the residuals under the simulation and MINVERSE of it) or Whitened (W r, W X computed by the
core for large or rank-deficient cases), GLS (the normal equations with MMULT/MINVERSE over the
chosen sensitivity columns, the estimates and their uncertainties), the per-row u, z, fitted
values and residuals after the refit, and the chi-square statistics (docs/recordings.md
sections 3.1 and 7)."""

from __future__ import annotations

import math

import numpy as np

from cmmwb.xlfuncs.locator import effects as fx
from cmmwb.xlfuncs.locator.diagnose import Diagnosis

from ..workbook.book import Book
from ..workbook.styles import FMT_SCI, FMT_UM
from ..workbook.xlref import Block, block, cell
from .records import display_unit

FMT = "0.000000"
ZFMT = "0.000"


def gls_sheets(book: Book, diag: Diagnosis, obs: dict, native: bool) -> dict:
    """Cov + Cinv (``native``) or Whitened, and the normal equations on GLS; returns their blocks
    (``fill_after`` adds the statistics)."""
    prep = diag.prep
    n = prep.C.shape[0]
    p = diag.X_sel.shape[1]
    p0 = obs["n_align"]
    sheet, ci = obs["sheet"], obs["ci"]
    r0 = obs["rows"][0]
    rvec = Block(sheet, r0, ci["residual_um"], n, 1)
    X = Block(sheet, r0, obs["first_X"], n, p) if p else None
    ws = book.sheet("GLS")
    out = {"rvec": rvec, "X": X, "p": p, "p0": p0, "native": native}
    if native:
        wc = book.sheet("Cov")
        book.text(wc, 1, 1, "C (µm²): covariance of the residuals under the simulation, G V_X G' "
                            "(Forbes 2025 eqs. 28-29), computed by the core")
        for i in range(n):
            for j in range(n):
                book.number(wc, 2 + i, 1 + j, prep.C[i, j], fmt=FMT_SCI, computed=True)
        Cb = Block("Cov", 2, 1, n, n)
        wi = book.sheet("Cinv")
        book.text(wi, 1, 1, "C^-1 = MINVERSE(C)")
        Ci = Block("Cinv", 2, 1, n, n)
        book.array(Ci, f"=MINVERSE({Cb.ref})", fmt=FMT_SCI, note="inverse of the covariance C")
        from openpyxl.utils import get_column_letter

        for w_ in (wc, wi):
            for j in range(n):   # 0.000E+00 of a negative number: 10 characters
                w_.column_dimensions[get_column_letter(1 + j)].width = 11
            # the top-left 24 x 9 on one landscape page at full size (12 columns printed at 6 pt)
            book.print_setup(w_, matrix=(n, n), corner=(24, 9), caption=(
                f"{w_.title}: top-left corner of the {n} x {n} matrix; the whole matrix is in the workbook, "
                "not in the printout"))
        out["C"] = Cb
        # column blocks: C^-1 r, C^-1 X
        book.text(ws, 1, 1, "C^-1 r")
        Cir = Block("GLS", 2, 1, n, 1)
        book.array(Cir, f"=MMULT({Ci.ref},{rvec.ref})")
        if p:
            book.text(ws, 1, 2, "C^-1 X")
            CiX = Block("GLS", 2, 2, n, p)
            book.array(CiX, f"=MMULT({Ci.ref},{X.ref})")
        out["Ci"], out["Cir"] = Ci, Cir
        c0 = 3 + p
    else:
        ww = book.sheet("Whitened")
        yw = diag.whitener(prep.r_um)
        # the structured covariance (xlfuncs.locator.structured) gives coordinates with the same inner
        # products a' C^-1 b, fewer than n of them: the rank of C is then a cell of its own
        k = diag.whitener.rank if diag.whitener.mode != "structured" else len(yw)
        book.text(ww, 1, 1, f"W r and W X with W C W' = I ({diag.whitener.mode}; computed by the core, "
                            f"C is {n} x {n})")
        if diag.whitener.mode == "structured":
            book.text(ww, 1, p + 3, "rank of C")
            book.number(ww, 1, p + 4, diag.whitener.rank, fmt="0", computed=True)
            out["rank_ref"] = cell(1, p + 4, "Whitened")
        Xw = diag.whitener(diag.X_sel) if p else np.zeros((k, 0))
        book.header(ww, 2, 1, ["Wr"] + [f"W {l}" for _, l in diag.sel_labels])
        for i in range(k):
            book.number(ww, 3 + i, 1, yw[i], fmt="0.000000E+00", computed=True)
            for j in range(p):
                book.number(ww, 3 + i, 2 + j, Xw[i, j], fmt="0.000000E+00", computed=True)
        out["yw"] = Block("Whitened", 3, 1, k, 1)
        out["Xw"] = Block("Whitened", 3, 2, k, p) if p else None
        out["k"] = k
        c0 = 1
    # normal equations block to the right (native) or on GLS (whitened)
    row = 1
    def label(r, c, text):
        book.text(ws, r, c, text)
    if p:
        label(row, c0, "M = X' C^-1 X" if native else "M = (WX)'(WX)")
        M = Block("GLS", row + 1, c0, p, p)
        if native:
            book.array(M, f"=MMULT(TRANSPOSE({X.ref}),{Block('GLS', 2, 2, n, p).ref})", fmt="0.000000E+00")
            Xty = f"MMULT(TRANSPOSE({X.ref}),{out['Cir'].ref})"
        else:
            book.array(M, f"=MMULT(TRANSPOSE({out['Xw'].ref}),{out['Xw'].ref})", fmt="0.000000E+00")
            Xty = f"MMULT(TRANSPOSE({out['Xw'].ref}),{out['yw'].ref})"
        row += p + 2
        label(row, c0, "X' C^-1 r" if native else "(WX)'(Wr)")
        g = Block("GLS", row + 1, c0, p, 1)
        book.array(g, f"={Xty}", fmt="0.000000E+00")
        row += p + 2
        label(row, c0, "M^-1 (covariance of the estimates)")
        Minv = Block("GLS", row + 1, c0, p, p)
        book.array(Minv, f"=MINVERSE({M.ref})", fmt="0.000000E+00")
        row += p + 2
        label(row, c0, "parameter")
        label(row, c0 + 1, "b = M^-1 X' C^-1 r")
        label(row, c0 + 2, "u(b) = sqrt(M^-1_jj)")
        label(row, c0 + 3, "unit")
        b = Block("GLS", row + 1, c0 + 1, p, 1)
        book.array(b, f"=MMULT({Minv.ref},{g.ref})", fmt=FMT_UM,
                   note="GLS estimates: alignment (nuisance) and the chosen effects")
        for j, (e, l) in enumerate(diag.sel_labels):
            book.text(ws, row + 1 + j, c0, l if e == "alignment" else (e if l == e else f"{e} {l}"))
            book.formula(ws, row + 1 + j, c0 + 2, f"=SQRT({Minv.cell(j, j)})", fmt=FMT_UM)
            unit = (("µm" if l.startswith("t") else "µrad") if e == "alignment" else "µm" if e == "outlier"
                    else "mm" if l == "period_mm" else display_unit(fx.BY_NAME[e].unit))
            book.text(ws, row + 1 + j, c0 + 3, unit)
        out.update(M=M, g=g, Minv=Minv, b=b, u_col=c0 + 2, b_row=row + 1, c0=c0)
        row += p + 2
        if p0:
            label(row, c0, "baseline: alignment only, b0 = Ma^-1 (A' C^-1 r)")
            Ma_inv = Block("GLS", row + 1, c0, p0, p0)
            book.array(Ma_inv, f"=MINVERSE({M.sub(0, 0, p0, p0).ref})", fmt="0.000000E+00")
            b0 = Block("GLS", row + 1, c0 + p0 + 1, p0, 1)
            book.array(b0, f"=MMULT({Ma_inv.ref},{g.sub(0, 0, p0, 1).ref})", fmt="0.000000E+00")
            out.update(Ma_inv=Ma_inv, b0=b0)
            row += p0 + 2
    out["stats_row"] = row
    return out


def fill_after(book: Book, diag: Diagnosis, obs: dict, gls: dict) -> None:
    """Per-row u, z, fitted, residual after; then the statistics on GLS."""
    sheet, ci = obs["sheet"], obs["ci"]
    ws = book.wb[sheet]
    p, p0 = gls["p"], gls["p0"]
    native = gls["native"]
    n = len(obs["rows"])
    for q, r in enumerate(obs["rows"]):
        L = lambda k: cell(r, ci[k])
        # u: sqrt of the diagonal of C (baseline-adjusted for point records)
        if native:
            cqq = gls["C"].cell(q, q)
            if p0:
                arow = block(r, obs["first_X"], 1, p0, sheet)
                book.array(Block(sheet, r, ci["u_um"], 1, 1),
                           f"=SQRT({cqq}-MMULT(MMULT({arow},{gls['Ma_inv'].ref}),TRANSPOSE({arow})))",
                           fmt=FMT)
            else:
                book.formula(ws, r, ci["u_um"], f"=SQRT({cqq})", fmt=FMT)
        else:
            book.number(ws, r, ci["u_um"], diag.u_obs[q], fmt=FMT, computed=True)
        if p0:
            arow = block(r, obs["first_X"], 1, p0)
            book.array(Block(sheet, r, ci["baseline_um"], 1, 1),
                       f"=MMULT({arow},{gls['b0'].ref})", fmt=FMT)
            book.formula(ws, r, ci["residual_before_um"], f"={L('residual_um')}-{L('baseline_um')}", fmt=FMT)
            before = L("residual_before_um")
        else:
            before = L("residual_um")
        book.formula(ws, r, ci["z"], f"={before}/{L('u_um')}", fmt=ZFMT)
        if p - p0 > 0:
            xrow = block(r, obs["first_X"] + p0, 1, p - p0)
            book.array(Block(sheet, r, ci["fitted_um"], 1, 1),
                       f"=MMULT({xrow},{gls['b'].sub(p0, 0, p - p0, 1).ref})", fmt=FMT)
        else:
            ws.cell(row=r, column=ci["fitted_um"]).value = 0.0
        if p0:
            arow = block(r, obs["first_X"], 1, p0)
            book.array(Block(sheet, r, ci["residual_after_um"], 1, 1),
                       f"={L('residual_um')}-MMULT({arow},{gls['b'].sub(0, 0, p0, 1).ref})-{L('fitted_um')}",
                       fmt=FMT)
        else:
            book.formula(ws, r, ci["residual_after_um"], f"={L('residual_um')}-{L('fitted_um')}", fmt=FMT)
        book.formula(ws, r, ci["z_after"], f"={L('residual_after_um')}/{L('u_um')}", fmt=ZFMT)
    # statistics
    wg = book.wb["GLS"]
    r0 = obs["rows"][0]
    e_after = Block(sheet, r0, ci["residual_after_um"], n, 1)
    e_before = Block(sheet, r0, ci["residual_before_um" if p0 else "residual_um"], n, 1)
    row = gls["stats_row"]
    c0 = gls.get("c0", 3)
    stats = {}

    def stat(key, formula, note, array=False, fmt=FMT):
        nonlocal row
        book.text(wg, row, c0, key)
        if array:
            book.array(Block("GLS", row, c0 + 1, 1, 1), formula, fmt=fmt, note=note)
        else:
            book.formula(wg, row, c0 + 1, formula, note=note, fmt=fmt)
        stats[key] = cell(row, c0 + 1, "GLS")
        row += 1

    if native:
        Ci = gls["Ci"].ref
        stat("chi2_before", f"=MMULT(TRANSPOSE({e_before.ref}),MMULT({Ci},{e_before.ref}))",
             "r0' C^-1 r0, r0 the residual of the baseline (docs/recordings.md section 3.1)", array=True)
        stat("dof_before", f"=COUNT({e_before.ref})-{p0}", "records (coordinates) minus alignment parameters",
             fmt="0")
        stat("chi2_after", f"=MMULT(TRANSPOSE({e_after.ref}),MMULT({Ci},{e_after.ref}))",
             "e' C^-1 e after the refit", array=True)
        stat("dof_after", f"=COUNT({e_after.ref})-{p}", "minus every fitted parameter", fmt="0")
    else:
        yw = gls["yw"].ref
        count = gls.get("rank_ref") or f"COUNT({yw})"
        if p:
            Xw = gls["Xw"]
            if p0:
                stat("chi2_before", f"=SUMSQ({yw}-MMULT({Xw.sub(0, 0, gls['k'], p0).ref},{gls['b0'].ref}))",
                     "|W r - W A b0|^2", array=True)
            else:
                stat("chi2_before", f"=SUMSQ({yw})", "|W r|^2")
            stat("dof_before", f"={count}-{p0}", "rank of C minus alignment parameters", fmt="0")
            stat("chi2_after", f"=SUMSQ({yw}-MMULT({Xw.ref},{gls['b'].ref}))", "|W r - W X b|^2", array=True)
        else:
            stat("chi2_before", f"=SUMSQ({yw})", "|W r|^2")
            stat("dof_before", f"={count}", "rank of C", fmt="0")
            stat("chi2_after", f"=SUMSQ({yw})", "no effect chosen")
        stat("dof_after", f"={count}-{p}", "minus every fitted parameter", fmt="0")
    stat("p_before", f"=CHIDIST({stats['chi2_before']},{stats['dof_before']})",
         "chi-square tail probability", fmt=FMT_SCI)
    # the targeted gate (docs/recordings.md section 7): the smallest Bonferroni-adjusted p-value of the
    # candidates of the first step, from the core's search (Candidates sheet)
    book.text(wg, row, c0, "p_targeted")
    book.number(wg, row, c0 + 1, math.exp(diag.logp_targeted) if diag.targeted_K else 1.0, fmt=FMT_SCI,
                computed=True)
    stats["p_targeted"] = cell(row, c0 + 1, "GLS")
    row += 1
    book.text(wg, row, c0, "mismatch")
    book.formula(wg, row, c0 + 1, f"=IF(OR({stats['p_before']}<alpha/2,{stats['p_targeted']}<alpha/2),"
                                  f"\"yes\",\"no\")", fmt=None,
                 note="two gates, alpha/2 each: the omnibus chi-square or the targeted test (docs/recordings.md section 7)")
    stats["mismatch"] = cell(row, c0 + 1, "GLS")
    row += 1
    stat("p_after", f"=CHIDIST({stats['chi2_after']},{stats['dof_after']})",
         "chi-square tail probability of what remains after the refit", fmt=FMT_SCI)
    book.text(wg, row, c0, "explained")
    book.formula(wg, row, c0 + 1, f"=IF({stats['p_after']}>=alpha,\"yes\",\"no\")", fmt=None,
                 note="the remaining chi-square passes: p_after >= alpha (docs/recordings.md section 7)")
    stats["explained"] = cell(row, c0 + 1, "GLS")
    row += 1
    stat("chi2_per_dof_before", f"={stats['chi2_before']}/{stats['dof_before']}", "")
    stat("chi2_per_dof_after", f"={stats['chi2_after']}/{stats['dof_after']}", "")
    stat("rms_before_um", f"=SQRT(SUMSQ({e_before.ref})/COUNT({e_before.ref}))", "RMS of the residuals (µm)")
    stat("rms_after_um", f"=SQRT(SUMSQ({e_after.ref})/COUNT({e_after.ref}))", "RMS after the refit (µm)")
    if diag.noise_scale:
        stat("noise_scale", f"=SQRT({stats['chi2_per_dof_after']})",
             "the declared uncertainties are too small by this factor: sqrt(chi2/dof) after the refit "
             "(docs/recordings.md section 7, noise level)")
        stat("u_noise_scale", f"={stats['noise_scale']}/SQRT(2*{stats['dof_after']})",
             "standard uncertainty of the noise scale, s / sqrt(2 dof)")
    gls["stats"] = stats
