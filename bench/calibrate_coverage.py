"""Coverage of the hyper-parameter fit of ``cmmwb calibrate`` (xlfuncs/calibrate.py).

Recordings simulated (``xlfuncs.locator.simulate``, the generative model behind Forbes 2025 eq. 28) from
known hyper-parameters (Forbes 2025 Table 3, MPE1) on the layouts below; every set is fitted by
REML from the task's values, and for every hyper-parameter the bench counts how often it is
estimated, how often the estimate lies within 2 u of the truth (in log: |log est - log true| <=
2 u(log)), and how often it is reported not identifiable or zero.

Usage::

    OPENBLAS_NUM_THREADS=1 python bench/calibrate_coverage.py            # 200 sets per layout
    OPENBLAS_NUM_THREADS=1 python bench/calibrate_coverage.py --sets 20 --only iso

Writes ``bench/results/calibrate_coverage.md`` (the table is rewritten after every layout, so a
stopped run leaves the sets it finished, with their counts).
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

from cmmwb.xlfuncs import calibrate as cb  # noqa: E402
from cmmwb.xlfuncs import pointcloud as pc  # noqa: E402
from cmmwb.xlfuncs import reml  # noqa: E402
from cmmwb.xlfuncs.locator import simulate as sm  # noqa: E402
from cmmwb.xlfuncs.locator.model import Model, prepare  # noqa: E402
from cmmwb.xlfuncs.model import MPE1  # noqa: E402  (Forbes 2025 Table 3)

THREE = (pc.Probe("P1", (0.0, 0.0, -50.0)), pc.Probe("P2", (150.0, 0.0, -50.0)), pc.Probe("P3", (0.0, 150.0, -50.0)))
PAIR = (pc.Probe("P1", (0.0, 20.0, -30.0)), pc.Probe("P2", (0.0, -20.0, -30.0)))
ONE = (pc.Probe("P1", (0.0, 0.0, -50.0)),)

LAYOUTS = (
    ("iso", "ISO 10360-2 lengths, 3 probes (offsets 0/150 mm), 3 repeats", "iso10360", THREE, {}),
    ("iso1", "ISO 10360-2 lengths, one probe offset", "iso10360", ONE, {}),
    ("step", "step gauges (x, y, xy), two probes, 2 repeats", "stepgauge", PAIR, {"repeats": 2}),
    ("ball", "ball plate 5x5, 4 passes, two probes", "ballplate", PAIR, {"passes": 4}),
    ("spheres", "four spheres, 13 points each with normals, two probes", "spheres", PAIR, {}),
)


def run_layout(key, title, name, probes, kw, sets, seed0=0, start_factor=1.0):
    L = sm.layout(name, probes, **kw)
    start = pc.Parameters(**{n: getattr(MPE1, n) * start_factor for n in reml.NAMES})
    model = Model(MPE1, probes, True)
    stats = {n: {"estimated": 0, "within": 0, "not identifiable": 0, "zero": 0, "zero_covered": 0, "off": 0,
                 "fixed": 0}
             for n in reml.NAMES}
    times, n_obs, failed = [], 0, 0
    for k in range(sets):
        rec = sm.simulate(L, MPE1, {}, seed=seed0 + k)
        prep = prepare(rec, model, False)
        n_obs = prep.r_um.shape[0]
        t = time.perf_counter()
        try:
            cal = cb.calibrate([reml.record_set(prep, key)], start)
        except Exception as e:  # noqa: BLE001  (counted and reported)
            failed += 1
            print(f"  set {k}: {e}", file=sys.stderr)
            continue
        times.append(time.perf_counter() - t)
        for n, e in cal.estimates.items():
            st = stats[n]
            st[e.status] += 1
            truth = getattr(MPE1, n)
            if e.status == "estimated":
                if abs(math.log(e.value) - math.log(truth)) <= 2.0 * e.u_log:
                    st["within"] += 1
            elif e.status == "zero" and e.upper is not None and truth <= e.upper:
                st["zero_covered"] += 1
    return {"key": key, "title": title, "sets": sets, "failed": failed, "obs": n_obs, "stats": stats,
            "median_s": float(np.median(times)) if times else float("nan"),
            "max_s": float(np.max(times)) if times else float("nan")}


def table(results, started: str, start_factor: float = 1.0) -> str:
    lines = ["# Coverage of the hyper-parameter fit (`cmmwb calibrate`)", "",
             f"Written by `bench/calibrate_coverage.py` ({started}; timings under load: 2 cores shared by "
             "six sessions, one BLAS thread).", "",
             "Truth: Forbes 2025 Table 3, MPE1, for every simulated machine; the fit starts from "
             + ("the same values" if start_factor == 1.0 else f"{start_factor:g} x those values (every sigma and "
                "lambda; the parameters not identified are held there)") + ". *within 2u*: |log estimate - log truth| <= 2 u(log estimate), u from the observed "
             "information; counted over the sets in which the parameter was estimated. *not ident.*: "
             "held at the task's value and reported not identifiable (with the measurement that would "
             "identify it); *zero*: the likelihood is largest at zero (the estimate is 0, reported with the "
             "upper one-sided 95 % limit of its REML profile); *truth below the upper limit*: of those; "
             "*share, estimated or zero*: (within 2u + truth below the limit) / (estimated + zero).", ""]
    for r in results:
        lines += [f"## {r['title']}", "",
                  f"{r['sets']} sets ({r['failed']} failed), {r['obs']} observations each; fit median "
                  f"{r['median_s']:.2f} s, max {r['max_s']:.2f} s.", "",
                  "| hyper-parameter | estimated | within 2u | share | zero | truth below the upper limit | share, estimated or zero | not ident. |",
                  "|---|---|---|---|---|---|---|---|"]
        for n in reml.NAMES:
            st = r["stats"][n]
            share = f"{100.0 * st['within'] / st['estimated']:.1f} %" if st["estimated"] else "—"
            tried = st["estimated"] + st["zero"]
            both = f"{100.0 * (st['within'] + st['zero_covered']) / tried:.1f} %" if tried else "—"
            lines.append(f"| {n} | {st['estimated']} | {st['within']} | {share} | {st['zero']} | "
                         f"{st['zero_covered']} | {both} | {st['not identifiable']} |")
        lines.append("")
    return "\n".join(lines)


#: the line of a results file from which on the text is kept when the tables are rewritten
NOTES = "<!-- notes: not written by calibrate_coverage.py -->"


def write_keeping_notes(path: Path, tables: str) -> None:
    """The tables, then the hand-written part of the file as it was (from :data:`NOTES` on)."""
    old = path.read_text(encoding="utf-8") if path.exists() else ""
    notes = old[old.index(NOTES):] if NOTES in old else NOTES + "\n"
    path.write_text(tables + "\n\n" + notes, encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sets", type=int, default=200)
    ap.add_argument("--only", default=None, help="layout keys, comma-separated: " + ", ".join(k for k, *_ in LAYOUTS))
    ap.add_argument("--start-factor", type=float, default=1.0,
                    help="start the fit from this multiple of the true hyper-parameters (default 1)")
    ap.add_argument("--out", default=None, help="default: bench/results/calibrate_coverage.md "
                    "(calibrate_coverage_start<F>.md with --start-factor)")
    args = ap.parse_args(argv)
    if args.out is None:
        tail = "" if args.start_factor == 1.0 else f"_start{args.start_factor:g}"
        args.out = str(ROOT / "bench" / "results" / f"calibrate_coverage{tail}.md")
    keys = set(args.only.split(",")) if args.only else None
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    results = []
    for key, title, name, probes, kw in LAYOUTS:
        if keys and key not in keys:
            continue
        t = time.perf_counter()
        r = run_layout(key, title, name, probes, kw, args.sets, start_factor=args.start_factor)
        results.append(r)
        write_keeping_notes(Path(args.out), table(results, started, args.start_factor))
        print(f"{title}: {args.sets} sets in {time.perf_counter() - t:.0f} s", flush=True)
    print(table(results, started, args.start_factor))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
