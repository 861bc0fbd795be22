"""``cmmwb calibrate RECORDINGS.csv [more] --task TASK.toml --out DIR``: the six factors'
hyper-parameters from the machine's recordings by REML (docs/calibrate.md;
:func:`generator.calibration.run.run_calibrate`)."""

from __future__ import annotations

import sys
from contextlib import nullcontext
from dataclasses import replace
from pathlib import Path

from cmmwb.xlfuncs.model import MPE1

from ..taskfile import collecting_notes, naming_lines, read_toml
from .common import add_command


def register(sub) -> None:
    s = add_command(sub, "calibrate", "the six factors' hyper-parameters from recordings (REML)",
                    "Restricted maximum likelihood of the Forbes 2025 hyper-parameters (sigma_R_um, sigma_S_ppm, "
                    "..., lambda_P) from the machine's own recordings (ISO 10360-2 lengths, step gauges, ball "
                    "plates: docs/recordings.md), with the effects the locator names as fixed effects; the "
                    "covariance of the estimates, what the records cannot identify and what would, the MPE "
                    "check of the fitted model, and the effects fed back as compensation or as an influence "
                    "factor (docs/calibrate.md).",
                    ("cmmwb calibrate iso.csv stepgauge.csv --task machine.toml --out cal",
                     "cmmwb calibrate iso.csv --task machine.toml --mpe 1.5,333 --out cal",
                     "cmmwb calibrate plate.csv --task machine.toml --feedback factor --out cal"))
    s.add_argument("recordings", nargs="+", metavar="RECORDINGS.csv",
                   help="recordings CSV files (lengths or points); each is an independent session")
    s.add_argument("--task", metavar="TASK.toml",
                   help="task file: its [parameters] are the starting values, its [[probes]] the probes, its "
                        "[mpe] the MPE statement checked")
    s.add_argument("--sigma-um", type=float, metavar="S",
                   help="instead of --task: start from a model with only repeatability sigma_R_um = S (µm)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    s.add_argument("--effects", default="auto", metavar="auto|none|NAME[,NAME]",
                   help="systematic effects estimated jointly as fixed effects: 'auto' those the locator names "
                        "(diagnose with the task's model), 'none', or a list of effect names of "
                        "docs/recordings.md section 4 (default: auto)")
    s.add_argument("--feedback", default="compensate", choices=("compensate", "factor", "none"),
                   help="how the effects enter the fitted task: compensated coordinates (the factor keeps the "
                        "corrections' u), an additional influence factor, or not at all (default: compensate)")
    s.add_argument("--mpe", default=None, metavar="A,B[,K]",
                   help="MPE statement E = A + L/B (A in µm, B in mm) and coverage factor K (default 2) for the "
                        "check; default: the task's [mpe]")
    s.add_argument("--rule", default=None, metavar="RULE[:VALUE]",
                   help="decision rule of the MPE verdict on C_max with U = 2 u(C_max): iso14253 (default), simple, "
                        "guarded_acceptance:R, guarded_rejection:R, specific_risk:MAX_PFA (docs/conformity.md)")
    s.add_argument("--start", default="task", choices=("task", "mpe1"),
                   help="starting values: the task's [parameters] (a zero there leaves the factor out), or "
                        "Forbes 2025 Table 3 MPE1 for every factor (default: task)")
    s.add_argument("--alpha", type=float, default=0.01, help="significance level of the locator (default: 0.01)")
    s.add_argument("--covariance", default="auto", choices=("auto", "dense", "structured"),
                   help="record covariance of the fit: dense n x n, structured (C = D + U U^T of diagnose, "
                        "never n x n: large files), or auto (dense up to 4000 observations per file, "
                        "structured above; default: auto)")
    s.add_argument("--profiles", default="auto", choices=("auto", "yes", "no"),
                   help="REML likelihood profiles of the estimates (about 9 refits each): yes, no, or auto "
                        "(only when every file has the dense covariance; default: auto)")
    s.add_argument("--no-workbook", action="store_true", help="skip the workbook (default: write it)")
    s.add_argument("--force", action="store_true",
                   help="replace outputs edited since cmmwb wrote them, keeping a backup (default: refuse)")
    s.set_defaults(func=run)


def run(args) -> int:
    from ..calibration.run import parse_mpe, parse_rule, run_calibrate  # the REML fit (scipy): only when run
    from ..diagnosis.run import load_model

    with collecting_notes() as notes:       # implausible values of the task or --mpe: warned about
        model, label = load_model(args.task, args.sigma_um)
        if args.start == "mpe1":
            model = replace(model, params=MPE1)
            label += " (starting values: Forbes 2025 Table 3 MPE1)"
        task_path = Path(args.task) if args.task else None
        doc = None
        if task_path is not None:
            doc = read_toml(task_path)
        with naming_lines(task_path) if task_path is not None else nullcontext():
            mpe = parse_mpe(args.mpe, doc, model.probes, task_path)
    rule = parse_rule(args.rule)
    result, files = run_calibrate([Path(p) for p in args.recordings], model, Path(args.out), task_path=task_path,
                                  task_label=label, effects=args.effects, feedback=args.feedback, mpe=mpe,
                                  alpha=args.alpha, workbook=not args.no_workbook, force=args.force,
                                  covariance=args.covariance, profiles=args.profiles, rule=rule,
                                  warnings=notes)
    for w in result["warnings"]:
        print(f"cmmwb: warning: {w}", file=sys.stderr)
    print(result["summary"])
    for f in files:
        print(f"  -> {f}")
    return 0
