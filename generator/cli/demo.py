"""``cmmwb demo --out DIR``: every worked example of the three papers and the mismatch-locator
demonstrations into one folder, with the headline results."""

from __future__ import annotations

import time
from pathlib import Path

from .. import __version__
from ..build import build_task
from ..jobs import JOBS
from .build import print_built
from .common import add_command

EXAMPLES_DIR = Path(__file__).resolve().parents[1] / "examples"


def register(sub) -> None:
    s = add_command(sub, "demo", "build every worked example of the three papers",
                    "Builds the worked examples of the three papers (workbooks, JSON, PNG plots), the "
                    "mismatch-locator demonstrations and the validation loop (recordings -> calibrate -> "
                    "validate) into one folder, and prints the headline results.",
                    ("cmmwb demo", "cmmwb demo --out /tmp/demo --pdf"))
    s.add_argument("--out", default="cmmwb-demo", metavar="DIR", help="output folder (default: cmmwb-demo)")
    s.add_argument("--pdf", action="store_true",
                   help="also print every workbook to PDF beside it (needs LibreOffice)")
    s.set_defaults(func=run)


def run(args) -> int:
    from ..diagnosis.run import demo as diagnosis_demo  # the locator (scipy): only when run
    from ..validation.loop import demo as validation_demo

    out = Path(args.out)
    if args.pdf:
        from ..workbook.pdf import require_libreoffice

        require_libreoffice()
    t0 = time.perf_counter()
    print(f"cmmwb {__version__} demo: building the worked examples of the three papers into {out}/")
    for kind, mod in JOBS.items():
        for example in mod.EXAMPLES:
            t = time.perf_counter()
            results, files = build_task(EXAMPLES_DIR / example, out / kind, pdf=args.pdf)
            print_built(results, files, f"\n[{kind}] {results['name']}  ({time.perf_counter() - t:.1f} s)")
    diagnosis_demo(out / "diagnose")
    validation_demo(out / "validate")
    if args.pdf:
        from ..workbook.pdf import print_books

        t = time.perf_counter()
        pdfs = print_books(sorted(b for b in out.rglob("*.xlsx") if not b.with_suffix(".pdf").exists()))
        print(f"\n[pdf] {len(pdfs)} workbooks printed by LibreOffice ({time.perf_counter() - t:.1f} s)")
        for f in pdfs:
            print(f"    -> {f}")
    print(f"\nDone in {time.perf_counter() - t0:.1f} s. Open the .xlsx files in Excel or LibreOffice; "
          "every number is a formula you can follow back to the inputs.")
    return 0
