"""``cmmwb diagnose RECORDINGS.csv --task TASK.toml --out DIR`` (or ``--sigma-um S``): the
mismatch locator (docs/recordings.md) writes ``DIR/diagnosis.json`` (section 5),
``DIR/diagnosis.xlsx`` (native refit) and PNG plots, all or nothing, and prints the plain-language
answer (:func:`generator.diagnosis.run.run_diagnose`)."""

from __future__ import annotations

import sys
from pathlib import Path

from cmmwb.xlfuncs.memory import STRUCTURED_MIN_OBS

from .common import add_command


def register(sub) -> None:
    s = add_command(sub, "diagnose", "compare recordings with the simulation: where, why, what to add",
                    "Mismatch locator (docs/recordings.md): chi-square of the recordings against the "
                    "simulation's covariance, location of the mismatch, the candidate effects that explain "
                    "it, and the refit. Writes DIR/diagnosis.json, a workbook whose refit uses native "
                    "formulas, and residual plots before and after.",
                    ("cmmwb diagnose stepgauge.csv --task machine.toml --out diag",
                     "cmmwb diagnose plate.csv --sigma-um 0.3 --out diag --alpha 0.001",
                     "cmmwb simulate --layout stepgauge --effect scale_x=2 --out rec.csv && "
                     "cmmwb diagnose rec.csv --sigma-um 0.2 --out d"))
    s.add_argument("recordings", metavar="RECORDINGS.csv",
                   help="recordings CSV (length records: a measured_mm column; point records: x_nom)")
    s.add_argument("--task", metavar="TASK.toml",
                   help="task file whose [parameters] and [[probes]] define the simulation")
    s.add_argument("--sigma-um", type=float, metavar="S",
                   help="instead of --task: a simulation with only repeatability sigma_R_um = S (µm)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    s.add_argument("--alpha", type=float, default=0.01, help="significance level (default: 0.01)")
    s.add_argument("--alpha-name", type=float, default=None, metavar="P",
                   help="adjusted p-value below which an effect is named as the cause (default: alpha/100); "
                        "between it and alpha the best effect is only 'indicated'")
    s.add_argument("--no-plots", action="store_true", help="skip the PNG plots (default: write them)")
    s.add_argument("--no-workbook", action="store_true", help="skip the workbook (default: write it)")
    s.add_argument("--force", action="store_true",
                   help="replace outputs edited since cmmwb wrote them, keeping a backup (default: refuse)")
    s.add_argument("--exact", action="store_true",
                   help="the dense record covariance (exact, memory ~ n^2) even for large point records "
                        "(default: above %d observations the structured operator, error bound in the "
                        "JSON's approximation)" % STRUCTURED_MIN_OBS)
    s.set_defaults(func=run)


def run(args) -> int:
    from ..diagnosis.run import load_model, run_diagnose  # the locator (scipy): only when run
    from ..taskfile import collecting_notes

    with collecting_notes() as notes:
        model, label = load_model(args.task, args.sigma_um)
    result, files = run_diagnose(Path(args.recordings), model, Path(args.out), alpha=args.alpha,
                                 plots=not args.no_plots, workbook=not args.no_workbook, task_label=label,
                                 force=args.force, exact=args.exact, alpha_name=args.alpha_name,
                                 warnings=notes, task_path=Path(args.task) if args.task else None)
    for w in result["warnings"]:
        print(f"cmmwb: warning: {w}", file=sys.stderr)
    print(result["summary"])
    for f in files:
        print(f"  -> {f}")
    return 0
