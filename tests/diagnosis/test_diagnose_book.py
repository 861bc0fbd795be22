"""Four engines, one answer: the diagnosis workbook's native refit (GLS normal equations with
MMULT/MINVERSE over the chosen sensitivity columns, themselves formulas of the record cells)
recomputed by `formulas` and by LibreOffice agrees with diagnosis.json to relative 1e-9."""

import json

import pytest

from cmmwb.generator.diagnosis import book as diagnose_book
from cmmwb.generator.diagnosis.run import run_diagnose
from cmmwb.generator.workbook.recalc import results_rows
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.recordings import write_recordings

from tests.helpers import ENGINES, close, recalc
from tests.helpers.clouds import MPE1, ONE, PAIR, THREE
from tests.helpers.locator import expected_rows

CASES = {
    # name: (layout, kwargs, probes, planted, temperature, effects that must be chosen)
    "lengths": ("iso10360", {"repeats": 1}, ONE, {"squareness_xy": 40.0, "thermal_expansion": 3.0},
                ("bump",), {"squareness_xy", "thermal_expansion"}),
    "lengths, three probes, whitened": ("iso10360", {"repeats": 3}, THREE, {"ECZ": 300.0, "scale_drift": 2.0},
                                        None, {"ECZ", "scale_drift"}),
    "points": ("ballplate", {"grid": 3}, PAIR, {"probe_qualification": {"P2": [2.5, -2.0, 1.5]},
                                                "squareness_xy": 40.0}, None,
               {"probe_qualification", "squareness_xy"}),
    "points 2-D": ("holeplate", {"grid": 2, "passes": 2}, PAIR[:1], {"probe_radius": 2.0, "offset_drift": [3.0, -2.0, 0.0]},
                   (19.0, 23.0), {"probe_radius", "offset_drift"}),
    # second edition (docs/recordings.md section 7): a gross outlier left out; inflated noise
    "lengths, an outlier": ("iso10360", {"repeats": 1}, ONE, {}, None, set()),
    "lengths, inflated noise": ("iso10360", {"repeats": 3}, ONE, {}, None, set()),
    # an out-of-library bump: not explained, the discrepancy candidate shown (section 7)
    "lengths, a bump": ("iso10360", {"repeats": 3}, ONE, {}, None, set()),
    # section 7's straightness (Legendre polynomials of the travel) and reversal (approach sign)
    "lengths, straightness and reversal": ("iso10360", {"repeats": 1}, PAIR, {"EZY": [0.0, 5.0], "reversal_x": 1.5},
                                           None, {"EZY", "reversal_x"}),
    "points 2-D, straightness and reversal": ("holeplate", {"grid": 3, "passes": 2}, PAIR[:1],
                                              {"EYX": [2.0, -1.5], "reversal_x": 1.0}, None, {"EYX", "reversal_x"}),
    # thermal gradient: the expansion-coefficient error at the length's midpoint / at the point
    "lengths, thermal gradient": ("stepgauge", {"steps": 8}, ONE, {"thermal_gradient_y": 150.0}, ("bump",),
                                  {"thermal_gradient_y"}),
    "points, thermal gradient": ("ballplate", {"grid": 3, "passes": 4}, PAIR[:1], {"thermal_gradient_y": 15.0},
                                 ("bump",), {"thermal_gradient_y"}),
    # probe lobing: harmonics 2-4 of the normal's azimuth as polynomials of nx, ny
    "points, probe lobing": ("spheres", {}, PAIR, {"probe_lobing": {"P1": [0.8, -0.5, 0.6, 0.0, 0.3, 0.4]}}, None,
                             {"probe_lobing"}),
    # periodic errors: SIN/COS of the travel at the scanned period, and the period's own column
    "lengths, periodic error": ("stepgauge", {}, ONE, {"periodic_x": [0.6, -0.4, 72.0]}, None, {"periodic_x"}),
    "points 2-D, periodic error": ("holeplate", {"passes": 2}, PAIR[:1], {"periodic_y": [0.5, 0.7, 118.0]}, None,
                                   {"periodic_y"}),
}


def _outlier(rec):
    rec.measured_mm[11] += 0.009        # 9 µm on one record
    return rec


def _bump(rec):
    import numpy as np

    return sm.plant_field(rec, lambda U: np.column_stack(
        [4.0 * np.exp(-0.5 * ((U[:, 0] - 650.0) / 100.0) ** 2), 0 * U[:, 0], 0 * U[:, 0]]))


SECOND = {"lengths, a bump": (MPE1, _bump),
          "lengths, an outlier": (MPE1, _outlier),
          "lengths, inflated noise": (pc.Parameters(**{k: v * (1.8 if k.startswith("sigma") else 1.0)
                                                       for k, v in MPE1.__dict__.items()}), None)}


