"""``cmmwb read BOOK.xlsx --out TASK.toml``: a filled-in workbook back into a task file.

Writes TASK.toml and, for point-cloud and feature tasks with a points table, ``<TASK>_points.csv``
beside it.  Nothing is written unless the whole workbook reads and the task validates; existing
files are kept unless ``--force``.  See :mod:`generator.reader` for what is read from where.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from .errors import InputError


def register(sub) -> None:
    from .commands import add_command

    s = add_command(sub, "read", "workbook (filled in, Excel or LibreOffice) -> task file",
                    "Reads the input cells of a workbook written by cmmwb build (and filled in or edited "
                    "in Excel or LibreOffice) back into a task file, so that cmmwb build regenerates the "
                    "workbook for the new task. Point-cloud and feature points go to TASK_points.csv "
                    "beside the task file. Nothing is written unless the whole workbook reads.",
                    ("cmmwb read filled_in.xlsx --out gauge2.toml && cmmwb build gauge2.toml --out gauge2",
                     "cmmwb read workbook_templates/pointcloud_template.xlsx --out mine.toml --force"))
    s.add_argument("book", metavar="BOOK.xlsx",
                   help="the .xlsx workbook (written by cmmwb build, possibly edited; not .xlsm)")
    s.add_argument("--out", required=True, metavar="TASK.toml", help="task file to write (TOML)")
    s.add_argument("--force", action="store_true", help="overwrite existing files (default: refuse)")
    s.set_defaults(func=cmd_read)


def read_to_files(book: Path, out: Path, *, force: bool = False) -> list[Path]:
    """Read ``book`` and write the task file ``out`` (and its points table); return the paths."""
    from .reader import read_workbook, task_text, validate

    book, out = Path(book), Path(out)
    if not book.exists():
        raise InputError("no such file", file=book)
    if out.suffix.lower() != ".toml":
        raise InputError("the task file must end in .toml", file=out)
    rt = read_workbook(book, points_file=f"{out.stem}_points.csv")
    validate(rt, book, out.name)
    targets = {out: task_text(rt, book), **{out.parent / n: t for n, t in rt.files.items()}}
    if not force:
        for path in targets:
            if path.exists():
                raise InputError("exists already (use --force to overwrite)", file=path)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"cannot create the folder: {e.strerror}", file=out.parent) from None
    staged = []
    try:
        for path, text in targets.items():
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            staged.append((tmp, path))
            with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
                fh.write(text)
            os.chmod(tmp, 0o644)  # as every other output (generator.workbook.atomic)
        # the points table first: a task file never refers to a table that is not there
        for tmp, path in sorted(staged, key=lambda t: t[1] == out):
            os.replace(tmp, path)
    except OSError as e:
        raise InputError(f"cannot write: {e.strerror}", file=out) from None
    finally:
        for tmp, _ in staged:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return list(targets)


def cmd_read(args) -> int:
    for path in read_to_files(Path(args.book), Path(args.out), force=args.force):
        print(path)
    return 0
