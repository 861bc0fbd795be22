"""One table of effects, two renderings: every candidate effect's sensitivity columns written as
workbook formulas (generator/diagnosis/formulas.py) and recomputed by `formulas` equal the core's
columns (xlfuncs/locator/effects.py) to relative 1e-9, cell by cell, on a recording that exercises
each effect: step gauges along two oblique directions for length records (every effect but
offset_drift, which does not apply to lengths), a spiral of points probed from all around with
two probes for point records (every effect)."""

from types import SimpleNamespace

import numpy as np
import pytest

from cmmwb.generator.diagnosis import book as diagnose_book
from cmmwb.generator.diagnosis import formulas as fo
from cmmwb.generator.diagnosis import records
from cmmwb.generator.workbook.book import Book
from cmmwb.generator.workbook.xlref import col
from cmmwb.xlfuncs.locator import diagnose as dg
from cmmwb.xlfuncs.locator import effects as fx
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.model import MPE1  # Forbes 2025 Table 3

from tests.helpers import ENGINES, close, recalc
from tests.helpers.clouds import PAIR

#: the point (a0, b0) of a periodic error at which the workbook linearizes its period (Inputs)
AB0 = (0.7, -0.4)


def spiral(probes, points: int = 40, radius: float = 10.0, step: float = 3.0) -> sm.Layout:
    """Points on a spiral about a diagonal line (nominal frame), normals outward and tilted up and
    down in turn: every axis sampled densely, every approach direction, both probes."""
    i = np.arange(points)
    th = i * (2.0 * np.pi / 7.0)
    Xn = np.column_stack([step * i + radius * np.cos(th), 0.8 * step * i + radius * np.sin(th), 0.6 * step * i])
    N = np.column_stack([np.cos(th), np.sin(th), np.where(i % 2 == 0, 0.5, -0.5)])
    N /= np.linalg.norm(N, axis=1)[:, None]
    centre = np.array([500.0, 400.0, 100.0])
    return sm.Layout("point", "spiral", tuple(probes), Xn + centre, N, i % len(probes),
                     [f"S{k + 1}" for k in i], ["spiral"] * points, np.linspace(0.0, 7200.0, points), X_nom=Xn)


def gauge(probes, directions=((1.0, 0.5, 1.0), (-0.5, 1.0, 1.0)), steps: int = 10) -> sm.Layout:
    """Step gauges along two oblique directions (simulate.stepgauge's faces, 20 mm apart, the right face
    probed with the second probe): every direction component, every axis travelled densely."""
    X, N, K, I, J, ids = [], [], [], [], [], []
    for g, d in enumerate(np.array(directions) / np.linalg.norm(directions, axis=1)[:, None]):
        o = np.array([500.0, 400.0, 250.0 - 60.0 * g]) - 100.0 * d
        first = None
        for k in range(steps):
            for side, off, sgn in (("L", 0.0, -1.0), ("R", 10.0, 1.0)):
                X.append(o + (20.0 * k + off) * d)
                N.append(sgn * d)
                K.append(1 if side == "R" else 0)
                if first is None:
                    first = len(X) - 1
                    continue
                I.append(first)
                J.append(len(X) - 1)
                ids.append(f"G{g + 1}-{side}{k + 1}")
    n = len(ids)
    return sm.Layout("length", "gauge", tuple(probes), np.array(X), np.array(N), np.array(K), ids,
                     ["gauge"] * n, np.linspace(0.0, 7200.0, n), I=np.array(I), J=np.array(J))


RECORDINGS = {
    "length": lambda: gauge(PAIR),
    "point": lambda: spiral(PAIR),
}


