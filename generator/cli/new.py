"""``cmmwb new KIND --out TASK.toml``: a commented task file of a kind that builds as it is
(the kind's ``NEW_TASK``, and the tables of ``NEW_TASK_FILES`` beside it)."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..jobs import job
from ..taskfile import KINDS
from ..workbook.atomic import write_text
from .common import add_command


def register(sub) -> None:
    s = add_command(sub, "new", "write a commented task file to start from",
                    "Writes a commented task file of the given kind that builds as it is; a point-cloud "
                    "task comes with its points table TASK_points.csv beside it.",
                    ("cmmwb new pointcloud --out gauge.toml   # also writes gauge_points.csv",
                     "cmmwb new budget --out knuckle.toml", "cmmwb new feature --out bore.toml",
                     "cmmwb new characteristic --out plate.toml   # also writes plate_points.csv",
                     "cmmwb import results.qif --stand-in --out plate.toml   # a characteristic task from a QIF "
                     "file's characteristics (docs/import.md)"))
    s.add_argument("kind", choices=KINDS, help="task kind: " + ", ".join(KINDS))
    s.add_argument("--out", required=True, metavar="TASK.toml", help="task file to write")
    s.add_argument("--force", action="store_true",
                   help="overwrite an existing task file (default: refuse); an existing points table is kept")
    s.set_defaults(func=run)


def run(args) -> int:
    out = Path(args.out)
    if out.exists() and not args.force:
        raise InputError("exists already (use --force to overwrite)", file=out)
    text, extras = new_task(args.kind, out.stem)
    for fname, content in extras.items():
        extra = out.parent / fname
        if extra.exists():
            print(f"{extra} exists already: kept as it is")
            continue
        write_text(extra, content)
        print(extra)
    write_text(out, text)  # after its points table: a task never names a file that is not there
    print(out)
    return 0


def new_task(kind: str, stem: str) -> tuple[str, dict[str, str]]:
    """The starter task of ``kind`` for a task file named ``stem``.toml, and the files it needs
    beside it, named after the task (``points.csv`` -> ``<stem>_points.csv``)."""
    mod = job(kind)
    text, extras = mod.NEW_TASK, {}
    for fname, content in mod.NEW_TASK_FILES.items():
        mine = f"{stem}_{fname}"
        text = text.replace(f'file = "{fname}"', f'file = "{mine}"')
        extras[mine] = content
    return text, extras
