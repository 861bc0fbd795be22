"""``cmmwb read``: a workbook a person filled in (in Excel or LibreOffice) back into a task file,
using the hidden sheet ``_task`` every built workbook carries for it
(:mod:`generator.workbook.tasksheet`).

What comes from where:

* the structure (kind, name, notes, distances, characteristics, datum system, feature options,
  sampling ...) from the hidden sheet ``_task`` that ``cmmwb build`` writes (``Book.task_info``):
  the task file the workbook was built from, as JSON, and a snapshot of every input cell;
* every value from the workbook: scalar inputs by their workbook-level defined names (= the task
  keys: ``sigma_R_um``, ``A_um``, ``probe1_px_mm``, ``S4_x_mm`` ...), tables (points, probes,
  weights, planning values) row by row until the first empty row, so rows added at the end of a
  table are read too.

Every cell is checked: a number where a number belongs (not text, not a formula, not a date,
finite, inside the cell's data validation range), text or a number where a label belongs, no
merged cells in the input area.  A problem is an :class:`InputError` naming the workbook, sheet
and cell.  The task is then validated by the kind's own ``load`` before anything is written, and
its messages are traced back to the sheet and cell the value came from.

openpyxl stores numbers with 16 significant digits and LibreOffice with 15; a value that still
equals the build-time value to those digits is given back at full precision (the snapshot), so
build -> read -> build is the identity, also through a LibreOffice save.
"""

from __future__ import annotations

import copy
import json
import re
import tempfile
import tomllib
from pathlib import Path

from . import __version__
from .decision import read_back as read_decision
from .errors import InputError, model_errors_named
from .jobs import job
from .taskfile import KINDS
from .workbook.atomic import write_texts
from .workbook.readback import Cells, ReadTask
from .workbook.tasksheet import TASK_INFO_FORMAT, TASK_SHEET

#: the sheets `read` takes values from (the others are not even loaded)
INPUT_SHEETS = {"Instructions", "Inputs", "Points", "Local", "Planning", "Characteristics", "Decision", TASK_SHEET}


# -- reading the task information -------------------------------------------------------------------

def task_info(cells: Cells) -> dict:
    """The JSON stored on the hidden ``_task`` sheet (see ``Book.task_info``)."""
    path = cells.path
    if TASK_SHEET not in cells.wb.sheetnames:
        raise InputError(f"no hidden sheet {TASK_SHEET!r}: not a workbook written by cmmwb (cmmwb read "
                         "needs a workbook from cmmwb build or workbook_templates/)", file=path,
                         where=f"sheet {TASK_SHEET}")
    ws = cells.wb[TASK_SHEET]
    parts = []
    row = 2
    while row <= ws.max_row:
        v = ws.cell(row=row, column=1).value
        if v is None:
            break
        parts.append(str(v))
        row += 1
    try:
        info = json.loads("".join(parts))
        if not isinstance(info, dict):
            raise ValueError
    except (ValueError, RecursionError):
        raise InputError("the task information is damaged (not the JSON cmmwb wrote)", file=path,
                         where=f"sheet {TASK_SHEET}") from None
    if info.get("format") != TASK_INFO_FORMAT:
        raise InputError(f"task information of format {info.get('format')!r}; this cmmwb reads format "
                         f"{TASK_INFO_FORMAT}", file=path, where=f"sheet {TASK_SHEET}")
    kind = info.get("kind")
    if kind not in KINDS:
        raise InputError(f"unknown task kind {kind!r}", file=path, where=f"sheet {TASK_SHEET}")
    if not isinstance(info.get("doc"), dict) or not isinstance(info.get("name"), str):
        raise InputError("the task information is damaged (no task)", file=path, where=f"sheet {TASK_SHEET}")
    snap = info.get("inputs")
    info["inputs"] = {k: v for k, v in snap.items() if isinstance(v, (int, float))} \
        if isinstance(snap, dict) else {}
    return info