def core_columns(D: fx.Design) -> dict[str, tuple[list[str], np.ndarray, float | None, float]]:
    """{effect: (labels, columns, period, full scale)} of every effect that applies to these
    records; a periodic error at the longest period the records identify, with its period's
    column at AB0."""
    out = {}
    for name in fx.NAMES:
        try:
            if name in fx.PERIODIC:
                P = float(fx.period_grid(D, fx.AXES.index(name[-1]))[0][0])
                c = fx.columns(D, name, P)
                out[name] = (c.labels + ["period_mm"],
                             np.column_stack([c.X, fx.period_column(D, name, P, *AB0)]), P, c.full_scale)
            else:
                c = fx.columns(D, name)
                out[name] = (c.labels, c.X, None, c.full_scale)
        except fx.NotApplicable:
            continue
    return out


def _sheet_with_every_effect(kind: str, tmp_path, engine: str):
    """Inputs and the record sheets of the diagnosis workbook with every exercised effect's
    columns chosen; (core columns, the sheet's values as ``engine`` recomputes them,
    {label: column}, rows)."""
    rec = sm.simulate(RECORDINGS[kind](), MPE1, {}, seed=5, temperature_C=(18.5, 23.0))
    prep = dg.prepare(rec, dg.Model(MPE1, PAIR, True), False)
    cols = core_columns(prep.design)
    labels = [("alignment", a) for a in prep.A_labels] + [(e, lab) for e, (labs, *_) in cols.items()
                                                          for lab in labs]
    diag = SimpleNamespace(prep=prep, alpha=0.01, sel_labels=labels, candidates={
        e: SimpleNamespace(period_mm=P, lin_ab=AB0) for e, (_, _, P, _) in cols.items() if P is not None})
    book = Book("diagnose", "diagnosis", "Every effect's sensitivity columns")
    inputs = diagnose_book.inputs_sheet(book, diag, None)
    write = records.length_records if kind == "length" else records.point_records
    _, obs = write(book, diag, inputs)
    path = book.save(tmp_path / f"{kind}.xlsx")
    return cols, recalc(path, engine)[obs["sheet"]], obs["ci"], obs["rows"]


@pytest.fixture(scope="module", params=ENGINES)
def sheets(tmp_path_factory, request):
    return {kind: _sheet_with_every_effect(kind, tmp_path_factory.mktemp(kind), request.param) for kind in RECORDINGS}


def test_every_family_has_columns_and_formulas():
    families = {e.family for e in fx.EFFECTS}
    assert families == set(fx.FAMILIES) == set(fo.FORMULAS)
    for f in families:   # a family without length columns has no length formula, and back
        assert (fx.FAMILIES[f].length is None) == (fo.FORMULAS[f].length is None), f


@pytest.mark.parametrize("kind", list(RECORDINGS))
def test_the_recordings_exercise_every_effect(sheets, kind):
    cols = sheets[kind][0]
    missing = set(fx.NAMES) - set(cols) - ({"offset_drift"} if kind == "length" else set())
    assert not missing


@pytest.mark.parametrize("kind", list(RECORDINGS))
@pytest.mark.parametrize("name", fx.NAMES)
def test_workbook_columns_equal_the_core_columns(sheets, kind, name):
    cols, values, ci, rows = sheets[kind]
    if name not in cols:
        pytest.skip(f"{name} does not apply to {kind} records")
    labels, X, _, full_scale = cols[name]
    assert X.shape == (len(rows), len(labels))
    for q, lab in enumerate(labels):
        # the recording exercises it: the core's own test of "a sensitivity" (diagnose.py)
        assert np.max(np.abs(X[:, q])) > fx.REL_ZERO * full_scale, (name, lab)
        c = col(ci[f"{name}:{lab}"])
        got = np.array([float(values.get(f"{c}{r}") or 0.0) for r in rows])
        # rel 1e-9; entries that cancel to nothing (a squareness of a length nearly along an axis)
        # agree to 1e-12 of the column's natural size
        bad = [(r, g, x) for r, g, x in zip(rows, got, X[:, q]) if not close(g, x, floor=1e-12 * full_scale)]
        assert not bad, (name, lab, bad[:3])
