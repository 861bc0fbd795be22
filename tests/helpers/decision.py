"""Conformity decisions in the built outputs: build a task (optionally edited), address the
Decision table by column name, and compare every cached Decision/Summary formula value with what an
engine recomputes (relative 1e-9, text exactly)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import openpyxl
import tomli_w
from openpyxl.utils import get_column_letter

from cmmwb.generator import decision
from cmmwb.generator.build import build_task

from tests.helpers import close, recalc


def build(tmp: Path, source: Path, edit=None, name: str | None = None):
    """Build ``source`` (a task file, optionally edited as a dict) into ``tmp``; (results, book)."""
    doc = tomllib.loads(source.read_text(encoding="utf-8"))
    if edit is not None:
        edit(doc)
    task = tmp / (name or source.name)
    for f in source.parent.glob("*.csv"):
        (tmp / f.name).write_bytes(f.read_bytes())
    task.write_text(tomli_w.dumps(doc), encoding="utf-8")
    results, files = build_task(task, tmp / "out", plots=False)
    return results, next(f for f in files if f.suffix == ".xlsx")


def at(row: int, name: str) -> str:
    """The coordinate of a Decision-table cell by its column name."""
    return f"{get_column_letter(decision.column(name))}{row}"


def cached(book: Path, sheets=("Decision", "Summary")) -> dict[str, dict[str, object]]:
    wb = openpyxl.load_workbook(book, data_only=True)
    wf = openpyxl.load_workbook(book)
    out = {}
    for s in sheets:
        out[s] = {c.coordinate: c.value for row in wb[s].iter_rows() for c in row
                  if c.value is not None and wf[s][c.coordinate].data_type == "f"}
    return out


def assert_engine_agrees(book: Path, engine: str) -> int:
    values = recalc(book, engine)
    n = 0
    for sheet, cells in cached(book).items():
        assert cells, f"{sheet}: no cached formula values"
        for coord, want in cells.items():
            got = values[sheet].get(coord)
            if isinstance(want, (int, float)):
                assert close(got, want, rel=1e-9), f"{engine} {sheet}!{coord}: {got!r} != {want!r}"
            else:
                assert got == want, f"{engine} {sheet}!{coord}: {got!r} != {want!r}"
            n += 1
    return n
