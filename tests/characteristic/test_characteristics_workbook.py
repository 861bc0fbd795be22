"""The `characteristic` workbook (the plate example): Results recalculated by `formulas` and by
LibreOffice agree with the JSON to 1e-9; u of the smooth characteristics is a live MMULT of the
sensitivity row and the joint V_A; the bonus, zone and margin of a position follow the size."""

import json

import openpyxl
import pytest

from cmmwb.generator.build import build_task
from cmmwb.generator.workbook.recalc import results_rows

from tests.helpers import ENGINES, EXAMPLES, REL, close, recalc

KEYS = ("value", "u", "tolerance_mm", "bonus_mm", "zone_mm", "margin_mm", "u_margin_um")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("plate")
    results, files = build_task(EXAMPLES / "characteristic_plate.toml", out, plots=False)
    book = next(f for f in files if f.suffix == ".xlsx")
    return results, book


@pytest.mark.parametrize("engine", ENGINES)
def test_results_agree_with_the_json(built, engine):
    results, book = built
    values = recalc(book, engine)
    errors = [(s, c, v) for s, cells in values.items() for c, v in cells.items()
              if isinstance(v, str) and v.startswith("#")]
    assert not errors, errors[:3]
    rows = results_rows(values)
    chars = results["characteristics"]
    assert [r["name"] for r in rows] == [c["name"] for c in chars]
    for r, c in zip(rows, chars):
        for k in ("value", "u"):
            assert close(float(r[k]), float(c[k]), rel=REL), (engine, c["name"], k, r[k], c[k])
    # tolerance, bonus, zone, margin and its u on 'Characteristics'
    cells = values["Characteristics"]
    checked = 0
    for row, c in enumerate(chars, start=2):
        for col, k in zip("KMNOP", KEYS[2:]):
            if c[k] is None:
                continue
            got = cells[f"{col}{row}"]
            assert close(float(got), float(c[k]), rel=REL, floor=1e-15), (engine, c["name"], k, got)
            checked += 1
    assert checked == sum(c[k] is not None for c in chars for k in KEYS[2:]) >= 20


def test_smooth_u_is_a_live_formula_and_form_u_is_a_noted_core_value(built):
    _, book = built
    ws = openpyxl.load_workbook(book)["Characteristics"]
    by_name = {ws.cell(row=r, column=1).value: r for r in range(2, ws.max_row + 1)}
    u_pos = ws.cell(row=by_name["pos_H1_MMC"], column=6).value
    assert "MMULT" in u_pos.text and "V_A" in u_pos.text
    form = ws.cell(row=by_name["flat_A_MZ"], column=6)
    assert isinstance(form.value, float) and "active-set" in form.comment.text
    assert ws.cell(row=by_name["pos_H1_MMC"], column=13).value.startswith("=MAX(0,")


@pytest.mark.parametrize("engine", ENGINES)
def test_the_bonus_follows_the_size_limit(built, tmp_path, engine):
    """Raising the hole's lower size limit (its MMC size) by 0.01 mm takes 0.01 mm off the bonus,
    the zone and the margin of its position at MMC."""
    results, book = built
    wb = openpyxl.load_workbook(book)
    ws = wb["Characteristics"]
    by_name = {ws.cell(row=r, column=1).value: r for r in range(2, ws.max_row + 1)}
    ws.cell(row=by_name["dia_H1"], column=9).value = 10.01
    edited = tmp_path / "edited.xlsx"
    wb.save(edited)
    cells = recalc(edited, engine)["Characteristics"]
    ref = {c["name"]: c for c in results["characteristics"]}["pos_H1_MMC"]
    r = by_name["pos_H1_MMC"]
    assert cells[f"M{r}"] == pytest.approx(ref["bonus_mm"] - 0.01, abs=1e-12)
    assert cells[f"N{r}"] == pytest.approx(ref["zone_mm"] - 0.01, abs=1e-12)
    assert cells[f"O{r}"] == pytest.approx(ref["margin_mm"] - 0.01, abs=1e-12)


def test_the_json_carries_tolerances_for_the_decision_rules(built):
    results, _ = built
    c = {c["name"]: c for c in results["characteristics"]}
    assert c["dia_H1"]["lsl"] == 10.0 and c["dia_H1"]["usl"] == 10.05
    assert c["flat_A_MZ"]["tolerance_mm"] == 0.01 and c["flat_A_MZ"]["method"] == "MZ"
    p = c["pos_H1_MMC"]
    assert p["material_condition"] == "MMC" and p["zone_mm"] == pytest.approx(0.05 + p["bonus_mm"])
    json.dumps(results)


@pytest.mark.parametrize("edit, message", [
    (('features = ["H1"]\ntolerance_mm = 0.009', 'features = ["H9"]\ntolerance_mm = 0.009'),
     "unknown feature 'H9'"),
    (('type = "flatness"', 'type = "wobble"'), "unknown type 'wobble'"),
    (('id_prefix = "A."', 'id_prefix = "Q."'), "no point id starts with 'Q.'"),
    (('tolerance_mm = 0.05', 'tolerance_mm = "wide"'), "must be a number"),
])
def test_bad_tasks_are_input_errors_that_name_the_problem(tmp_path, edit, message):
    from cmmwb.generator.errors import InputError

    src = (EXAMPLES / "characteristic_plate.toml").read_text(encoding="utf-8")
    assert edit[0] in src
    task = tmp_path / "plate.toml"
    task.write_text(src.replace(edit[0], edit[1], 1), encoding="utf-8")
    (tmp_path / "characteristic_plate.csv").write_text(
        (EXAMPLES / "characteristic_plate.csv").read_text(encoding="utf-8"), encoding="utf-8")
    with pytest.raises(InputError, match=message) as err:
        build_task(task, tmp_path / "out", plots=False)
    assert "plate.toml" in str(err.value)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_tolerance_typed_in_the_workbook_goes_back_to_the_task_file(built, tmp_path):
    """cmmwb read: the flatness tolerance typed on 'Characteristics' is in the task file read
    back, and that task builds with it (the zone, not the value, changes)."""
    import tomllib

    from cmmwb.generator.reader import read_to_files

    results, book = built
    wb = openpyxl.load_workbook(book)
    ws = wb["Characteristics"]
    row = next(r for r in range(2, ws.max_row + 1) if ws.cell(row=r, column=1).value == "flat_A_MZ")
    ws.cell(row=row, column=11).value = 0.02
    edited = tmp_path / "edited.xlsx"
    wb.save(edited)
    files = read_to_files(edited, tmp_path / "back" / "task.toml")
    doc = tomllib.loads(files[0].read_text(encoding="utf-8"))
    c = next(c for c in doc["characteristics"] if c["name"] == "flat_A_MZ")
    assert c["tolerance_mm"] == 0.02 and c["method"] == "MZ"
    again, _ = build_task(files[0], tmp_path / "again", plots=False)
    ref = {c["name"]: c for c in results["characteristics"]}["flat_A_MZ"]
    new = {c["name"]: c for c in again["characteristics"]}["flat_A_MZ"]
    assert new["tolerance_mm"] == 0.02 and new["value"] == ref["value"] and new["u"] == ref["u"]
