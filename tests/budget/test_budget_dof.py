"""Degrees of freedom in the budget kind's budgets (GUM G.4): every budget row has a
distribution (the one u = b·E_L,MPE implies) and ν (∞ for the MPE inputs, GUM G.4.2/G.4.3), every
budget a ν_eff cell (Welch–Satterthwaite, GUM eq. (G.2b)); a type A repeatability of
``[[decision.tolerances]]`` (s_um, n_repeats) is a row of its characteristic's budget, normal,
ν = n − 1, so that ν_eff is finite and k = t_95.45(⌊ν_eff⌋) with ``k_from_dof``.

The knuckle (S1_S2_distance has s = 2.5 µm of n = 5; here S4_position gets s = 3 µm of n = 4 as
well) is built, recalculated by `formulas` and LibreOffice, and every new cell is compared with
the JSON at relative 1e-9, text exactly.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest
import tomli_w

from cmmwb.generator.budget import book as budget_book
from cmmwb.generator.build import build_task
from cmmwb.xlfuncs import dof

from tests.helpers import ENGINES, close, recalc

KNUCKLE = Path(budget_book.__file__).parents[1] / "examples" / "knuckle.toml"


def build(tmp: Path, monkeypatch, edit=None):
    """Build the knuckle (optionally edited); (results, workbook, layout of the budget cells)."""
    doc = tomllib.loads(KNUCKLE.read_text(encoding="utf-8"))
    if edit is not None:
        edit(doc)
    task = tmp / "knuckle.toml"
    task.write_text(tomli_w.dumps(doc), encoding="utf-8")
    layout: dict = {}
    write = budget_book.write

    def spy(*args, **kw):
        layout.update(write(*args, **kw))
        return layout

    monkeypatch.setattr(budget_book, "write", spy)
    results, files = build_task(task, tmp / "out", plots=False)
    return results, next(f for f in files if f.suffix == ".xlsx"), layout


def with_position_repeatability(doc: dict) -> None:
    for t in doc["decision"]["tolerances"]:
        if t["characteristic"] == "S4_position":
            t.update(s_um=3.0, n_repeats=4)


@pytest.fixture(scope="module")
def knuckle(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    try:
        yield build(tmp_path_factory.mktemp("dof"), mp, with_position_repeatability)
    finally:
        mp.undo()


def pairs(results: dict, layout: dict) -> list[tuple[str, str, str, object]]:
    """(what, sheet, cell, JSON value) of every new cell: ν = ∞ is the JSON null and the text ∞."""
    out = []

    def nu(v):
        return "∞" if v is None else v

    def block(sheet, where, bc_rows, json_rows, nu_eff_cell, json_nu_eff):
        assert [r["input"] for r in json_rows] == [c["input"] for c in bc_rows]
        for c, r in zip(bc_rows, json_rows):
            out.append((f"{where} {r['input']} distribution", sheet, c["distribution"], r["distribution"]))
            out.append((f"{where} {r['input']} nu", sheet, c["nu"], nu(r["nu"])))
        out.append((f"{where} nu_eff", sheet, nu_eff_cell, nu(json_nu_eff)))

    def distance(cc, entry, where):
        for v in entry["variants"]:
            bc = cc.variants[v["variant"]]
            if v["variant"] == entry["variant"]:
                assert v["nu_eff"] == entry["nu_eff"], where
            block(bc.sheet, f"{where} [{v['variant']}]", bc.rows, v["rows"], bc.nu_eff, v["nu_eff"])

    for ch in results["characteristics"]:
        cc = layout[ch["name"]]
        if ch["model"] == "position":
            block(cc.sheet, ch["name"], cc.rows, ch["rows"], cc.nu_eff, ch["nu_eff"])
            for dcc, d in zip(cc.distances, ch["distances"]):
                distance(dcc, d, f"{ch['name']} {d['name']}")
        else:
            distance(cc, ch, ch["name"])
        a = ch.get("type_a")
        assert (a is None) == (cc.type_a is None), ch["name"]
        if a is not None:
            for key, json_key in (("u", "u_um"), ("nu", "nu"), ("u_with", "u_with_type_a_um"), ("k", "k"),
                                  ("U_with", "U_with_type_a_um")):
                out.append((f"{ch['name']} type A {json_key}", cc.sheet, cc.type_a[key], a[json_key]))
    return out


def assert_agrees(values: dict, results: dict, layout: dict) -> int:
    n = 0
    for what, sheet, coord, want in pairs(results, layout):
        got = values[sheet].get(coord)
        if isinstance(want, str):
            assert got == want, f"{sheet}!{coord} {what}: {got!r} != {want!r}"
        else:
            assert close(got, want, rel=1e-9), f"{sheet}!{coord} {what}: {got!r} != {want!r}"
        n += 1
    return n


# -- the core -------------------------------------------------------------------------------------

@pytest.mark.parametrize("b, name", [(0.577, "rectangular"), (1 / math.sqrt(3), "rectangular"),
                                     (0.408, "triangular"), (1 / 3, "normal (b given)"),
                                     (0.5, "normal (b given)")])
def test_b_names_the_distribution(b, name):
    assert dof.distribution_of_b(b) == name


def test_json_rows_carry_distribution_and_nu(knuckle):
    results, _, _ = knuckle
    for ch in results["characteristics"]:
        rows = ch["rows"] if ch["model"] != "position" else [r for d in ch["distances"] for r in d["rows"]]
        assert {r["distribution"] for r in rows} == {"rectangular"}        # b = 0.577
        assert {r["nu"] for r in rows} == {None}                           # ν = ∞: type B
        assert set(rows[0]) >= {"input", "value_mm", "sensitivity", "u_um", "contribution_um"}


def test_type_a_makes_nu_eff_finite_and_k_from_t(knuckle):
    """S1_S2_distance: u_c (type B, ν = ∞) and u_A = 2.5/√5 µm, ν_A = 4: ν_eff = u⁴/(u_A⁴/4)
    by hand, k = t_95.45(⌊ν_eff⌋); the same numbers as the Decision sheet's."""
    results, _, _ = knuckle
    ch = next(c for c in results["characteristics"] if c["name"] == "S1_S2_distance")
    a = ch["type_a"]
    u_a = 2.5 / math.sqrt(5)
    u = math.hypot(ch["u_um"], u_a)
    assert close(a["u_um"], u_a, rel=1e-12) and a["nu"] == 4 and a["distribution"] == "normal"
    assert close(ch["nu_eff"], u ** 4 / (u_a ** 4 / 4), rel=1e-12)
    assert math.isfinite(ch["nu_eff"]) and ch["nu_eff"] > 4
    assert close(a["k"], dof.t_quantile(0.5 + dof.P_K2 / 2, math.floor(ch["nu_eff"])), rel=1e-12)
    assert a["k"] > 2.0
    d = next(d for d in results["decisions"] if d["characteristic"] == "S1_S2_distance")
    assert close(d["nu_eff"], ch["nu_eff"], rel=1e-12) and close(d["k"], a["k"], rel=1e-12)
    assert close(d["U_um"], a["U_with_type_a_um"], rel=1e-12)
    assert ch["u_um"] < a["u_with_type_a_um"]          # u_um (the Results contract) stays type B


def test_without_type_a_nu_eff_is_infinite(knuckle):
    results, _, _ = knuckle
    ch = next(c for c in results["characteristics"] if c["name"] == "S3_position")
    assert ch["nu_eff"] is None and "type_a" not in ch


# -- the workbook, four engines ---------------------------------------------------------------------

@pytest.mark.parametrize("engine", ENGINES)
def test_every_engine_agrees_with_the_json(knuckle, engine):
    results, book, layout = knuckle
    n = assert_agrees(recalc(book, engine), results, layout)
    assert n > 500


@pytest.mark.parametrize("engine", ENGINES)
def test_another_b_is_shown_live(tmp_path, monkeypatch, engine):
    """b = 0.408 (1/√6): every MPE input reads "triangular" in the recalculated workbook."""
    def edit(doc):
        doc["mpe"]["b"] = 0.408
    results, book, layout = build(tmp_path, monkeypatch, edit)
    assert_agrees(recalc(book, engine), results, layout)
    assert {r["distribution"] for c in results["characteristics"] if c["model"] != "position"
            for r in c["rows"]} == {"triangular"}
