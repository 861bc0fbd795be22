"""``cmmwb addin build-oxt --out cmmwb.oxt``: the LibreOffice Calc add-in as an extension;
``cmmwb addin relink BOOK.xlsx --out BOOK.ods``: the large workbook with its ``Live_addin``
formulas bound to that add-in, so they compute in Calc (generator/lo_addin/relink_live.py)."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .common import add_command


def cmd_build_oxt(args) -> int:
    from ..oxt import build_oxt

    out = Path(args.out)
    if out.suffix.lower() != ".oxt":
        raise InputError("the extension file must end in .oxt (unopkg needs it)", file=out)
    if out.exists() and not args.force:
        raise InputError("exists already (use --force to overwrite)", file=out)
    print(build_oxt(out))
    return 0


LO_PYTHON = "/usr/bin/python3"  # LibreOffice's Python (python3-uno on Debian/Ubuntu)
#: the sheet whose add-in formulas relink binds (generator/lo_addin/relink_live.py: LIVE)
LIVE_SHEET = "Live_addin"


def cmd_relink(args) -> int:
    """Checks first, in cmmwb's process (the workbook guard, the ``Live_addin`` sheet, the output's
    folder), then LibreOffice on a private copy of the book: its lock file (``.~lock.NAME#``) is
    made and removed in that copy's folder, never beside the user's file."""
    import shutil
    import subprocess
    import tempfile
    import zipfile

    from ..oxt import SOURCES
    from ..workbook.cache import sheet_parts
    from ..workbook.safe_xlsx import check

    book, out = Path(args.book), Path(args.out)
    check(book)                    # the workbook guard: a regular .xlsx, no macros, links, DDE, bombs
    with zipfile.ZipFile(book) as z:
        try:
            sheets = sheet_parts(z)
        except (KeyError, ValueError, zipfile.BadZipFile) as e:
            raise InputError(f"cannot list the workbook's sheets ({e})", file=book) from None
    if LIVE_SHEET not in sheets:
        raise InputError(f"has no {LIVE_SHEET} sheet: only the large workbooks cmmwb build writes above the "
                         "native size have one (this one computes without the add-in); nothing to relink",
                         file=book)
    if out.suffix.lower() != ".ods":
        raise InputError("the relinked workbook must end in .ods (it keeps the add-in names)", file=out)
    if not out.parent.is_dir():
        raise InputError("the output's folder does not exist (create it first)", file=out)
    if out.exists() and not args.force:
        raise InputError("exists already (use --force to overwrite)", file=out)
    python = args.lo_python or LO_PYTHON
    if shutil.which("soffice") is None or subprocess.run([python, "-c", "import uno"],
                                                         capture_output=True).returncode != 0:
        raise InputError(f"needs LibreOffice (soffice) and its Python with uno ({python}; "
                         "apt-get install libreoffice-script-provider-python python3-numpy)", file=book)
    with tempfile.TemporaryDirectory(prefix="cmmwb-relink-") as tmp:
        copy = Path(tmp) / book.name
        shutil.copyfile(book, copy)
        cmd = [python, str(SOURCES / "relink_live.py"), str(copy), "--out", str(out.resolve())]
        if args.profile:
            cmd += ["--profile", args.profile]
        if args.cache:
            cmd += ["--cache", args.cache]
        run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        lines = [line.strip() for line in run.stderr.splitlines() if line.strip()]
        raise InputError("LibreOffice could not relink the workbook: " + (lines[-1] if lines else
                         f"exit status {run.returncode}"), file=book)
    print(run.stdout.strip())
    return 0


def register(sub) -> None:
    s = add_command(sub, "addin", "the spreadsheet add-ins (see docs/addins.md)",
                    "The optional add-ins that compute the Gaussian-process blocks of large workbooks: "
                    "the LibreOffice Calc extension and the relinking of a large workbook so its "
                    "Live_addin sheet computes in Calc. Excel uses xlwings instead (docs/addins.md).",
                    ("cmmwb addin build-oxt --out cmmwb.oxt && unopkg add cmmwb.oxt",
                     "cmmwb addin relink plate.xlsx --out plate.ods"))
    verbs = s.add_subparsers(dest="addin_command", required=True, metavar="VERB")
    b = add_command(verbs, "build-oxt", "write the LibreOffice Calc add-in extension (.oxt)",
                    "Writes the LibreOffice Calc add-in (the functions of the Live_addin sheet) as an "
                    "extension file; install it with 'unopkg add FILE.oxt' (needs LibreOffice's "
                    "Python script provider and python3-numpy).",
                    ("cmmwb addin build-oxt --out cmmwb.oxt", "unopkg add cmmwb.oxt"))
    b.add_argument("--out", required=True, metavar="FILE.oxt",
                   help="extension file to write, e.g. cmmwb.oxt (required)")
    b.add_argument("--force", action="store_true", help="overwrite an existing file (default: refuse)")
    b.set_defaults(func=cmd_build_oxt)
    r = add_command(verbs, "relink", "save a large workbook as .ods whose Live_addin computes in Calc",
                    "Opens a large workbook written by cmmwb build in LibreOffice, re-enters its "
                    "Live_addin formulas so they bind to the installed cmmwb extension, recalculates "
                    "and saves it as .ods (LibreOffice 7.4 does not bind add-in names read from "
                    ".xlsx). Needs soffice and LibreOffice's Python with uno.",
                    ("cmmwb addin relink plate.xlsx --out plate.ods",
                     "cmmwb addin relink plate.xlsx --out plate.ods --profile ~/.config/libreoffice/4"))
    r.add_argument("book", help="large workbook (.xlsx) written by cmmwb build")
    r.add_argument("--out", required=True, metavar="FILE.ods",
                   help="LibreOffice workbook to write, e.g. plate.ods (required)")
    r.add_argument("--force", action="store_true", help="overwrite an existing file (default: refuse)")
    r.add_argument("--profile", metavar="DIR", help="LibreOffice user profile folder that has the "
                                                    "extension (default: your own profile)")
    r.add_argument("--cache", metavar="DIR", help="UNO_SHARED_PACKAGES_CACHE folder of a private "
                                                  "'unopkg add --shared' installation (default: none)")
    r.add_argument("--lo-python", metavar="PYTHON", help=f"LibreOffice's Python (default {LO_PYTHON})")
    r.set_defaults(func=cmd_relink)
