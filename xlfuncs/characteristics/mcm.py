"""The Monte Carlo check of the characteristics' linearised uncertainties (JCGM 101 adaptive):
every draw of the six influence factors of Forbes 2025 moves the points, every feature is
refitted and every characteristic evaluated anew, extreme points and minimum zones included."""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..minzone import basis_is_optimal, chebyshev_zone
from .evaluation import RAD, VALUE, Context, Result, constants, form, form_residuals
from .joint import JointFit
from .specs import FORM_TYPES, CharacteristicSpec

# ------------------------------------------------------------------------------------------
# Monte Carlo (JCGM 101) of every characteristic: refit, re-evaluate exactly
# ------------------------------------------------------------------------------------------

def monte_carlo(jf: JointFit, frames, chars: Sequence[CharacteristicSpec], results: Sequence[Result],
                cloud, params, *, n_dig: int = 2, batch: int = 2000, max_draws: int = 400_000,
                rng=None, sampler=None):
    """JCGM 101 adaptive Monte Carlo of the characteristics: every draw of the six influence
    factors (xlfuncs.montecarlo.PointCloudSampler over the joint point set) moves the points,
    every feature is refitted (Gauss-Newton from the reference, xlfuncs.montecarlo.refit_batch)
    and every characteristic evaluated anew: the extreme points found again, the minimum zone
    solved again (small-angle LP about the draw's least-squares feature, warm-started from the
    reference's contact points).  Returns the MCResult, u in the results' units (µm, µrad), then
    the margin (zone - value, µm) of every position with a tolerance, its MMC/LMC bonus taken
    from the drawn size."""
    from .. import montecarlo as mc

    frames = frames if isinstance(frames, Mapping) else {f.name: f for f in frames}
    sampler = sampler or mc.PointCloudSampler(cloud, params)
    consts = [constants(jf, frames, c) for c in chars]
    ref_basis = []
    for ci, c in enumerate(chars):
        if c.type in FORM_TYPES and c.method == "MZ":
            _, fz = form(Context(jf, frames), c, consts[ci], None)
            ref_basis.append(fz["zone"].basis)
        else:
            ref_basis.append(None)
    ref_local = {nm: mc.refit_batch(f, f.X_mm[None])[0] for nm, f in jf.fits.items()}
    ref_values = np.array([VALUE[c.type](Context(jf, frames), c, consts[ci], None)[0][0]
                           if ref_basis[ci] is None else
                           form(Context(jf, frames), c, consts[ci], None)[0][0]
                           for ci, c in enumerate(chars)])
    conv = np.array([1e3 if r.unit == "mm" else RAD * 1e6 for r in results])

    def one_batch(M, g):
        out = np.zeros((M, len(chars)))
        for s0 in range(0, M, 1000):
            Mb = min(1000, M - s0)
            dl = sum(sampler.draw(Mb, g).values())          # (Mb, m, 3) µm
            Xb = jf.X_mm[None] + dl * mc.MILLI
            deltas = {nm: mc.refit_batch(f, Xb[:, np.asarray(jf.specs[nm].indices, int)])
                      - ref_local[nm] for nm, f in jf.fits.items()}
            ctx = Context(jf, frames, deltas=deltas, X=Xb, B=Mb)
            for ci, c in enumerate(chars):
                if ref_basis[ci] is None:
                    out[s0:s0 + Mb, ci] = VALUE[c.type](ctx, c, consts[ci], None)[0]
                    continue
                # minimum zone: the reference contact points checked in one go, LP where changed
                ds, gs = form_residuals(ctx, c)
                ok, h, _ = basis_is_optimal(ds, gs, ref_basis[ci])
                for b in np.flatnonzero(~ok):
                    h[b] = chebyshev_zone(ds[b], gs[b], basis=ref_basis[ci]).h
                out[s0:s0 + Mb, ci] = h
        cols = [(out - ref_values) * conv]
        for ci, si, sign, lim in margins:      # zone - value, the bonus from the drawn size
            bonus = np.clip(sign * (out[:, si] - lim), 0.0, None)
            cols.append(((chars[ci].tolerance_mm + bonus - out[:, ci]) - ref_margin[ci])[:, None] * 1e3)
        return {"total": np.hstack(cols)}

    # the margins of positions with a tolerance (MMC/LMC bonus from the size characteristic)
    by_name = {c.name: i for i, c in enumerate(chars)}
    margins = []
    for ci, (c, r) in enumerate(zip(chars, results)):
        if c.type != "position" or c.tolerance_mm is None:
            continue
        if c.material_condition == "RFS":
            margins.append((ci, ci, 0.0, 0.0))
            continue
        size = chars[by_name[c.size]]
        mmc = c.material_condition == "MMC"
        lim = (size.lsl if c.internal else size.usl) if mmc else (size.usl if c.internal else size.lsl)
        margins.append((ci, by_name[c.size], (1.0 if c.internal else -1.0) * (1.0 if mmc else -1.0), lim))
    ref_margin = {ci: c.tolerance_mm + max(0.0, sign * (ref_values[si] - lim)) - ref_values[ci]
                  for ci, si, sign, lim in margins for c in [chars[ci]]}

    names = [c.name for c in chars] + [f"{chars[ci].name} margin" for ci, *_ in margins]
    return mc.adaptive(one_batch, names, n_dig=n_dig, batch=batch, max_draws=max_draws, rng=rng)
