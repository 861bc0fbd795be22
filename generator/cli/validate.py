"""``cmmwb validate RESULTS.csv --task TASK.toml --out DIR``: does the model hold on this machine?
The task's U of every characteristic against calibrated workpieces measured on the machine
(ISO/TS 15530-4; docs/validate.md; :func:`generator.validation.run.run_validate`)."""

from __future__ import annotations

from pathlib import Path

from .common import add_command


def register(sub) -> None:
    s = add_command(sub, "validate", "check the model's U against calibrated workpieces (ISO/TS 15530-4)",
                    "Per measured characteristic of a calibrated workpiece E_n = |y - y_cal| / sqrt(U^2 + U_cal^2) "
                    "with U the task's (as cmmwb build computes it, or the fitted task cmmwb calibrate wrote); the "
                    "share of rows with E_n <= 1 against the coverage the model claims, where the deviations are "
                    "structured (the mismatch locator on lengths with their probed points) and the verdict with its "
                    "rule, cause and next step (docs/validate.md).",
                    ("cmmwb validate results.csv --task fitted.toml --out val",
                     "cmmwb validate results.csv --task lengths.toml --task features.toml --out val",
                     "cmmwb simulate --validation ballplate,stepgauge --out valset && "
                     "cmmwb validate valset/results.csv --task valset/validation_lengths.toml --out val"))
    s.add_argument("results", metavar="RESULTS.csv",
                   help="measured and calibrated values of calibrated workpieces (docs/validate.md section 2)")
    s.add_argument("--task", action="append", required=True, metavar="TASK.toml",
                   help="task file giving the model's U of the characteristics (repeatable: several tasks, "
                        "their results named apart)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    s.add_argument("--alpha", type=float, default=0.01,
                   help="significance level of the verdict: alpha/2 for the count, alpha/2 for the structure "
                        "(default: 0.01)")
    s.add_argument("--no-workbook", action="store_true", help="skip the workbook (default: write it)")
    s.add_argument("--force", action="store_true",
                   help="replace outputs edited since cmmwb wrote them, keeping a backup (default: refuse)")
    s.set_defaults(func=run)


def run(args) -> int:
    from ..validation.run import run_validate  # the core and the locator: only when run

    result, files = run_validate(Path(args.results), [Path(t) for t in args.task], Path(args.out), alpha=args.alpha,
                                 workbook=not args.no_workbook, force=args.force)
    print(result["summary"])
    for f in files:
        print(f"  -> {f}")
    return 0
