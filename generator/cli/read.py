"""``cmmwb read BOOK.xlsx --out TASK.toml``: a filled-in workbook back into a task file.

Writes TASK.toml and, for point-cloud and feature tasks with a points table, ``<TASK>_points.csv``
beside it.  Nothing is written unless the whole workbook reads and the task validates; existing
files are kept unless ``--force``.  See :mod:`generator.reader` for what is read from where
(:func:`generator.reader.read_to_files`).
"""

from __future__ import annotations

from pathlib import Path

from ..reader import read_to_files
from .common import add_command


def register(sub) -> None:
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
    s.set_defaults(func=run)


def run(args) -> int:
    for path in read_to_files(Path(args.book), Path(args.out), force=args.force):
        print(path)
    return 0
