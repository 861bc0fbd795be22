"""The workbook templates (workbook_templates/): current with the generator, made for people
(instructions first, yellow validated input cells with names, protected formulas) and readable
without a spreadsheet program (cached Results values equal to the JSON)."""

from __future__ import annotations

import json

import openpyxl
import pytest
from openpyxl.worksheet.formula import ArrayFormula

from cmmwb.generator import templates
from cmmwb.generator.jobs import job
from cmmwb.generator.reader import TASK_SHEET
from cmmwb.generator.workbook.recalc import read_cached, results_rows
from cmmwb.generator.workbook.styles import DEFAULT_FILL, INPUT_FILL

from tests.helpers import results_table

SOURCES = templates.sources()


def expected_results(kind, source, tmp_path):
    """The JSON the core computes for a template's task (no workbook involved)."""
    from cmmwb.generator.taskfile import read_toml

    mod = job(kind)
    if source is None:
        source = tmp_path / "task.toml"
        source.write_text(mod.NEW_TASK, encoding="utf-8")
        for name, text in mod.NEW_TASK_FILES.items():
            (tmp_path / name).write_text(text, encoding="utf-8")
    return mod.compute(mod.load(source, read_toml(source)))


def test_every_kind_and_every_worked_example_has_a_template():
    names = set(SOURCES)
    assert {"pointcloud_template.xlsx", "budget_template.xlsx", "feature_template.xlsx"} <= names
    assert {"examples/stepgauge_I_MPE1.xlsx", "examples/knuckle.xlsx",
            "examples/feature_table1_circle_arc.xlsx"} <= names
    for name in names:
        assert (templates.TEMPLATE_DIR / name).exists(), f"missing {name}: run python -m generator.templates"


def test_templates_are_current_with_the_generator():
    """Regenerated and compared in content (formulas, text, styles, names, validations, print
    setup; numbers to relative 1e-9, see generator.templates.differences), so that another CPU's
    BLAS kernel does not make them stale; if this fails after a change of a writer, run
    `python -m generator.templates` and commit the templates with the change."""
    assert templates.stale() == []


def test_the_content_comparison_sees_a_changed_number_and_ignores_rounding(tmp_path):
    """A change in the 10th digit is a difference; one in the 16th (another summation order) is not."""
    src = templates.TEMPLATE_DIR / "examples" / "stepgauge_I_MPE1.xlsx"
    wb = openpyxl.load_workbook(src)
    base = tmp_path / "base.xlsx"                      # saved by openpyxl too: no cached values in either
    wb.save(base)
    ws = wb["Inputs"]
    cell = max((c for r in ws.iter_rows() for c in r                 # the sheet's largest number: the
                if isinstance(c.value, (int, float)) and not isinstance(c.value, bool)),  # abs floor is
               key=lambda c: abs(c.value))                           # 1e-9 x the sheet's scale
    value = float(cell.value)
    for factor, differs in ((1 + 1e-8, True), (1 + 4e-16, False)):
        cell.value = value * factor
        edited = tmp_path / f"edited_{differs}.xlsx"
        wb.save(edited)
        found = templates.differences(base, edited)
        assert any(f"Inputs!{cell.coordinate}" in d for d in found) == differs, found
        assert all(d.startswith(f"Inputs!{cell.coordinate}:") for d in found), found


