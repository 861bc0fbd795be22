"""``cmmwb addin build-oxt --out cmmwb.oxt``: the LibreOffice Calc add-in as an extension;
``cmmwb addin relink BOOK.xlsx --out BOOK.ods``: the large workbook with its ``Live_addin``
formulas bound to that add-in, so they compute in Calc (generator/lo_addin/relink_live.py)."""

from __future__ import annotations

from pathlib import Path

from .errors import InputError


def cmd_build_oxt(args) -> int:
    from .oxt import build_oxt

    out = Path(args.out)
    if out.suffix.lower() != ".oxt":
        raise InputError("the extension file must end in .oxt (unopkg needs it)", file=out)
    if out.exists() and not args.force:
        raise InputError("exists already (use --force to overwrite)", file=out)
    print(build_oxt(out))
    return 0


LO_PYTHON = "/usr/bin/python3"  # LibreOffice's Python (python3-uno on Debian/Ubuntu)


def cmd_relink(args) -> int:
    import shutil
    import subprocess

    from .oxt import SOURCES

    book, out = Path(args.book), Path(args.out)
    if not book.is_file():
        raise InputError("no such workbook", file=book)
    if out.suffix.lower() != ".ods":
        raise InputError("the relinked workbook must end in .ods (it keeps the add-in names)", file=out)
    if out.exists() and not args.force:
        raise InputError("exists already (use --force to overwrite)", file=out)
    python = args.lo_python or LO_PYTHON
    if shutil.which("soffice") is None or subprocess.run([python, "-c", "import uno"],
                                                         capture_output=True).returncode != 0:
        raise InputError(f"needs LibreOffice (soffice) and its Python with uno ({python}; "
                         "apt-get install libreoffice-script-provider-python python3-numpy)", file=book)
    cmd = [python, str(SOURCES / "relink_live.py"), str(book), "--out", str(out)]
    if args.profile:
        cmd += ["--profile", args.profile]
    if args.cache:
        cmd += ["--cache", args.cache]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        raise InputError(f"LibreOffice could not relink the workbook: {run.stderr.strip()}", file=book)
    print(run.stdout.strip())
    return 0


def register(sub) -> None:
    s = sub.add_parser("addin", help="the spreadsheet add-ins (see docs/addins.md)")
    verbs = s.add_subparsers(dest="addin_command", required=True)
    b = verbs.add_parser("build-oxt", help="write the LibreOffice Calc add-in extension (.oxt); "
                                           "install it with: unopkg add FILE.oxt")
    b.add_argument("--out", required=True, help="extension file to write, e.g. cmmwb.oxt")
    b.add_argument("--force", action="store_true", help="overwrite an existing file")
    b.set_defaults(func=cmd_build_oxt)
    r = verbs.add_parser("relink", help="save a large workbook as .ods whose Live_addin formulas compute "
                                        "in LibreOffice with the installed add-in (docs/addins.md)")
    r.add_argument("book", help="large workbook (.xlsx) written by cmmwb build")
    r.add_argument("--out", required=True, help="LibreOffice workbook to write, e.g. plate.ods")
    r.add_argument("--force", action="store_true", help="overwrite an existing file")
    r.add_argument("--profile", help="LibreOffice user profile folder that has the extension "
                                     "(default: your own profile)")
    r.add_argument("--cache", help="UNO_SHARED_PACKAGES_CACHE folder of a private "
                                   "'unopkg add --shared' installation")
    r.add_argument("--lo-python", help=f"LibreOffice's Python (default {LO_PYTHON})")
    r.set_defaults(func=cmd_relink)
