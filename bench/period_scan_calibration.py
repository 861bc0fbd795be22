"""Calibration of the periodic candidates' look-elsewhere correction (docs/diagnose.md section 6).

On records that agree with the simulation, the p-value of the best period of the scan (the
chi-square tail with 2 df times the look-elsewhere factor M) must be below alpha in at most alpha
of the sets.  Measured for two factors: M = the periods of the scan's grid (what the locator
uses) and M = the independent periods, 1 + (1/P_min - 1/P_max) x travel (too few).

Usage::

    python bench/period_scan_calibration.py            # 200 null sets per layout
    python bench/period_scan_calibration.py --sets 50

Writes ``bench/results/period_scan_calibration.md``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cmmwb.xlfuncs.locator import diagnose as dg  # noqa: E402
from cmmwb.xlfuncs.locator import effects as fx  # noqa: E402
from cmmwb.xlfuncs.locator import simulate as sm  # noqa: E402
from cmmwb.xlfuncs.locator.linalg import Whitener, orth, project_out  # noqa: E402
from cmmwb.xlfuncs.locator.search import Candidate, scan_period  # noqa: E402

sys.path.insert(0, str(ROOT / "bench"))
from diagnose_benchmark import MPE1, ONE, PAIR  # noqa: E402

LAYOUTS = (("step gauges (x, y, xy), one probe", "stepgauge", ONE, {}),
           ("step gauges, two probes", "stepgauge", PAIR, {}),
           ("hole plate (2-D, two passes)", "holeplate", PAIR[:1], {"passes": 2}))
LEVELS = (0.1, 0.05, 0.01)


def best_period_p(rec, model) -> dict[str, tuple[float, float]]:
    """{candidate: (log p raw of the best period, number of independent periods)} before any effect."""
    prep = dg.prepare(rec, model)
    W = Whitener(prep.C)
    Q0, _ = orth(W(prep.A)) if prep.A.shape[1] else (np.zeros((len(prep.r_um), 0)), [])
    y0 = project_out(Q0, W(prep.r_um))
    out = {}
    for name in fx.PERIODIC:
        a = fx.AXES.index(name[-1])
        try:
            lo, hi, span = fx.period_range(prep.design, a)
        except fx.NotApplicable:
            continue
        c, white = Candidate(name), {}
        scan_period(prep, W, Q0, Q0, y0, white, c)
        Qz, kept = orth(project_out(Q0, white[name][:, c.kept]))
        dchi = float(np.sum((Qz.T @ y0) ** 2))
        out[name] = (dg.chi2_logsf(dchi, len(kept)), c.n_periods, 1 + math.floor((1 / lo - 1 / hi) * span))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sets", type=int, default=200, help="null sets per layout (default 200)")
    ap.add_argument("--seed", type=int, default=5000)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    lines = ["# Look-elsewhere correction of the period scan (null sets)", "",
             f"{args.sets} null sets per layout (MPE1 noise, no effect), seeds {args.seed}..; share of the "
             f"candidates whose best period has a corrected p-value below the level. "
             f"`python bench/period_scan_calibration.py --sets {args.sets}`", "",
             "| layout | candidate | M grid / independent | " + " | ".join(
                 f"p < {q:g}: grid M / independent M" for q in LEVELS) + " |",
             "|---|---|---|" + "---|" * len(LEVELS)]
    for label, name, probes, kw in LAYOUTS:
        L = sm.layout(name, probes, **kw)
        model = dg.Model(MPE1, probes, True)
        got: dict[str, list] = {}
        for s in range(args.sets):
            rec = sm.simulate(L, MPE1, {}, seed=args.seed + s)
            for cand, v in best_period_p(rec, model).items():
                got.setdefault(cand, []).append(v)
        for cand, vals in got.items():
            logp = np.array([v[0] for v in vals])
            Mg, Mi = vals[0][1], vals[0][2]
            cells = []
            for q in LEVELS:
                grid = np.mean(logp + math.log(Mg) < math.log(q))
                ind = np.mean(logp + math.log(Mi) < math.log(q))
                cells.append(f"{100 * grid:.1f} % / {100 * ind:.1f} %")
            lines.append(f"| {label} | {cand} | {Mg} / {Mi} | " + " | ".join(cells) + " |")
    lines += ["", f"{time.perf_counter() - t0:.0f} s."]
    text = "\n".join(lines) + "\n"
    Path(args.out).mkdir(parents=True, exist_ok=True)
    name = "period_scan_calibration.md" if args.sets >= 200 else f"period_scan_calibration_{args.sets}.md"
    (Path(args.out) / name).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
