"""The ``budget`` workbook (Wojtyła/Płowucha 2023): live formulas that agree with the JSON.

The shipped steering-knuckle task is written by the job module, recalculated with `formulas`,
LibreOffice and Gnumeric, and every budget cell (x_i, dl/dx_i, u_i, contribution, l, u_c, U, of the
chosen and of every other variant, and each position's combination) is compared with the Python
core at relative 1e-9 (absolute 1e-12 for quantities that are zero).  Then a user's edit is
replayed: a coordinate, A_um and a TED changed with openpyxl, recalculated, compared with
``compute`` on the edited task.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import openpyxl
import pytest

from cmmwb.generator.budget import book as budget_book
from cmmwb.generator.budget import job as budget_job
from cmmwb.generator.errors import InputError
from cmmwb.generator.workbook.recalc import results_rows

from tests.helpers import ENGINES, close, recalc
from tests.helpers.budget import (
    TABLE9,
    TABLES,
    assert_printed,
    numerical_gradient,
    reference_value,
)

KNUCKLE = Path(budget_job.__file__).parents[1] / "examples" / "knuckle.toml"

def knuckle_doc() -> dict:
    return tomllib.loads(KNUCKLE.read_text(encoding="utf-8"))


def build(doc: dict, path: Path):
    task = budget_job.load(KNUCKLE, doc)
    results = budget_job.compute(task)
    layout = budget_book.write(task, budget_job.evaluate(task), path)
    return task, results, layout


def budget_pairs(values, results: dict, layout: dict):
    """(what, workbook value, JSON value) for every compared cell."""
    out = []

    def rows(sheet, where, cells, json_rows):
        assert [c["input"] for c in cells] == [r["input"] for r in json_rows], where
        for c, r in zip(cells, json_rows):
            for key, json_key in (("value", "value_mm"), ("sensitivity", "sensitivity"),
                                  ("u", "u_um"), ("contribution", "contribution_um")):
                out.append((f"{sheet}!{c[key]} {where} {r['input']} {json_key}",
                            values[sheet].get(c[key]), r[json_key]))

    def thermal(sheet, where, cells, json_rows):
        assert len(cells) == len(json_rows), where
        for c, r in zip(cells, json_rows):
            for key, json_key in (("value", "value"), ("sensitivity", "sensitivity"), ("u", "u"),
                                  ("contribution", "contribution_um")):
                out.append((f"{sheet}!{c[key]} {where} {r['input']} {json_key}",
                            values[sheet].get(c[key]), r[json_key]))

    def distance(cc, entry, where):
        for v in entry["variants"]:
            bc = cc.variants[v["variant"]]
            rows(bc.sheet, f"{where} [{v['variant']}]", bc.rows, v["rows"])
            thermal(bc.sheet, f"{where} [{v['variant']}] W", bc.thermal, v.get("workpiece_rows", []))
            for key, json_key in (("value", "value_mm"), ("u", "u_um"), ("U", "U_um")):
                out.append((f"{bc.sheet}!{getattr(bc, key)} {where} [{v['variant']}] {json_key}",
                            values[bc.sheet].get(getattr(bc, key)), v[json_key]))
        assert cc.chosen.label == entry["variant"]

    for ch in results["characteristics"]:
        cc = layout[ch["name"]]
        for key, json_key in (("value", "value_mm"), ("u", "u_um"), ("U", "U_um")):
            out.append((f"{cc.sheet}!{getattr(cc, key)} {ch['name']} {json_key}",
                        values[cc.sheet].get(getattr(cc, key)), ch[json_key]))
        if ch["model"] == "position":
            rows(cc.sheet, ch["name"], cc.rows, ch["rows"])
            for dcc, d in zip(cc.distances, ch["distances"]):
                distance(dcc, d, f"{ch['name']} {d['name']}")
        else:
            distance(cc, ch, ch["name"])
    return out


def assert_workbook_matches(values, results, layout) -> int:
    errors = [(s, c, v) for s, cells in values.items() for c, v in cells.items()
              if isinstance(v, str) and v.startswith("#")]
    assert not errors, errors[:5]
    pairs = budget_pairs(values, results, layout)
    bad = [(w, a, b) for w, a, b in pairs if not close(a, b)]
    assert not bad, f"{len(bad)} of {len(pairs)} cells differ, e.g. {bad[:3]}"
    rows = results_rows(values)
    assert [r["name"] for r in rows] == [c["name"] for c in results["characteristics"]]
    for r, ch in zip(rows, results["characteristics"]):
        assert r["variant"] == ch["variant"]
        for key in ("value_mm", "u_um", "U_um"):
            assert close(r[key], ch[key]), (ch["name"], key, r[key], ch[key])
    return len(pairs)


@pytest.fixture(scope="module")
def knuckle(tmp_path_factory):
    path = tmp_path_factory.mktemp("budget") / "knuckle.xlsx"
    task, results, layout = build(knuckle_doc(), path)
    return path, task, results, layout


_recalculated: dict = {}


def knuckle_in(knuckle, engine: str) -> dict:
    """The knuckle workbook as ``engine`` recomputes it (once per engine and module)."""
    if engine not in _recalculated:
        _recalculated[engine] = recalc(knuckle[0], engine)
    return _recalculated[engine]


@pytest.fixture(scope="module")
def knuckle_formulas(knuckle):
    return knuckle_in(knuckle, "formulas")


@pytest.fixture(scope="module")
def knuckle_libreoffice(knuckle):
    return knuckle_in(knuckle, "libreoffice")


@pytest.fixture(scope="module")
def edited(tmp_path_factory, knuckle):
    """The user's edit: S4 moves (y 89 -> 90.5, z 63 -> 61.2), E moves (z 19 -> 20.5), the MPE
    becomes 2.5 + L/250 and the TED of S1 from the secondary datum 45.004.  The expected results
    come from ``compute`` on the same edit of the task file, with the variants the workbook shows
    (a rebuild with "auto" could pick others after an edit; the workbook flags that)."""
    path, task, results, layout = knuckle
    wb = openpyxl.load_workbook(path)
    edits = {"S4_y_mm": 90.5, "S4_z_mm": 61.2, "E_z_mm": 20.5, "A_um": 2.5,
             "S1_position_ted1_mm": 45.004}
    for name, value in edits.items():
        (sheet, coord), = wb.defined_names[name].destinations
        wb[sheet][coord.replace("$", "")].value = value
    out = path.with_name("knuckle_edited.xlsx")
    wb.save(out)

    doc = knuckle_doc()
    doc["points"]["S4"] = [0.01, 90.5, 61.2]
    doc["points"]["E"] = [0, -72, 20.5]
    doc["mpe"]["A_um"] = 2.5
    for entry, ch in zip(doc["characteristics"], results["characteristics"]):
        if entry["name"] == "S1_position":
            entry["ted_mm"] = [45.004, 26]
        if ch["model"] == "position":
            entry["variant"] = [d["variant"] for d in ch["distances"]]
        else:
            entry["variant"] = ch["variant"]
    etask = budget_job.load(KNUCKLE, doc)
    eresults = budget_job.compute(etask)
    assert eresults != results
    return out, eresults, layout


# ---------------------------------------------------------------------------------------------
# The shipped knuckle workbook in every engine
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("engine", ENGINES)
def test_every_engine_agrees_with_the_json(knuckle, engine):
    path, task, results, layout = knuckle
    n = assert_workbook_matches(knuckle_in(knuckle, engine), results, layout)
    assert n > 2000          # every cell of every variant's budget was compared


@pytest.mark.libreoffice
def test_tables_1_to_9_come_out_of_the_recalculated_workbook(knuckle, knuckle_libreoffice):
    """The paper's printed tables, read from the cells LibreOffice computed."""
    path, task, results, layout = knuckle
    values = knuckle_libreoffice
    by_point = {ch["point"]: (ch, layout[ch["name"]]) for ch in results["characteristics"]
                if ch["model"] == "position"}
    for table, (point, datum, variant, _, text, u_c) in TABLES.items():
        ch, cc = by_point[point]
        i = ch["datums"].index(datum)
        dcc = cc.distances[i]
        assert dcc.chosen.label == variant
        v = values[dcc.sheet]
        for c, line in zip(dcc.chosen.rows, text.strip().splitlines()):
            name, x, s, u, contrib = line.split()
            assert c["input"] == name
            assert_printed(v[c["value"]], x, min_decimals=2, what=f"Table {table} {name}")
            assert_printed(v[c["sensitivity"]], s, min_decimals=3, what=f"Table {table} {name}")
            assert_printed(v[c["u"]], u, what=f"Table {table} {name}")
            assert_printed(v[c["contribution"]], contrib, min_decimals=3,
                           what=f"Table {table} {name}")
        assert_printed(v[dcc.chosen.u], u_c, what=f"Table {table} u_c")
    for point, (u1, u2, upos) in TABLE9.items():
        ch, cc = by_point[point]
        v = values[cc.sheet]
        assert_printed(v[cc.rows[0]["u"]], u1)
        assert_printed(v[cc.rows[1]["u"]], u2)
        assert_printed(v[cc.u], upos)


