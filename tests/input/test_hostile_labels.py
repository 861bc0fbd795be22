"""No text of a task reaches a formula string (issue 33, first family; issue 32's Summary and
Decision sheets): a user names a characteristic `dia "H1"`, a point `=HYPERLINK("http://x")`, a
lab `+cmd|' /C calc'!A0`. Every kind is built with such labels wherever its task takes free text
(point ids, characteristic and feature names, `[report]` fields); LibreOffice recalculates each
book with no error value in any cell, the labels stand in their cells as text, and `cmmwb read`
gives the same task back."""

from __future__ import annotations

import csv
import io
import tomllib
from pathlib import Path

import openpyxl
import pytest
import tomli_w

from cmmwb.generator.build import build_task
from cmmwb.generator.jobs import job
from cmmwb.generator.reader import read_to_files
from cmmwb.generator.workbook.cache import ERRORS
from cmmwb.generator.workbook.recalc import recalculate, soffice

from tests.helpers import EXAMPLES

#: the texts a spreadsheet would take for a formula, a DDE call, or a broken string literal
HOSTILE = ['=HYPERLINK("http://x")', "@SUM(1+1)", "+cmd|' /C calc'!A0", 'dia "H1"', "-2+3"]
REPORT = {"lab": "=1+1", "operator": "@me", "cmm": "+cmd|' /C calc'!A0", "artefact": 'part "7"',
          "job_id": "-1", "notes": ['=HYPERLINK("x")', 'say "hi"']}


def _points_csv(rows: list[dict]) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["id", "x", "y", "z", "nx", "ny", "nz", "probe"])
    for r in rows:
        w.writerow([r["id"], r["x"], r["y"], r["z"], r["nx"], r["ny"], r["nz"], r["probe"]])
    return out.getvalue()


def _read_csv(text: str) -> list[dict]:
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    return list(csv.DictReader(lines))


def pointcloud_task(tmp: Path) -> Path:
    """`cmmwb new pointcloud`'s gauge blocks with hostile point ids, a tolerance on a distance
    between two of them, and hostile report fields."""
    mod = job("pointcloud")
    doc = tomllib.loads(mod.NEW_TASK)
    rows = _read_csv(mod.NEW_TASK_FILES["points.csv"])
    for r, new in zip(rows, HOSTILE):
        r["id"] = new
    (tmp / "points.csv").write_text(_points_csv(rows), encoding="utf-8")
    doc["distances"] = [{"from": rows[0]["id"], "to": rows[1]["id"], "group": HOSTILE[2]},
                        {"from": rows[2]["id"], "to": rows[3]["id"], "group": HOSTILE[3]}]
    doc["decision"] = {"rule": "guarded_rejection", "r": 0.5,
                       "tolerances": [{"from": rows[0]["id"], "to": rows[1]["id"], "tol_mm": 0.002}]}
    doc["report"] = REPORT
    task = tmp / "hostile_pointcloud.toml"
    task.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return task


def feature_task(tmp: Path) -> Path:
    """The measured plane face with hostile ids on some of its points."""
    src = EXAMPLES / "feature_plane_face.toml"
    doc = tomllib.loads(src.read_text(encoding="utf-8"))
    text = (EXAMPLES / doc["points"]["file"]).read_text(encoding="utf-8")
    rows = _read_csv(text)
    for r, new in zip(rows, HOSTILE):
        r["id"] = new
    (tmp / "face.csv").write_text(_points_csv(rows), encoding="utf-8")
    doc["points"]["file"] = "face.csv"
    doc["report"] = REPORT
    doc["feature"].pop("weights", None)
    task = tmp / "hostile_feature.toml"
    task.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return task


