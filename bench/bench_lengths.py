"""diagnose on length records at scale (issue 26): the structured record covariance
(:mod:`xlfuncs.locator.structured_lengths`, C = D + U U^T, never n x n) against the dense one.

Usage: ``python bench/bench_lengths.py [equal] [scale] [--records 20000,200000]``.

* ``equal``  5,000 records diagnosed both ways: the largest relative difference of chi-square
             before/after, the candidates' likelihood ratios, the estimates, their u and the
             records' u (goal: 1e-8);
* ``scale``  ISO 10360-2 style runs (7 positions x 10 lengths, three probes, temperature and time)
             of 20,000 and 200,000 records with planted squareness (15 µrad) and ECZ (200 µrad)
             errors: time, peak memory (ru_maxrss of a fresh process), ranks, the stated bound,
             what was found (goal at 200,000: <= 120 s, <= 4 GB).

Every run is a fresh subprocess with one BLAS thread (OPENBLAS_NUM_THREADS=1: the 2-core machine
is shared with other jobs; the load average is printed with each row).  Results:
bench/results/lengths_equal.md and lengths_scale.md.
"""

from __future__ import annotations

import sys
from pathlib import Path

from fresh_process import run_fresh  # bench/, the folder of this script, is on sys.path

ROOT = Path(__file__).resolve().parents[1]

SETUP = """
import time, resource, json, math
import numpy as np
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.locator import diagnose as dg, simulate as sm
from cmmwb.xlfuncs.model import MPE1  # Forbes 2025 Table 3
PROBES = (pc.Probe("P1", (0.0, 0.0, -50.0)), pc.Probe("P2", (150.0, 0.0, -50.0)), pc.Probe("P3", (0.0, 150.0, -50.0)))
n = {n}
L = sm.iso10360(PROBES, repeats=-(-n // 70), fractions=tuple(np.linspace(0.07, 0.7, 10)), hours=8.0)
rec = sm.simulate(L, MPE1, {{"squareness_xy": 15.0, "ECZ": 200.0}}, seed=7, temperature_C=(19.8, 21.0))
model = dg.Model(MPE1, PROBES, True)
"""

SCALE = SETUP + """
ru0 = resource.getrusage(resource.RUSAGE_SELF)
t = time.perf_counter()
d = dg.diagnose(rec, model, structured={structured})
seconds = time.perf_counter() - t
ru1 = resource.getrusage(resource.RUSAGE_SELF)
diag_cpu = ru1.ru_utime + ru1.ru_stime - ru0.ru_utime - ru0.ru_stime
C = d.prep.C
est = {{e: dg.effect_estimates(d, e) for e in d.chosen}}
out = {{"n": rec.n, "seconds": seconds, "diag_cpu_s": diag_cpu, "chosen": d.chosen, "chi2_before": d.chi2_before, "dof": d.dof_before,
        "estimates": {{e: [v["estimate"], v["u"]] for e, v in est.items()}},
        "ranks": getattr(C, "ranks", None), "k": getattr(C, "k", None),
        "bound": C.chi2_bound() if hasattr(C, "chi2_bound") else None}}
"""

EQUAL = SETUP + """
s = dg.diagnose(rec, model, structured=True)
d = dg.diagnose(rec, model, structured=False)
def rel(a, b):
    a, b = np.atleast_1d(np.asarray(a, float)), np.atleast_1d(np.asarray(b, float))
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300))) if a.size else 0.0
cand = max(rel(s.candidates[k].delta_chi2, c.delta_chi2) for k, c in d.candidates.items()
           if c.delta_chi2 is not None and s.candidates[k].delta_chi2 is not None)
seconds = 0.0
out = {{"n": rec.n, "chosen": [s.chosen, d.chosen], "chi2_before": rel(s.chi2_before, d.chi2_before),
        "chi2_after": rel(s.chi2_after, d.chi2_after), "logp_before": rel(s.logp_before, d.logp_before),
        "candidates_delta_chi2": cand, "beta": rel(s.beta, d.beta),
        "u_beta": rel(np.sqrt(np.diag(s.cov_beta)), np.sqrt(np.diag(d.cov_beta))), "u_records": rel(s.u_obs, d.u_obs),
        "bound": s.prep.C.chi2_bound()}}
"""

def main(argv: list[str]) -> int:
    parts = [a for a in argv if not a.startswith("--")] or ["equal", "scale"]
    sizes = [20_000, 200_000]
    for a in argv:
        if a.startswith("--records="):
            sizes = [int(v) for v in a.split("=", 1)[1].split(",")]
    head = ["Measured by `python bench/bench_lengths.py` on the 2-core machine shared with other jobs "
             "(each row a fresh process, one BLAS thread; peak = ru_maxrss; load = 1-minute load average "
             "after the run, 2.0 = both cores busy; CPU = user + system time of the process, simulation of the "
             "records included, the share of the wall time this process got).", ""]
    if "equal" in parts:
        r = run_fresh(EQUAL.format(n=5000, structured=True))
        print("equal", r, flush=True)
        lines = head + ["## structured against dense, 5,000 length records (largest relative difference)", "",
                  "| records | chosen (structured / dense) | chi2 before | chi2 after | log p before | "
                  "candidates' Δχ² | estimates | their u | records' u | stated chi2 bound | peak MB (both runs) |",
                  "|---|---|---|---|---|---|---|---|---|---|---|",
                  f"| {r['n']:,} | {' + '.join(r['chosen'][0])} / {' + '.join(r['chosen'][1])} | "
                  f"{r['chi2_before']:.1e} | {r['chi2_after']:.1e} | {r['logp_before']:.1e} | "
                  f"{r['candidates_delta_chi2']:.1e} | {r['beta']:.1e} | {r['u_beta']:.1e} | "
                  f"{r['u_records']:.1e} | {r['bound']:.1e} | {r['peak_MB']:.0f} |", ""]
        write("equal", lines)
    if "scale" in parts:
        lines = head + ["## diagnose on ISO 10360-2 style length records (planted squareness_xy 15 µrad, ECZ 200 µrad)", "",
                  "| path | records | time / s | CPU / s of the diagnosis (whole process) | peak MB | load | chosen | estimates (u) | k (ranks) | chi2 rel. bound |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for n in sizes:
            r = run_fresh(SCALE.format(n=n, structured=True))
            print("scale", r, flush=True)
            est = ", ".join(f"{e} {v[0]:.2f} ({v[1]:.2f})" for e, v in r["estimates"].items())
            ranks = ", ".join(f"{k} {v}" for k, v in r["ranks"].items())
            lines.append(f"| structured | {r['n']:,} | {r['seconds']:.1f} | {r['diag_cpu_s']:.1f} ({r['cpu_s']:.1f}) | {r['peak_MB']:.0f} | {r['load']:.1f} | "
                         f"{' + '.join(r['chosen'])} | {est} | {r['k']} ({ranks}) | {r['bound']:.1e} |")
        lines.append("")
        write("scale", lines)
    return 0


def write(part: str, lines: list[str]) -> None:
    out = ROOT / "bench" / "results" / f"lengths_{part}.md"
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(out.read_text())


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
