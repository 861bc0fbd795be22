"""``cmmwb demo --out DIR``: every worked example of the three papers, the characteristic plate, the
mismatch-locator demonstrations and the validation loop into one folder, each task file beside its book, and the
folder's index (:mod:`generator.demo_index`); a few lines on the console, ending with the index's
path (``--verbose``: every book's headline results too)."""

from __future__ import annotations

import os
import time
import tomllib
from pathlib import Path

from .. import __version__
from ..build import build_task
from ..demo_index import ITEMS, write_index
from ..jobs import JOBS
from ..workbook.atomic import Staging
from ..workbook.provenance import provenance
from .build import print_built
from .common import add_command

EXAMPLES_DIR = Path(__file__).resolve().parents[1] / "examples"


def register(sub) -> None:
    s = add_command(sub, "demo", "build every worked example of the three papers",
                    "Builds the worked examples of the three papers and a drawing's characteristics "
                    "(workbooks, JSON, PNG plots, each book's task file beside it), the mismatch-locator "
                    "demonstrations and the validation loop (recordings -> calibrate -> validate) into one "
                    "folder, and writes DIR/index.html (and DIR/index.md): which book "
                    "shows which paper's result or answers which question, the sheet to look at first and the "
                    "command that rebuilds it. Prints a few lines ending with the index's path.",
                    ("cmmwb demo --out cmmwb-demo",
                     "cmmwb demo --out demo --pdf      # and a PDF of every book (needs LibreOffice)"))
    s.add_argument("--out", default="cmmwb-demo", metavar="DIR", help="output folder (default: cmmwb-demo)")
    s.add_argument("--pdf", action="store_true",
                   help="also print every workbook to PDF beside it (needs LibreOffice)")
    s.add_argument("--force", action="store_true",
                   help="replace books and task files edited since an earlier demo wrote them into DIR, "
                        "keeping NAME.bak backups (default: refuse)")
    s.add_argument("--verbose", "-v", action="store_true",
                   help="print every book's headline results and files as it is built (default: a summary "
                        "of a few lines)")
    s.set_defaults(func=run)


def run(args) -> int:
    from ..diagnosis.run import demo as diagnosis_demo  # the locator (scipy): only when run
    from ..validation.loop import demo as validation_demo

    out = Path(args.out)
    if args.pdf:
        from ..workbook.pdf import require_libreoffice

        require_libreoffice()
    t0 = time.perf_counter()
    if args.verbose:
        print(f"cmmwb {__version__} demo: building the worked examples of the three papers into {out}/")
    rebuild: dict[str, str] = {}       # book, relative to out -> the command that rebuilds it, in out
    for kind, mod in JOBS.items():
        for example in mod.EXAMPLES:
            t = time.perf_counter()
            task = copy_task(EXAMPLES_DIR / example, out / kind, force=args.force)
            results, files = build_task(task, out / kind, pdf=args.pdf, force=args.force)
            book = next(f for f in files if f.suffix == ".xlsx")
            rebuild[book.relative_to(out).as_posix()] = f"cmmwb build {kind}/{task.name} --out {kind}"
            if args.verbose:
                print_built(results, files, f"\n[{kind}] {results['name']}  ({time.perf_counter() - t:.1f} s)")
    for f in diagnosis_demo(out / "diagnose", verbose=args.verbose, force=args.force):
        if f.name == "diagnosis.xlsx":
            case = f.parent.relative_to(out).as_posix()
            rebuild[f"{case}/{f.name}"] = (f"cmmwb diagnose {case}/recordings.csv --task {case}/task.toml "
                                           f"--out {case}")
    loop = out / "validate"
    for f in validation_demo(loop, verbose=args.verbose, force=args.force):
        if f.suffix == ".xlsx":
            rebuild[f.relative_to(out).as_posix()] = validation_command(f.parent.relative_to(out).as_posix(),
                                                                        loop.relative_to(out).as_posix())
    printed = ""
    if args.pdf:
        from ..workbook.pdf import print_books

        t = time.perf_counter()
        pdfs = print_books(sorted(b for b in out.rglob("*.xlsx") if not b.with_suffix(".pdf").exists()))
        printed = f"; {len(pdfs)} of them printed to PDF by LibreOffice in {time.perf_counter() - t:.1f} s"
        if args.verbose:
            print(f"\n[pdf] {len(pdfs)} workbooks printed by LibreOffice")
            for f in pdfs:
                print(f"    -> {f}")
    index = write_index(out, rebuild, force=args.force)
    print(f"{'' if not args.verbose else chr(10)}cmmwb {__version__} demo: {len(rebuild)} workbooks with their "
          f"JSON, plots and task files in {out}{os.sep} ({time.perf_counter() - t0:.1f} s{printed})")
    first = next((it for it in ITEMS if it.question and it.book in rebuild), None)
    if first is not None:
        print(f"  {first.question} Open {out / first.book}, sheet {first.first_sheet}.")
    print("  White cells are formulas you can follow back to the inputs; grey cells were computed by the "
          "Python core.")
    print(("" if args.verbose else "  --verbose prints every book's headline results; ") +
          f"{'  ' if args.verbose else ''}{index[1]} is the index as text.")
    print("Which book shows what, the sheet to look at first and how to rebuild it:")
    print(f"  {index[0]}")
    return 0


def validation_command(step: str, loop: str) -> str:
    """The command, run in the demo folder, that rebuilds the book of the validation loop's ``step``
    (its folder, ``validate/calibrate`` or ``validate/validate_start``/``validate_fitted``), from
    the files the loop wrote into ``loop`` (docs/validate.md section 6)."""
    name = step.rsplit("/", 1)[-1]
    if name == "calibrate":
        return (f"cmmwb calibrate {loop}/iso.csv {loop}/plate.csv --task {loop}/validation/start_lengths.toml "
                f"--profiles no --out {step}")
    tasks = {"validate_start": (f"{loop}/validation/start_lengths.toml", f"{loop}/validation/start_features.toml"),
             "validate_fitted": (f"{loop}/calibrate/fitted.toml", f"{loop}/validation/fitted_features.toml")}[name]
    return f"cmmwb validate {loop}/validation/results.csv " + " ".join(f"--task {t}" for t in tasks) + f" --out {step}"


def copy_task(example: Path, out_dir: Path, force: bool = False) -> Path:
    """The example task file and the files it reads (``[points] file``), copied into ``out_dir``
    (all or nothing, through the folder's manifest), so that its book can be rebuilt and the task
    edited there; the copy's path."""
    text = example.read_text(encoding="utf-8")
    names = [f["name"] for f in provenance(example, tomllib.loads(text))["input_files"]]
    with Staging(out_dir, force=force) as tmp:
        (tmp / example.name).write_text(text, encoding="utf-8", newline="\n")
        for name in names:
            (tmp / name).write_bytes((example.parent / name).read_bytes())
    return out_dir / example.name
