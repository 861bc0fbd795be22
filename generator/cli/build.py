"""``cmmwb build TASK.toml --out DIR``: a task file into its workbook, JSON and plots
(:func:`generator.build.build_task`)."""

from __future__ import annotations

from pathlib import Path

from ..build import build_task
from ..jobs import job
from ..report import summary_lines
from .common import add_command


def register(sub) -> None:
    s = add_command(sub, "build", "task file -> workbook + JSON (+ plots)",
                    "Computes the task with the Python core and writes DIR/<name>.xlsx (native formulas), "
                    "DIR/<name>.json and PNG plots, all or nothing; prints the headline results.",
                    ("cmmwb build gauge.toml --out gauge",
                     "cmmwb build gauge.toml --out gauge --force      # after editing the workbook",
                     "cmmwb build bore.toml --out bore --no-plots --cache none",
                     "cmmwb build knuckle.toml --out knuckle --pdf    # and a printed PDF for the audit file",
                     "cmmwb import results.qif --stand-in --out plate.toml && cmmwb build plate.toml --out plate"
                     "   # a QIF file's characteristics decided (docs/import.md)"))
    s.add_argument("task", metavar="TASK.toml", help="the task file (see cmmwb new)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    s.add_argument("--no-plots", action="store_true", help="skip the PNG plots (default: write them)")
    s.add_argument("--pdf", action="store_true",
                   help="also print the workbook to DIR/<name>.pdf for the audit file (needs LibreOffice); "
                        "a later build of the task without --pdf removes that PDF, as it does every file "
                        "of the previous build it does not write again (an edited one: see --force)")
    s.add_argument("--force", action="store_true",
                   help="replace outputs that were edited since cmmwb wrote them, keeping NAME.bak backups "
                        "(default: refuse)")
    s.add_argument("--cache", choices=("results", "all", "none"), default="results",
                   help="cached values for programs that do not calculate: the Results sheet from the "
                        "JSON (default: results), every formula cell as the `formulas` engine computes it "
                        "(all; slow for big workbooks), or none")
    s.add_argument("--exact", action="store_true",
                   help="no approximation: a feature task's V_A by the exact O(m^2) sum even above "
                        "100,000 points (default: the task's [feature] va_method, auto)")
    s.set_defaults(func=run)


def run(args) -> int:
    if args.pdf:
        from ..workbook.pdf import require_libreoffice

        require_libreoffice()   # before anything is written
    results, files = build_task(Path(args.task), Path(args.out), plots=not args.no_plots,
                                force=args.force, cache=args.cache, exact=args.exact, pdf=args.pdf)
    print_built(results, files)
    return 0


def print_built(results: dict, files: list[Path], header: str | None = None) -> None:
    """The headline results of one built task and where its files went."""
    print(header if header is not None else f"[{results['kind']}] {results['name']}")
    for line in job(results["kind"]).summary(results) + summary_lines(results):
        print(f"    {line}")
    for f in files:
        print(f"    -> {f}")