def test_every_computed_cell_is_a_formula_of_the_named_inputs(knuckle):
    path, task, results, layout = knuckle
    wb = openpyxl.load_workbook(path)
    cc = layout["S4_position"]
    ws = wb[cc.sheet]
    chosen = cc.distances[0].chosen
    first = chosen.rows[0]
    assert ws[first["value"]].value == "=S4_x_mm-C_x_mm"            # x_CS4
    assert ws[first["u"]].value == f"=b*(A_um+ABS(${first['value'][0]}${first['value'][1:]})/B_mm)"
    for row in chosen.rows:
        for key in ("value", "sensitivity", "u", "contribution"):
            assert str(ws[row[key]].value).startswith("="), (row, key)
    for sheet in wb.sheetnames:
        for r in wb[sheet].iter_rows():
            for c in r:
                if isinstance(c.value, (int, float)) and not isinstance(c.value, bool):
                    # plain numbers only in the named input cells on Inputs
                    assert sheet == "Inputs", (sheet, c.coordinate, c.value)
    names = set(wb.defined_names)
    assert {"A_um", "B_mm", "b", "k", "S4_x_mm", "S4_position_ted2_mm"} <= names


def test_auto_choice_is_flagged_live(knuckle_formulas):
    """Each variant table says whether the chosen variant is still the lowest u_c."""
    values = knuckle_formulas
    flags = [v for cells in values.values() for v in cells.values() if v in ("yes", "no")]
    assert flags and set(flags) == {"yes"}
    assert len(flags) == 4 * 2 + 4      # 4 positions with 2 distances, 4 other characteristics


