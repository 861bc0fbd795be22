"""Decision words that are true (issue 32), over every decision `cmmwb demo` makes (every worked
example of every kind): the rule's outcome ("accepted / rejected under rule X", or the ISO 14253-1
rule's own three) and the conformity statement (what value and U prove) are separate, and no word
contradicts the value against its limits: nothing "conforms" or is "conformity proven" outside its
tolerance interval, nothing "does not conform" inside it. The JSON, the Decision sheet and the
Summary (the report page) say the same."""

from __future__ import annotations

import openpyxl
import pytest

from cmmwb.generator import decision
from cmmwb.generator.build import build_task
from cmmwb.generator.jobs import JOBS
from cmmwb.generator.workbook import report_page
from cmmwb.xlfuncs import conformity as cf

from tests.helpers import EXAMPLES
from tests.helpers.decision import at

DEMO = [(kind, name) for kind, mod in JOBS.items() for name in mod.EXAMPLES]


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """{example: (results, book)} of every demo task with decisions."""
    out = {}
    for kind, name in DEMO:
        results, files = build_task(EXAMPLES / name, tmp_path_factory.mktemp(name.split(".")[0]), plots=False)
        if results.get("decisions"):
            out[name] = (results, next(f for f in files if f.suffix == ".xlsx"))
    return out


def _inside(y: float, lo: float | None, hi: float | None) -> bool:
    return (lo is None or y >= lo) and (hi is None or y <= hi)


def test_every_kind_has_decisions_in_the_demo(demo):
    kinds = {results["kind"] for results, _ in demo.values()}
    assert kinds == set(JOBS)
    assert sum(len(r["decisions"]) for r, _ in demo.values()) >= 40


def test_no_word_contradicts_the_value_against_its_limits(demo):
    bad = []
    n = 0
    for name, (results, _) in demo.items():
        for d in results["decisions"]:
            n += 1
            y, lsl, usl, U = d["value_mm"], d["lsl_mm"], d["usl_mm"], d["U_um"] / 1000
            inside = _inside(y, lsl, usl)
            if d["outcome"] == cf.CONFORMS or d["conformity"] == cf.CONFORMITY_PROVEN:
                ok = _inside(y, None if lsl is None else lsl + U, None if usl is None else usl - U)
            elif d["outcome"] == cf.DOES_NOT_CONFORM or d["conformity"] == cf.NONCONFORMITY_PROVEN:
                ok = not _inside(y, None if lsl is None else lsl - U, None if usl is None else usl + U)
            else:
                ok = True
            ok = ok and (d["conformity"] != cf.CONFORMITY_PROVEN or inside)
            ok = ok and (d["conformity"] != cf.NONCONFORMITY_PROVEN or not inside)
            if d["rule"] != "iso14253":          # a binary rule's outcome is accepted or rejected, never conformity
                ok = ok and d["outcome"] in (cf.ACCEPTED, cf.REJECTED) and d["rule_outcome"] == d["outcome"]
            else:
                ok = ok and d["conformity"] == {cf.CONFORMS: cf.CONFORMITY_PROVEN, cf.UNDECIDED: cf.NEITHER_PROVEN,
                                                cf.DOES_NOT_CONFORM: cf.NONCONFORMITY_PROVEN}[d["outcome"]]
            # the non-conformance limits are T -/+ U under every rule
            want = [None if lsl is None else lsl - U, None if usl is None else usl + U]
            ok = ok and all((a is None) == (b is None) and (a is None or abs(a - b) < 1e-12)
                            for a, b in zip(d["non_conformance_limits_mm"], want))
            if not ok:
                bad.append((name, d["characteristic"], d["outcome"], d["conformity"], y, lsl, usl, U))
    assert n >= 40 and not bad, bad


def test_table7_guarded_rejection_accepts_beyond_the_limit_and_proves_nothing(demo):
    """feature/table7_cone_arc: r0 = 50.0215 mm against [49.98, 50.02] mm, p_c = 0.19, guarded
    rejection r = 0.5: accepted under the rule, neither conformity nor non-conformity proven (it
    printed "conforms (acceptance zone)"); R_U = T_U + U (it was 50.0217 = A_U)."""
    results, book = demo["feature_table7_cone_arc.toml"]
    (d,) = results["decisions"]
    assert (d["value_mm"], d["lsl_mm"], d["usl_mm"]) == pytest.approx((50.0215, 49.98, 50.02))
    assert round(d["p_c"], 2) == 0.19
    assert (d["outcome"], d["rule_name"], d["zone"]) == ("accepted", "guarded rejection", "acceptance zone")
    assert (d["conformity"], d["conformity_zone"]) == ("neither proven", "uncertainty range")
    assert d["non_conformance_limits_mm"][1] == pytest.approx(50.02 + d["U_um"] / 1000, abs=1e-12)
    _sheets_say(book, d)


@pytest.mark.parametrize("name", ["stepgauge_I_MPE1.toml", "stepgauge_II_MPE1.toml", "stepgauge_I_MPE2.toml",
                                  "stepgauge_II_MPE2.toml"])
def test_step_gauge_specific_risk_rejects_and_proves_nothing(demo, name):
    """Specific risk, max_pfa = 0.05: d(L1→L26) = 500.0021 mm against 500 ± 0.003 mm has p_c =
    0.92 (MPE1) or 0.67 (MPE2): rejected under the rule, and inside its tolerance: neither proven
    (it printed "does not conform (rejection zone)"; 8 such rows in the demo)."""
    results, book = demo[name]
    for d in results["decisions"]:
        assert (d["outcome"] == "accepted") == (d["p_c"] >= 0.95) and d["rule_name"] == "specific risk"
        if d["outcome"] == "rejected":
            assert _inside(d["value_mm"], d["lsl_mm"], d["usl_mm"]) and d["conformity"] == "neither proven"
        _sheets_say(book, d)
    d = next(x for x in results["decisions"] if x["characteristic"] == "L1→L26")
    assert d["value_mm"] == pytest.approx(500.0021) and d["outcome"] == "rejected"
    assert round(d["p_c"], 2) == (0.92 if "MPE1" in name else 0.67)


def test_the_demo_has_eight_rejected_rows_that_prove_nothing(demo):
    rows = [(n, d["characteristic"]) for n, (r, _) in demo.items() for d in r["decisions"]
            if d["rule"] == "specific_risk" and d["outcome"] == "rejected"]
    assert len(rows) == 8, rows


def _sheets_say(book, d: dict) -> None:
    """The Decision row and the Summary's block of ``d`` hold the JSON's words (cached values)."""
    wb = openpyxl.load_workbook(book, data_only=True)
    ws = wb["Decision"]
    r = next(r for r in range(decision.FIRST_ROW, ws.max_row + 1)
             if ws[at(r, "characteristic")].value == d["characteristic"])
    for key in ("outcome", "zone", "conformity", "conformity_zone"):
        assert ws[at(r, key)].value == d[key], key
    s = wb["Summary"]
    row = next(r for r in range(1, s.max_row + 1) if s.cell(r, 1).value == d["characteristic"])
    assert s.cell(row, report_page.C["decision"]).value == d["outcome"]
    assert s.cell(row + 1, report_page.C["decision"]).value == f"({d['rule_name']})"
    assert s.cell(row, report_page.C["conformity"]).value == d["conformity"]
    assert s.cell(row + 1, report_page.C["conformity"]).value == f"({d['conformity_zone']})"
    assert s.cell(row + 1, 1).value == d["statement"]