# -- reading ---------------------------------------------------------------------------------------

def read_workbook(path: Path, points_file: str = "points.csv") -> ReadTask:
    """Read a workbook; ``points_file`` names the points table the task will refer to."""
    from .workbook.safe_xlsx import load

    path = Path(path)
    wb = load(path, INPUT_SHEETS)
    cells = Cells(path, wb, {})
    info = task_info(cells)
    cells.snapshot = info["inputs"]
    kind = info["kind"]
    rt = ReadTask(kind, info["name"], copy.deepcopy(info["doc"]))
    job(kind).read_book(cells, rt, points_file)
    read_decision(cells, rt)
    return rt


# -- validation and writing -------------------------------------------------------------------------

def validate(rt: ReadTask, book: Path, toml_name: str = "task.toml") -> None:
    """Load and compute the task as ``cmmwb build`` would (so that what ``read`` writes builds);
    messages point back to the workbook's cells."""
    import warnings

    import tomli_w

    mod = job(rt.kind)
    with tempfile.TemporaryDirectory(prefix="cmmwb_read_") as tmp:
        tmp = Path(tmp)
        for name, text in rt.files.items():
            (tmp / name).write_text(text, encoding="utf-8")
        toml = tmp / toml_name
        try:
            text = tomli_w.dumps(rt.doc)
        except (TypeError, ValueError, RecursionError) as e:
            raise InputError(f"the task information is damaged ({type(e).__name__})", file=book,
                             where=f"sheet {TASK_SHEET}") from None
        toml.write_text(text, encoding="utf-8")
        with model_errors_named(file=book):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)
                    mod.compute(mod.load(toml, tomllib.loads(text)))
            except InputError as e:
                raise _traced(e, rt, book, tmp) from None


def _traced(e: InputError, rt: ReadTask, book: Path, tmp: Path) -> InputError:
    where = e.where or ""
    if e.file and Path(e.file).parent == tmp and Path(e.file).suffix.lower() == ".csv":
        m = re.match(r"line ([0-9]+)(.*)$", where)
        if m and int(m.group(1)) in rt.csv_rows:
            return InputError(e.message, file=book, where=rt.csv_rows[int(m.group(1))] + m.group(2))
        return InputError(e.message, file=book, where="sheet Points")
    src = rt.sources.get(where)
    if src is None:
        for key in sorted(rt.sources, key=len, reverse=True):
            if where.startswith(key):
                src = rt.sources[key]
                break
    loc = f"{src} ({where})" if src else (f"{where} (as read from the workbook)" if where else None)
    return InputError(e.message, file=book, where=loc)


def read_to_files(book: Path, out: Path, *, force: bool = False) -> list[Path]:
    """Read ``book`` and write the task file ``out`` (and its points table); return the paths."""
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
    try:
        # the points table first: a task file never refers to a table that is not there
        write_texts(dict(sorted(targets.items(), key=lambda t: t[0] == out)))
    except OSError as e:
        raise InputError(f"cannot write: {e.strerror}", file=out) from None
    return list(targets)


def task_text(rt: ReadTask, book: Path) -> str:
    """The task file: a short header and the TOML."""
    import tomli_w

    head = (f"# cmmwb {__version__}: task read from {Path(book).name} (kind {rt.kind!r}).\n"
            "# Build with:  cmmwb build THIS.toml --out DIR\n\n")
    return head + _ARRAY.sub(_one_line, tomli_w.dumps(rt.doc))


_ARRAY = re.compile(r"\[\n((?:    [^\n\[\]{}]*,\n)+)\]")


def _one_line(m: re.Match) -> str:
    """Short arrays of scalars on one line: ``[0.0, 0.0, -20.0]``."""
    items = [line.strip()[:-1] for line in m.group(1).splitlines()]
    text = "[" + ", ".join(items) + "]"
    return text if len(text) <= 100 else m.group(0)