def _build(tmp_path, case, monkeypatch):
    layout, kw, probes, planted, T, _ = CASES[case]
    L = sm.layout(layout, probes, **kw)
    if T == ("bump",):
        import numpy as np

        T = 20.0 + 3.0 * np.sin(np.pi * L.time_s / L.time_s.max())
    params, tweak = SECOND.get(case, (MPE1, None))
    rec = sm.simulate(L, params, planted, seed=17, temperature_C=T)
    if tweak:
        rec = tweak(rec)
    path = tmp_path / "rec.csv"
    write_recordings(rec, path)
    if "whitened" in case:
        monkeypatch.setattr(diagnose_book, "NATIVE_MAX_OBS", 20)
    result, files = run_diagnose(path, dg.Model(MPE1, probes, True), tmp_path / "out", plots=False)
    return result, tmp_path / "out" / "diagnosis.xlsx"


@pytest.fixture(scope="module")
def books(tmp_path_factory):
    out = {}
    mp = pytest.MonkeyPatch()
    try:
        for case in CASES:
            out[case] = _build(tmp_path_factory.mktemp(case.replace(" ", "_").replace(",", "")), case, mp)
            mp.undo()
    finally:
        mp.undo()
    return out


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("case", list(CASES))
def test_native_refit_agrees_with_the_json(books, case, engine):
    result, book = books[case]
    assert {e["name"] for e in result["effects"]} >= CASES[case][5], result["summary"]
    values = recalc(book, engine)
    rows = {r["quantity"]: r for r in results_rows(values)}
    exp, unc = expected_rows(result)
    assert set(rows) == set(exp)
    for q, v in exp.items():
        assert close(rows[q]["value"], v), f"{engine} {case}: {q} {rows[q]['value']!r} != {v!r}"
        if q in unc:
            assert close(rows[q]["u"], unc[q]), f"{engine} {case}: u({q})"
    errors = [(s, c, v) for s, cells in values.items() for c, v in cells.items()
              if isinstance(v, str) and v.startswith("#")]
    assert not errors, errors[:5]


@pytest.mark.parametrize("engine", ENGINES)
def test_standardized_residuals_of_the_located_records_agree(books, engine):
    result, book = books["lengths"]
    values = recalc(book, engine)["Records"]
    header = {v: k[:-1] for k, v in values.items() if k.endswith("1") and k[:-1].isalpha()}
    col_id, col_z = header["id"], header["z"]
    by_id = {values[f"{col_id}{r}"]: values[f"{col_z}{r}"] for r in range(2, result["records"] + 2)}
    for item in result["located"]:
        assert close(by_id[item["id"]], item["z"]), item


def test_the_json_written_is_the_contract(books):
    result, book = books["lengths"]
    on_disk = json.loads((book.parent / "diagnosis.json").read_text())
    assert on_disk == json.loads(json.dumps(result))
    assert on_disk["kind"] == "length" and on_disk["records"] == 35


def test_the_outlier_is_left_out_in_the_workbook_too(books):
    result, _ = books["lengths, an outlier"]
    assert [o["id"] for o in result["outliers"]] and result["effects"] == [] and result["explained"]


def test_inflated_noise_gives_the_noise_scale_in_the_workbook(books):
    result, _ = books["lengths, inflated noise"]
    assert result["noise_scale"] and result["effects"] == [] and not result["explained"]


def test_the_discrepancy_is_shown_in_the_search_log(books):
    import openpyxl

    result, book = books["lengths, a bump"]
    d = result["discrepancy"]
    assert result["explained"] is False and d["chosen"] is True
    ws = openpyxl.load_workbook(book)["Candidates"]
    rows = [[c.value for c in r] for r in ws.iter_rows()]
    at = next(i for i, r in enumerate(rows) if isinstance(r[0], str) and r[0].startswith("discrepancy (chosen)"))
    head, vals = rows[at + 1], rows[at + 2]
    for key in ("p_adjusted", "chi2_after", "size_um"):        # xlsx keeps 15-17 digits
        assert close(vals[head.index(key)], d[key]), key


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("case", ["lengths", "lengths, inflated noise"])
def test_the_report_page_carries_the_verdicts_and_the_estimates_live(books, case, engine):
    """The Summary sheet (issue 32): the mismatch verdict as the GLS sheet's formulas decide it,
    and each estimated effect's rounded statement from the Results cells."""
    from cmmwb.generator.diagnosis.page import AGREE, DISAGREE

    result, book = books[case]
    texts = [v for v in recalc(book, engine)["Summary"].values() if isinstance(v, str)]
    assert (DISAGREE if result["mismatch"] else AGREE) in texts
    for e in result["effects"]:
        if e["name"] != "outlier":
            assert any(t.startswith(f"{e['name']} = ") and "coverage probability" in t for t in texts), e["name"]
    assert result["provenance"]["input_files"][0]["name"] == "rec.csv"
    assert any(result["provenance"]["input_files"][0]["sha256"] in t for t in texts)
