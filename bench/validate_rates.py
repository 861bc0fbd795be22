"""Rates of ``cmmwb validate`` (xlfuncs/validation.py) on simulated machines with known truth.

Every set is a validation set of :mod:`cmmwb.xlfuncs.validation_sets` measured (two runs) by a
CMM drawn from Forbes 2025 Table 3 MPE1 (probes P1, P2 at +-20 mm in y, 30 mm below the head),
its certificates drawn from their U_cal; the task is the machine's own model (MPE1), so that

* **model right** (nothing planted): the verdict should be "holds" in >= 95 % of the sets and the
  share of rows with E_n <= 1 near the claimed 95.45 %;
* **effect planted** that the task does not model (20 µrad squareness_xy, 30 µm/m scale): the
  verdict should be "does not hold" in >= 95 % of the sets, and name the effect.

Usage::

    OPENBLAS_NUM_THREADS=1 python bench/validate_rates.py              # 200 sets per layout and case
    OPENBLAS_NUM_THREADS=1 python bench/validate_rates.py --sets 20 --only stepgauge

Writes ``bench/results/validate_rates.md`` (rewritten after every layout; the text from the notes
marker on is kept).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cmmwb.xlfuncs import validation as va  # noqa: E402
from cmmwb.xlfuncs import validation_sets as vsm  # noqa: E402
from cmmwb.xlfuncs.locator.model import Model  # noqa: E402
from cmmwb.xlfuncs.model import MPE1  # noqa: E402  (Forbes 2025 Table 3)

PROBES = vsm.DEFAULT_PROBES
LAYOUTS = (
    ("ballplate", "ball plate 5 x 5 (pitch 100 mm, xy plane): 300 centre distances x 2 runs, probed points",
     ("ballplate",)),
    ("stepgauge", "step gauges along x, y, xy (21 steps): 123 lengths x 2 runs, two probes, probed points",
     ("stepgauge",)),
    ("rings+spheres", "rings 25, 100 mm and two spheres: 5 fitted characteristics x 2 runs, no probed points",
     ("ring", "sphere")),
    ("all", "all four workpieces: 428 characteristics x 2 runs", ("ballplate", "stepgauge", "ring", "sphere")),
)
CASES = (("model right", {}), ("squareness_xy 20 µrad", {"squareness_xy": 20.0}),
         ("scale 30 µm/m", {"scale": 30.0}))
NOTES_MARKER = "<!-- notes: kept when the tables are rewritten -->"
OUT = ROOT / "bench" / "results" / "validate_rates.md"


def run_case(vs, U, planted: dict, sets: int, seed0: int) -> dict:
    model = Model(MPE1, PROBES, True)
    holds, shares, named, other, kinds, times = 0, [], 0, {}, {}, []
    for k in range(sets):
        meas = vsm.measure(vs, MPE1, planted, seed=seed0 + k, runs=2)
        rows, geo = vsm.rows_of(vs, meas, U)
        t = time.perf_counter()
        v = va.validate(rows, geo, model)
        times.append(time.perf_counter() - t)
        holds += v.holds
        shares.append(v.count.within / v.count.n)
        if not v.holds and v.causes:
            c = v.causes[0]
            kinds[c["kind"]] = kinds.get(c["kind"], 0) + 1
            want = next(iter(planted), None)
            name = c.get("name") or ("scale" if c["kind"] == "scale" else None)
            if want is not None and name == want:
                named += 1
            elif name is not None:
                other[name] = other.get(name, 0) + 1
    return {"sets": sets, "holds": holds, "share_mean": float(np.mean(shares)), "share_min": float(np.min(shares)),
            "named": named, "other": other, "kinds": kinds, "time_s": float(np.median(times))}


def table(results: list[tuple[str, str, str, dict]]) -> str:
    lines = ["| layout | case | sets | verdict holds | does not hold | names the planted effect | other cause named "
             "(first cause) | rows within E_n <= 1 (mean, min) | median time |",
             "|---|---|---|---|---|---|---|---|---|"]
    for key, _, case, r in results:
        n = r["sets"]
        fails = n - r["holds"]
        named = f"{r['named']}/{n}" if case != "model right" else "—"
        other = ", ".join(f"{k} {v}" for k, v in sorted(r["other"].items(), key=lambda kv: -kv[1])) or "—"
        kinds = ", ".join(f"{k} {v}" for k, v in sorted(r["kinds"].items(), key=lambda kv: -kv[1]))
        lines.append(f"| {key} | {case} | {n} | {r['holds']}/{n} ({100 * r['holds'] / n:.1f} %) | {fails}/{n} "
                     f"({100 * fails / n:.1f} %) | {named} | {other}{' (' + kinds + ')' if kinds else ''} | "
                     f"{100 * r['share_mean']:.2f} %, {100 * r['share_min']:.1f} % | {r['time_s']:.2f} s |")
    return "\n".join(lines)


def write(results, sets: int) -> None:
    keep = ""
    if OUT.exists():
        text = OUT.read_text(encoding="utf-8")
        if NOTES_MARKER in text:
            keep = text[text.index(NOTES_MARKER):]
    head = ("# `cmmwb validate` on simulated machines with known truth\n\n"
            f"`bench/validate_rates.py`, {sets} sets per layout and case; machine and task: Forbes 2025 Table 3 "
            "MPE1, probes P1 (0, 20, -30) and P2 (0, -20, -30) mm; two runs of every workpiece; certificates "
            "U_cal = 0.3 + 0.5 L/m µm (ball plate), 0.2 + 0.5 L/m (step gauge), 0.15 (rings), 0.1 (sphere "
            "diameters), 0.3 + 0.5 L/m (sphere distance), k_cal = 2; verdict at alpha = 0.01 "
            "(docs/validate.md).\n\nLayouts:\n\n" + "\n".join(f"- **{k}**: {d}" for k, d, _ in LAYOUTS) + "\n\n")
    OUT.write_text(head + table(results) + "\n\n" + (keep or NOTES_MARKER + "\n"), encoding="utf-8")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sets", type=int, default=200)
    ap.add_argument("--only", default=None)
    ap.add_argument("--seed0", type=int, default=0)
    args = ap.parse_args()
    results = []
    for key, desc, wps in LAYOUTS:
        if args.only and key not in args.only.split(","):
            continue
        vs = vsm.build(wps, PROBES)
        U = vsm.model_U(vs, MPE1)
        for case, planted in CASES:
            t = time.perf_counter()
            r = run_case(vs, U, planted, args.sets, args.seed0)
            results.append((key, desc, case, r))
            print(f"{key:14s} {case:24s} holds {r['holds']}/{r['sets']} named {r['named']} share "
                  f"{r['share_mean']:.4f} ({time.perf_counter() - t:.0f} s)", flush=True)
            write(results, args.sets)


if __name__ == "__main__":
    main()