# ---------------------------------------------------------------------------------------------
# Randomized essential points: workbook sensitivities against numerical derivatives
# ---------------------------------------------------------------------------------------------


def random_task_doc(seed: int) -> dict:
    """Every model on random essential points in a 400 mm box and a random MPE."""
    import numpy as np

    rng = np.random.default_rng(seed)
    pts = {n: [round(float(v), 6) for v in rng.uniform(-200, 200, 3)]
           for n in ("A", "B", "C", "D", "E", "S", "T")}
    chars = [
        {"name": "pp", "model": "point_point", "from": "S", "to": "T"},
        {"name": "pl", "model": "point_line", "point": "S", "line": ["A", "B"]},
        {"name": "pn", "model": "point_plane", "point": "S", "plane": ["A", "B", "C"]},
        {"name": "ll", "model": "line_line", "line1": ["A", "B"], "line2": ["S", "T"]},
        {"name": "d2", "model": "datum_distance", "point": "T", "datum": "secondary"},
        {"name": "pos", "model": "position", "point": "S", "datums": ["secondary", "tertiary"],
         "ted_mm": [10.0, 20.0]},
    ]
    return {"task": {"kind": "budget", "name": f"random{seed}"},
            "mpe": {"A_um": round(float(rng.uniform(0.5, 5)), 3),
                    "B_mm": round(float(rng.uniform(100, 1000)), 1),
                    "b": round(float(rng.uniform(0.3, 0.7)), 3), "k": 2},
            "points": pts, "datum_system": {"primary": ["A", "B", "C"], "secondary": ["D", "E"]},
            "characteristics": chars}


