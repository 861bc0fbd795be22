"""``cmmwb import FILE --out TASK.toml|RECORDINGS.csv``: QIF and AQDEF files in (docs/import.md)."""

from __future__ import annotations

from pathlib import Path

from .common import add_command


def run(args) -> int:
    from ..importers import run_import

    files, report = run_import(Path(args.file), Path(args.out), features=args.feature, kind=args.kind,
                               normals=args.normals, force=args.force, stand_in=args.stand_in, part=args.part)
    for line in report:
        print(f"  {line}")
    for f in files:
        print(f)
    return 0


def register(sub) -> None:
    s = add_command(sub, "import", "QIF points or characteristics (or Q-DAS AQDEF values) -> task, "
                    "recordings or an annotated QIF",
                    "Reads the measured points of a QIF results file (ISO 23952: points, normals, probe "
                    "and nominal where given) into a pointcloud or feature task with its points table, "
                    "or (--out FILE.csv) into point recordings for cmmwb diagnose, each point against "
                    "its closest point on the file's nominal element. Its characteristics (tolerances, "
                    "measured values, PASS/FAIL): --out COPY.qif writes a copy with combinedUncertainty on "
                    "every supported value, in the file's own unit, each saying where its u comes from (the "
                    "file's points, or a simulated stand-in part when it has none); --stand-in --out "
                    "TASK.toml writes them as a characteristic task on that stand-in part (the file's "
                    "values as 'measured', its tolerances; MMC positions with their bonus) that cmmwb "
                    "build decides. Units converted to mm and stated; what the file holds but cmmwb does "
                    "not use is named, never dropped silently. Details: docs/import.md.",
                    ("cmmwb import part.qif --out bore.toml --feature BORE_1 && cmmwb build bore.toml --out bore",
                     "cmmwb import part.qif --out gauge.toml --feature SPH_1 --feature SPH_2   # a pointcloud task",
                     "cmmwb import part.qif --out part.csv && cmmwb diagnose part.csv --task bore.toml --out diag",
                     "cmmwb import results.qif --out results_u.qif      # the characteristics' u, in a copy",
                     "cmmwb import results.qif --stand-in --part 183 --out plate.toml && cmmwb build plate.toml "
                     "--out plate"))
    s.add_argument("file", metavar="FILE",
                   help="a QIF file (.qif) or an AQDEF file (.dfq, .dfd with its .dfx)")
    s.add_argument("--out", required=True, help="task file to write (.toml; the points go to the .csv "
                                                "of the same name), recordings (.csv), or a copy of a QIF "
                                                "file with its characteristics' uncertainties (.qif)")
    s.add_argument("--feature", action="append", metavar="NAME",
                   help="feature to import (FeatureName or id; repeat for a pointcloud task of several; "
                        "required for a task: without it the command lists the file's features; for "
                        "recordings default: every feature with a nominal plane, circle, cylinder or sphere)")
    s.add_argument("--kind", choices=("feature", "pointcloud"),
                   help="task kind (default: feature for one --feature, pointcloud for several)")
    s.add_argument("--normals", choices=("file", "from-feature"), default="file",
                   help="point normals from the file (default), or from the measured element when the "
                        "file has none (stated in the task notes)")
    s.add_argument("--stand-in", action="store_true",
                   help="QIF characteristics -> a characteristic task (--out TASK.toml) on a simulated stand-in "
                        "part built from the file's nominals (said in the task's notes and the outputs): the "
                        "file's measured values decided with the stand-in's u")
    s.add_argument("--part", metavar="ID",
                   help="with --stand-in: the measured part (MeasurementResults id) whose values the task "
                        "decides (default: the first)")
    s.add_argument("--force", action="store_true", help="overwrite existing output files (default: refuse)")
    s.set_defaults(func=run)