def characteristic_task(tmp: Path) -> Path:
    """`cmmwb new characteristic` with hostile feature, frame and characteristic names."""
    mod = job("characteristic")
    doc = tomllib.loads(mod.NEW_TASK)
    (tmp / "points.csv").write_text(mod.NEW_TASK_FILES["points.csv"], encoding="utf-8")
    names = {"A": HOSTILE[0], "B": HOSTILE[3]}
    for f in doc["features"]:
        f["name"] = names[f["name"]]
    for fr in doc["frames"]:
        fr["name"] = HOSTILE[2]
        fr["primary"], fr["secondary"] = names[fr["primary"]], names[fr["secondary"]]
    for c, new in zip(doc["characteristics"], (HOSTILE[1], HOSTILE[3])):
        c["name"] = new
        c["features"] = [names[f] for f in c["features"]]
        if "frame" in c:
            c["frame"] = HOSTILE[2]
    doc["report"] = REPORT
    task = tmp / "hostile_characteristic.toml"
    task.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return task


def budget_task(tmp: Path) -> Path:
    """The knuckle (its names are identifiers by the task's rules) with hostile report fields."""
    doc = tomllib.loads((EXAMPLES / "knuckle.toml").read_text(encoding="utf-8"))
    doc["report"] = REPORT
    task = tmp / "hostile_budget.toml"
    task.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return task


TASKS = {"pointcloud": pointcloud_task, "budget": budget_task, "feature": feature_task,
         "characteristic": characteristic_task}


@pytest.fixture(scope="module", params=sorted(TASKS))
def built(request, tmp_path_factory):
    tmp = tmp_path_factory.mktemp(request.param)
    task = TASKS[request.param](tmp)
    results, files = build_task(task, tmp / "out", plots=False)
    return request.param, task, results, next(f for f in files if f.suffix == ".xlsx")


def _errors(values: dict) -> list[str]:
    return [f"{sheet}!{coord}: {v}" for sheet, cells in values.items() for coord, v in cells.items()
            if isinstance(v, str) and (v in ERRORS or v.startswith("Err:"))]


def test_the_labels_stand_in_their_cells_as_text(built):
    """Every hostile text that is in the book is a text cell (never a formula), on the Summary
    too (its statements refer to the cell holding the label)."""
    kind, task, results, book = built
    wb = openpyxl.load_workbook(book)
    texts = {c.value for ws in wb.worksheets for row in ws.iter_rows() for c in row
             if isinstance(c.value, str) and c.data_type == "s"}
    formulas = [c.value for ws in wb.worksheets for row in ws.iter_rows() for c in row if c.data_type == "f"]
    for h in [*HOSTILE, *[v for v in REPORT.values() if isinstance(v, str)]]:
        if any(ch.isalpha() for ch in h):         # "-1" is in many a formula, as a number
            assert not any(h in f for f in formulas), (kind, h)
    assert "=1+1" in texts and 'part "7"' in texts                 # the report fields on the Summary
    if kind != "budget":
        assert any(h in t for h in HOSTILE for t in texts if t != "@me")


@pytest.mark.libreoffice
def test_libreoffice_recalculates_with_no_error_cell(built):
    if soffice() is None:
        pytest.skip("needs LibreOffice")
    kind, task, results, book = built
    assert not _errors(recalculate(book, "libreoffice")), kind


def test_the_formulas_engine_recalculates_with_no_error_cell(built):
    kind, task, results, book = built
    assert not _errors(recalculate(book, "formulas")), kind


def test_read_gives_the_same_task_back(built, tmp_path):
    kind, task, results, book = built
    out = tmp_path / "back.toml"
    files = read_to_files(book, out)
    doc = tomllib.loads(out.read_text(encoding="utf-8"))
    original = tomllib.loads(task.read_text(encoding="utf-8"))
    assert doc["report"] == original["report"]
    for key in ("features", "frames", "characteristics", "distances", "decision"):
        if key in original:
            assert doc[key] == original[key], key
    if "file" in original.get("points", {}):
        want = [r["id"] for r in _read_csv((task.parent / original["points"]["file"]).read_text("utf-8"))]
        if "rows" in doc["points"]:            # a few points: in the task file
            ids = [r["id"] for r in doc["points"]["rows"]]
        else:
            back = next(f for f in files if f.suffix == ".csv")
            ids = [r["id"] for r in _read_csv(back.read_text(encoding="utf-8"))]
        assert ids == want
    # and it builds to the same results
    again, _ = build_task(out, tmp_path / "again", plots=False)
    assert again["statements"] == results["statements"]