def assert_sensitivities_are_derivatives(values, task, layout) -> int:
    """Every variant's dl/dx_i cells against five-point differences of the paper's equations
    (written independently in test_budget_core.reference_value), relative 1e-7."""
    import numpy as np

    n = 0
    for c, r in zip(task.characteristics, budget_job.evaluate(task)):
        cc = layout[c.name]
        dists = zip(cc.distances, r.distances) if c.model == "position" else [(cc, r)]
        for dcc, d in dists:
            for vb in d.variants:
                bc = dcc.variants[vb.label]
                v = values[bc.sheet]
                x = np.array([v[row["value"]] for row in bc.rows], dtype=float)
                s = np.array([v[row["sensitivity"]] for row in bc.rows], dtype=float)
                num = numerical_gradient(lambda y: reference_value(vb.spec.kind, y), x, 1e-3)
                np.testing.assert_allclose(s, num, rtol=1e-7, atol=1e-7 * np.max(np.abs(s)),
                                           err_msg=f"{c.name} {vb.label}")
                assert v[bc.value] == pytest.approx(reference_value(vb.spec.kind, x), rel=1e-9)
                n += 1
    return n


@pytest.mark.parametrize("engine", ENGINES)
def test_random_configuration_sensitivities_in_the_workbook(tmp_path, engine):
    task, results, layout = build(random_task_doc(7), tmp_path / "random.xlsx")
    values = recalc(tmp_path / "random.xlsx", engine)
    assert assert_sensitivities_are_derivatives(values, task, layout) == 1 + 2 + 9 + 4 + 6 + 9
    assert_workbook_matches(values, results, layout)


# ---------------------------------------------------------------------------------------------
# A user's edit, recalculated
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("engine", ENGINES)
def test_edited_inputs_recalculate_in_every_engine(edited, engine):
    out, eresults, layout = edited
    values = recalc(out, engine)
    assert_workbook_matches(values, eresults, layout)
    # the edit is visible: S1's position is now 2 * 0.004 mm off its TED
    s1 = next(c for c in eresults["characteristics"] if c["name"] == "S1_position")
    assert s1["value_mm"] == pytest.approx(0.008, rel=1e-9)


# ---------------------------------------------------------------------------------------------
# The job module: CLI build, new, bad input
# ---------------------------------------------------------------------------------------------


def test_cli_build_writes_workbook_json_and_plot(tmp_path):
    from cmmwb.generator.cli import main

    assert main(["build", str(KNUCKLE), "--out", str(tmp_path)]) == 0
    results = json.loads((tmp_path / "knuckle.json").read_text(encoding="utf-8"))
    assert results["kind"] == "budget"
    assert (tmp_path / "knuckle.xlsx").exists()
    assert (tmp_path / "knuckle_contributions.png").exists()
    ch = results["characteristics"][0]
    assert set(ch) >= {"name", "model", "variant", "value_mm", "u_um", "U_um", "rows"}
    assert set(ch["rows"][0]) == {"input", "value_mm", "sensitivity", "u_um", "contribution_um",
                                  "distribution", "nu"}
    assert_printed(ch["u_um"], "5.82")
    assert budget_job.summary(results)