@pytest.mark.parametrize("name", sorted(SOURCES))
def test_a_template_is_made_for_people(name):
    path = templates.TEMPLATE_DIR / name
    wb = openpyxl.load_workbook(path)
    assert wb.sheetnames[0] == "Instructions"
    instructions = " ".join(str(c.value) for c in wb["Instructions"]["A"] if c.value)
    assert "yellow" in instructions and "cmmwb read" in instructions and "cmmwb build" in instructions
    assert wb[TASK_SHEET].sheet_state == "hidden"
    named = set()
    for dn in wb.defined_names.values():
        for sheet, ref in dn.destinations:
            ws = wb[sheet]
            for row in ws[ref.replace("$", "")] if ":" in ref else [[ws[ref.replace("$", "")]]]:
                for c in row:
                    named.add((sheet, c.coordinate))
    inputs = formulas = 0
    for ws in wb.worksheets:
        validated = [dv for dv in ws.data_validations.dataValidation if dv.type == "decimal"]
        for row in ws.iter_rows():
            for c in row:
                if c.protection.locked is False:        # an input cell
                    inputs += 1
                    where = f"{ws.title}!{c.coordinate}"
                    # a number, or a per-probe default (=sigma_PQ_um) a number may replace
                    assert isinstance(c.value, (int, float)) or str(c.value).startswith("="), where
                    # yellow; green for an input that inherits a default by formula (issue 11)
                    fill = DEFAULT_FILL if str(c.value).startswith("=") else INPUT_FILL
                    assert c.fill.fgColor.rgb.endswith(fill.fgColor.rgb[-6:]), where
                    if fill is DEFAULT_FILL:
                        assert c.comment is not None and "inherits" in c.comment.text, where
                    assert any(c.coordinate in dv.sqref for dv in validated), f"{where} not validated"
                    assert (ws.title, c.coordinate) in named, f"{where} has no defined name"
                if isinstance(c.value, ArrayFormula) or c.data_type == "f":
                    formulas += 1
        if any(c.data_type == "f" or isinstance(c.value, ArrayFormula) for r in ws.iter_rows() for c in r):
            # formulas are protected against overwriting, without a password
            assert ws.protection.sheet and not ws.protection.password, ws.title
    assert inputs > 0 and formulas > 0


@pytest.mark.parametrize("name", sorted(SOURCES))
def test_a_template_shows_its_results_without_calculating(tmp_path, name):
    """openpyxl data_only=True (what previewers and pandas see): every Results value is there
    and equals the JSON of the core."""
    kind, source = SOURCES[name]
    results = expected_results(kind, source, tmp_path)
    wb = openpyxl.load_workbook(templates.TEMPLATE_DIR / name, data_only=True)
    rows = results_rows({"Results": {c.coordinate: c.value for r in wb["Results"].iter_rows()
                                     for c in r if c.value is not None}})
    expected = results_table(kind, results)
    # the contract's columns (a book may add columns to the right, e.g. the feature books' unit)
    assert len(rows) == len(expected) > 0 and all(v is not None for r in rows for v in r.values())
    # the template was made on some CPU, the JSON here on this one: numbers agree to 1e-9 of the
    # column's largest value (an exactly-zero value is 0 on one BLAS kernel and 1e-15 on another)
    for key in expected[0]:
        col = [r[key] for r in expected]
        got = [r[key] for r in rows]
        # text entries exactly (labels; the feature books' '—' where u_um or u_urad does not apply)
        assert [g for g, v in zip(got, col) if isinstance(v, str)] == [v for v in col if isinstance(v, str)], key
        numbers = [(g, v) for g, v in zip(got, col) if not isinstance(v, str)]
        if numbers:
            scale = max(abs(v) for _, v in numbers)
            assert [g for g, _ in numbers] == pytest.approx([v for _, v in numbers], rel=1e-9,
                                                            abs=1e-9 * scale), key


def test_pandas_style_reading_sees_numbers(tmp_path):
    """A program reading cached values only (as recalc.read_cached does) gets the same numbers."""
    values = read_cached(templates.TEMPLATE_DIR / "examples" / "stepgauge_I_MPE1.xlsx")
    rows = results_rows(values)
    results = expected_results("pointcloud", templates.EXAMPLES_DIR / "stepgauge_I_MPE1.toml", tmp_path)
    assert [r["U_um"] for r in rows] == pytest.approx([d["U_um"] for d in results["distances"]], rel=1e-9)
    # the Budget cells the Results point at carry the same values
    assert values["Budget"]["F2"] == pytest.approx(results["distances"][0]["U_um"], rel=1e-9)
    json.dumps(rows)  # plain Python values
