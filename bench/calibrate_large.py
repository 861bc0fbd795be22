"""``cmmwb calibrate`` beyond the dense cap (issue 24): the REML fit of the hyper-parameters on the
structured record covariance (:mod:`xlfuncs.reml_structured`, C = D + U U^T of ``diagnose``, never
n x n) for length records far above ``reml.DENSE_MAX_OBS`` = 4,000 observations.

Usage: ``python bench/calibrate_large.py [--records=20000]``: two fits per size, every
hyper-parameter free, then the three length scales held at their start (``fixed`` of
:func:`xlfuncs.calibrate.calibrate`: no derivative columns, half the operator's width); the one
evaluation is always in all twelve.

ISO 10360-2 style runs (7 positions x 10 lengths, three probes with offsets, as
``bench/bench_lengths.py``) simulated from Forbes 2025 Table 3 MPE1 (no planted effect), then
:func:`xlfuncs.calibrate.calibrate` from MPE1 and the GLS checks of ``cmmwb calibrate``
(:func:`xlfuncs.calibration_checks.gls_fit`, :func:`standardized_residuals`): the time of one
REML evaluation (log-likelihood, gradient and expected information in all twelve parameters),
of the whole fit, the peak memory (ru_maxrss of a fresh process; a dense n x n matrix of 20,000
records alone would be 3.2 GB), the ranks of the operator and its stated chi-square bound, and the
estimates against the simulation's values.

Every run is a fresh subprocess with one BLAS thread (the 2-core machine is shared with other
jobs; the load average is printed with each row).  Results: bench/results/calibrate_large.md.
"""

from __future__ import annotations

import sys
from pathlib import Path

from fresh_process import run_fresh  # bench/, the folder of this script, is on sys.path

ROOT = Path(__file__).resolve().parents[1]

CODE = """
import time, resource, json, math
import numpy as np
from cmmwb.xlfuncs import pointcloud as pc, reml, calibrate as cb, calibration_checks as checks
from cmmwb.xlfuncs.locator import diagnose as dg, simulate as sm
from cmmwb.xlfuncs.model import MPE1  # Forbes 2025 Table 3
PROBES = (pc.Probe("P1", (0.0, 0.0, -50.0)), pc.Probe("P2", (150.0, 0.0, -50.0)), pc.Probe("P3", (0.0, 150.0, -50.0)))
n = {n}
L = sm.iso10360(PROBES, repeats=-(-n // 70), fractions=tuple(np.linspace(0.07, 0.7, 10)), hours=8.0)
rec = sm.simulate(L, MPE1, {{}}, seed=7)
model = dg.Model(MPE1, PROBES, True)
t = time.perf_counter()
prep = dg.prepare(rec, model, reml.use_structured(rec))
s = reml.record_set(prep, "iso", structured=reml.use_structured(rec))
prep_s = time.perf_counter() - t
v = {{k: float(getattr(MPE1, k)) for k in reml.NAMES}}
t = time.perf_counter()
t0 = reml.reml_terms([s], v, list(reml.NAMES))
one_s = time.perf_counter() - t
t = time.perf_counter()
cal = cb.calibrate([s], MPE1, fixed={hold!r})
fit_s = time.perf_counter() - t
t = time.perf_counter()
beta, cov, chi2, dof = checks.gls_fit(s, cal.params)
e, u, z = checks.standardized_residuals(s, cal.params)
checks_s = time.perf_counter() - t
out = {{"n": rec.n, "obs": int(len(s.y)), "op": type(s.op).__name__, "prep_s": prep_s, "one_s": one_s, "fit_s": fit_s,
        "checks_s": checks_s, "iterations": cal.iterations, "ranks": getattr(s.op, "ranks", None),
        "bound": getattr(s.op, "chi2_bound", None), "chi2_dof": chi2 / dof, "z_rms": float(np.sqrt(np.mean(z * z))),
        "estimates": {{k: [e_.status, e_.value, e_.u, e_.start] for k, e_ in cal.estimates.items()}}}}
"""


def run(n: int, hold: tuple) -> dict:
    return run_fresh(CODE.format(n=n, hold=hold))


def main(argv: list[str]) -> int:
    sizes = [20_000]
    holds = [(), ("lambda_ET_mm", "lambda_ER_mm", "lambda_P")]
    for a in argv:
        if a.startswith("--records="):
            sizes = [int(v) for v in a.split("=", 1)[1].split(",")]
    lines = ["Measured by `python bench/calibrate_large.py` on the 2-core machine shared with other jobs "
             "(each row a fresh process, one BLAS thread; peak = ru_maxrss; load = 1-minute load average after "
             "the run, 2.0 = both cores busy; CPU = user + system time of the whole process, simulation included).",
             "",
             "## REML fit of the hyper-parameters on ISO 10360-2 style length records (simulated from MPE1)",
             "",
             "| records | covariance | held at the start | prepare / s | one REML evaluation (12 parameters) / s | fit / s (iterations) | "
             "GLS checks / s | CPU / s | peak MB | load | k (ranks) | chi2 rel. bound | chi2/dof, rms z |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    fits = []
    for n, hold in [(n, h) for n in sizes for h in holds]:
        r = run(n, hold)
        print(r, flush=True)
        ranks = ", ".join(f"{k} {v}" for k, v in (r["ranks"] or {}).items())
        lines.append(f"| {r['n']:,} | {r['op']} | {', '.join(hold) or '—'} | {r['prep_s']:.1f} | {r['one_s']:.1f} | {r['fit_s']:.0f} "
                     f"({r['iterations']}) | {r['checks_s']:.1f} | {r['cpu_s']:.0f} | {r['peak_MB']:.0f} | "
                     f"{r['load']:.1f} | {ranks} | {r['bound'] or 0:.1e} | {r['chi2_dof']:.3f}, {r['z_rms']:.3f} |")
        r["hold"] = hold
        fits.append(r)
    lines += ["", "## The estimates (simulation's value: Forbes 2025 Table 3 MPE1)", ""]
    for r in fits:
        lines += [f"{r['n']:,} records, held: {', '.join(r['hold']) or 'none'}:", "", "| hyper-parameter | status | estimate | u | simulated |",
                  "|---|---|---|---|---|"]
        for k, (status, value, u, start) in r["estimates"].items():
            lines.append(f"| {k} | {status} | {value:.4g} | {'' if u is None else f'{u:.2g}'} | {start:g} |")
        lines.append("")
    out = ROOT / "bench" / "results" / "calibrate_large.md"
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(out.read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
