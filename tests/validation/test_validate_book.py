"""The validation workbook recalculates in every engine to the numbers of validation.json: per row
the deviation, U_c, E_n, u_c, the claimed coverage and z; the count, the binomial tails, the
chi-square of the rows, the verdict; the Results sheet.  A small set: twelve step-gauge lengths
with their probed points (one with a repeat), two rings and two spheres."""

import json

import pytest

from cmmwb.generator.cli import main
from cmmwb.generator.workbook.recalc import results_rows

from tests.helpers import ENGINES, close, recalc

ROW_COLUMNS = {"deviation": "O", "U_c": "P", "E_n": "Q", "u_c": "S", "claimed_coverage": "T"}


@pytest.fixture(scope="module")
def book(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("valbook")
    assert main(["simulate", "--validation", "stepgauge,ring,sphere", "--seed", "8", "--runs", "2",
                 "--out", str(tmp / "set")]) == 0
    lines = (tmp / "set" / "results.csv").read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("characteristic"))
    body = lines[head + 1:]
    steps = [ln for ln in body if ln.startswith("SGx") and ",1," in ln][:12]
    rest = [ln for ln in body if not ln.startswith("SG")]
    repeat = steps[3].split(",")
    repeat[3] = f"{float(repeat[3]) + 0.0003:.7f}"          # a second reading of one length in run 1
    (tmp / "small.csv").write_text("\n".join([lines[head], *steps, ",".join(repeat), *rest]) + "\n")
    assert main(["validate", str(tmp / "small.csv"), "--task", str(tmp / "set" / "validation_lengths.toml"),
                 "--task", str(tmp / "set" / "validation_features.toml"), "--out", str(tmp / "out")]) == 0
    return tmp / "out" / "validation.xlsx", json.loads((tmp / "out" / "validation.json").read_text())


def test_the_small_set_has_rows_with_and_without_probed_points_and_a_repeat(book):
    _, r = book
    assert len(r["rows"]) == 12 + 10 and r["locator"]["records"] == 12
    assert [row["repeats"] for row in r["rows"]].count(2) == 1
    assert r["count"]["p_low_correlated"] is not None


@pytest.mark.parametrize("engine", ENGINES)
def test_the_workbook_agrees_with_its_json(book, engine):
    path, r = book
    values = recalc(path, engine)
    ws = values["Rows"]
    for k, row in enumerate(r["rows"]):
        for name, col in ROW_COLUMNS.items():
            assert close(ws[f"{col}{3 + k}"], row[name]), (engine, k, name, ws[f"{col}{3 + k}"], row[name])
        assert ws[f"R{3 + k}"] == (1 if row["within"] else 0)
    v = values["Verdict"]
    cells = {v[f"A{i}"]: v.get(f"B{i}") for i in range(2, 20) if v.get(f"A{i}")}
    c = r["count"]
    for key, want in (("rows", c["rows"]), ("within", c["within"]), ("share", c["share"]),
                      ("claimed", c["claimed"]), ("p_low_binomial", c["p_low_binomial"]),
                      ("p_high_binomial", c["p_high_binomial"]), ("p_count", c["p_low"]),
                      ("p_structure", r["p_structure"]), ("holds", 1.0 if r["verdict"]["holds"] else 0.0)):
        assert close(float(cells[key]), want), (engine, key, cells[key], want)
    z2 = sum(row["deviation"] ** 2 / row["u_c"] ** 2 for row in r["rows"])
    assert close(float(cells["chi2_rows"]), z2)
    assert cells["verdict"] == r["verdict"]["verdict"]
    res = {row["quantity"]: row["value"] for row in results_rows(values)}
    assert close(float(res["p_count"]), c["p_low"]) and close(float(res["within"]), c["within"])
    # the report page: its verdicts and its rows (largest E_n first) are live formulas of the sheets
    page = set(values["Summary"].values())
    assert r["verdict"]["verdict"] in page and "no structure found" in page
    assert f"E_n = {r['worst'][0]['E_n']:.2f}" in page
