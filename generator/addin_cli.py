"""``cmmwb addin build-oxt --out cmmwb.oxt``: the LibreOffice Calc add-in as an extension."""

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


def register(sub) -> None:
    s = sub.add_parser("addin", help="the spreadsheet add-ins (see docs/addins.md)")
    verbs = s.add_subparsers(dest="addin_command", required=True)
    b = verbs.add_parser("build-oxt", help="write the LibreOffice Calc add-in extension (.oxt); "
                                           "install it with: unopkg add FILE.oxt")
    b.add_argument("--out", required=True, help="extension file to write, e.g. cmmwb.oxt")
    b.add_argument("--force", action="store_true", help="overwrite an existing file")
    b.set_defaults(func=cmd_build_oxt)