def test_new_budget_writes_the_knuckle(tmp_path):
    from cmmwb.generator.cli import main

    out = tmp_path / "task.toml"
    assert main(["new", "budget", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == budget_job.NEW_TASK
    doc = tomllib.loads(budget_job.NEW_TASK)
    task = budget_job.load(out, doc)
    assert [c.name for c in task.characteristics][:4] == ["S4_position", "S1_position",
                                                           "S2_position", "S3_position"]
    assert "knuckle.toml" in budget_job.EXAMPLES


def bad(mutate, match: str, where: str | None = None):
    doc = knuckle_doc()
    mutate(doc)
    with pytest.raises(InputError, match=match) as e:
        budget_job.load(KNUCKLE, doc)
    assert e.value.file == str(KNUCKLE)
    if where is not None:
        assert e.value.where == where
    return e.value


def test_text_in_a_number_is_an_error():
    bad(lambda d: d["mpe"].__setitem__("A_um", "three"), "must be a number", "[mpe] A_um")


def test_nan_coordinate_is_an_error():
    bad(lambda d: d["points"].__setitem__("S4", [0, float("nan"), 63]), "finite", "[points] S4")


def test_unknown_point_is_an_error():
    bad(lambda d: d["characteristics"][0].__setitem__("point", "S9"), "unknown point 'S9'",
        "[[characteristics]] #1 key 'point'")


def test_unknown_model_is_an_error():
    bad(lambda d: d["characteristics"][1].__setitem__("model", "flatness"), "must be one of",
        "[[characteristics]] #2 key 'model'")


def test_point_name_that_looks_like_a_formula_is_an_error():
    bad(lambda d: d["points"].__setitem__("=HYPERLINK(1)", [0, 0, 0]), "point name",
        "[points] =HYPERLINK(1)")


def test_collinear_datum_points_name_the_characteristic():
    err = bad(lambda d: d["points"].__setitem__("C", [150, -32, 0]), "collinear",
              "[[characteristics]] #1")
    assert "S4_position" in str(err)


def test_unknown_variant_lists_the_valid_ones():
    bad(lambda d: d["characteristics"][6].__setitem__("variant", "XS4.(ABxAC)"),
        r"CS4\.\(CAxCB\)", "[[characteristics]] #7 key 'variant'")


def test_point_on_a_line_is_an_error():
    bad(lambda d: d["points"].__setitem__("S3", [0.01, -26, -15]), "lies on the line",
        "[[characteristics]] #6")


def test_cli_exit_status_2_names_file_and_characteristic(tmp_path):
    import subprocess
    import sys

    task = tmp_path / "k.toml"
    task.write_text(KNUCKLE.read_text(encoding="utf-8").replace("C = [0, 61, 0]",
                                                                "C = [150, -32, 0]"))
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "cmmwb.generator", "build", str(task), "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    msg = r.stderr.strip()
    assert len(msg.splitlines()) == 1 and "Traceback" not in msg
    assert "k.toml" in msg and "[[characteristics]] #1" in msg and "collinear" in msg
    assert not out.exists()


def test_datum_models_need_a_datum_system():
    bad(lambda d: d.pop("datum_system"), "needs a \\[datum_system\\]",
        "[[characteristics]] #1 key 'model'")


#: the part's temperature with every row (docs/workpiece.md): aluminium, two readings 0.4 K apart, a CMM
#: that does not correct (the expansion left in the result, carried in quadrature)
WORKPIECE = {"material": "aluminium", "u_alpha_ppm_per_K": 1.0, "T_readings_degC": [23.3, 23.7], "u_T_K": 0.3,
             "corrected": False}


@pytest.mark.parametrize("engine", ENGINES)
def test_the_part_temperature_rows_are_live_in_every_engine(tmp_path, engine):
    """With [workpiece] every budget (chosen and other variants, a position's two distances) gains the
    rows alpha, T, dT, b in the paper's layout; every cell agrees with the JSON, and the W part of a
    distance's u is l u(eps) (sensitivities -l (T - 20), -l alpha)."""
    doc = knuckle_doc()
    doc["workpiece"] = dict(WORKPIECE)
    task, results, layout = build(doc, tmp_path / "knuckle_W.xlsx")
    u_eps = math.sqrt((3.5 * 1.0) ** 2 + 23.1**2 * (0.3**2 + 0.4**2 / 12) + (23.1 * 3.5) ** 2)
    n = 0
    for ch in results["characteristics"]:
        for d in ([ch] if ch["model"] != "position" else ch["distances"]):
            assert d["u_W_um"] == pytest.approx(d["value_mm"] * u_eps * 1e-3, rel=1e-12), d["name"]
            assert [r["input"] for r in d["workpiece_rows"]] == ["alpha", "T", "dT", "b_uncorrected"]
            n += 1
    assert n >= 8
    assert assert_workbook_matches(recalc(tmp_path / "knuckle_W.xlsx", engine), results, layout) > 400


def test_W_off_is_one_key_and_the_paper_tables_stay(tmp_path):
    """enabled = false keeps the inputs and rows (u = 0): u, U of every characteristic are the
    paper's, as without the table."""
    plain = budget_job.compute(budget_job.load(KNUCKLE, knuckle_doc()))
    doc = knuckle_doc()
    doc["workpiece"] = dict(WORKPIECE, enabled=False)
    off = budget_job.compute(budget_job.load(KNUCKLE, doc))
    for a, b in zip(plain["characteristics"], off["characteristics"]):
        assert (a["u_um"], a["U_um"], a["value_mm"]) == (b["u_um"], b["U_um"], b["value_mm"]), a["name"]
