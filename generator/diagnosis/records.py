"""The record sheets of the diagnosis workbook (``docs/recordings.md`` section 3): Records (length
records: inputs, direction, ram positions, residual, the chosen effects' sensitivity columns as
formulas of the row, :mod:`.formulas`) or Points + Coords (point records: one row per point, one
row per coordinate with the alignment and the effects' columns), and the carriage travels on
Inputs that the straightness and periodic columns are normalized by."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

from openpyxl.styles import Alignment

from cmmwb.xlfuncs.locator import effects as fx
from cmmwb.xlfuncs.locator.diagnose import Diagnosis

from ..workbook.book import Book
from ..workbook.pagesetup import LINE_PT, wrapped_lines
from ..workbook.styles import FMT_COORD, FMT_MM, NUMBER_FORMAT
from ..workbook.xlref import block, cell
from .formulas import Row, alignment_formula, length_formula, point_formula


def display_unit(unit: str) -> str:
    """A unit as the workbooks spell it (µm, µrad); diagnosis.json keeps the contract's um, urad (docs/recordings.md)."""
    return unit.replace("um", "µm").replace("urad", "µrad").replace("µrµm", "µrad") if unit != "1" else unit


def travel_cells(book: Book, diag: Diagnosis, inputs: dict, sheet: str, cols: dict[str, list[int]],
                 n: int) -> dict[str, tuple[str, str]]:
    """For the chosen straightness effects (docs/recordings.md section 7): the travel of their
    carriage over the records, lo = MIN and hi = MAX of the ram coordinate columns ``cols[axis]``
    of ``sheet`` (rows 2..n+1), on Inputs; {carriage: (lo cell, hi cell)}."""
    periodic = [e for e in dict.fromkeys(e for e, _ in diag.sel_labels) if e in fx.PERIODIC]
    cars = sorted({e[2] for e, _ in diag.sel_labels if e in fx.STRAIGHTNESS} | {e[-1].upper() for e in periodic})
    if not cars:
        return {}
    wi = book.wb["Inputs"]
    r = inputs["free_row"]
    book.text(wi, r, 1, "travel of the carriages over the records (ram coordinates, mm): the straightness "
                        "polynomials P2, P3 are of s = (2 u - lo - hi)/(hi - lo); a periodic error's phase "
                        "is about (lo + hi)/2")
    book.header(wi, r + 1, 1, ["carriage", "lo_mm", "hi_mm"])
    out = {}
    for k, car in enumerate(cars):
        rr = r + 2 + k
        ranges = ",".join(block(2, c, n, 1, sheet) for c in cols[car.lower()])
        book.text(wi, rr, 1, car)
        book.formula(wi, rr, 2, f"=MIN({ranges})")
        book.formula(wi, rr, 3, f"=MAX({ranges})")
        out[car] = (cell(rr, 2, "Inputs"), cell(rr, 3, "Inputs"))
    if periodic:
        r += 3 + len(cars)
        book.text(wi, r, 1, "periodic errors (docs/diagnose.md section 6): the period found by the locator's "
                            "scan (a search, not a formula) and the point (a, b) its sensitivity is linearized at")
        book.header(wi, r + 1, 1, ["effect", "period_mm", "a0_um", "b0_um"], [
            None, "the period of the largest drop of chi-square over the scanned grid, refined; fixed here",
            "a of the fit with the period fixed (the refit's column for the period is the derivative at a0, b0)",
            "b of the fit with the period fixed"])
        for k, name in enumerate(periodic):
            c = diag.candidates[name]
            rr = r + 2 + k
            book.text(wi, rr, 1, name)
            for q, v in enumerate((c.period_mm, *c.lin_ab)):
                book.number(wi, rr, 2 + q, float(v), fmt="0.0000", computed=True)
            out["periodic:" + name[-1]] = tuple(cell(rr, 2 + q, "Inputs") for q in range(3))
            inputs.setdefault("periodic", {})[name] = out["periodic:" + name[-1]]
    return out


# -- records -------------------------------------------------------------------------------------

#: the record sheets print at this scale (percent), pages across and down: 8 pt text from 11 pt
#: cells (fitted to the page width, 40 columns printed at 4 pt)
RECORDS_SCALE = 0.75
#: the footer of a sheet printed at RECORDS_SCALE: 11 pt prints at 8.25 pt
FOOTER_PT = 11
#: the width (characters) a wrapped header of a record sheet is counted in (its numbers' width)
HEADER_WIDTH = 11

#: columns of the recordings (docs/recordings.md names them without a unit) that are in mm: their
#: headers in the workbook carry it (x1_mm ...)
LENGTH_MM_COLUMNS = frozenset({"x1", "y1", "z1", "x2", "y2", "z2", "p1x", "p1y", "p1z", "p2x", "p2y", "p2z"})
POINT_MM_COLUMNS = frozenset({"x_nom", "y_nom", "z_nom", "x", "y", "z", "px", "py", "pz"})


def shown(key: str, mm_columns) -> str:
    """The header a person reads for column ``key``: ``x1_mm`` for a coordinate of the
    recordings; an effect's design column ``name:label`` with its unit, µm of the record per unit
    of the effect (``squareness_xy: squareness_xy (µm per µrad)``, a space after the colon so that
    a narrow column wraps it); other keys carry their unit already (``residual_um``) or have none
    (``z``, ``n1x``)."""
    if key in mm_columns:
        return f"{key}_mm"
    if ":" in key:
        name = key.split(":", 1)[0]
        unit = "µm" if name == "outlier" else display_unit(fx.BY_NAME[name].unit)
        return f"{key.replace(':', ': ', 1)} (µm per {unit})"
    return key


def _input_column(book: Book, ws, r0: int, c: int, values) -> None:
    """A column of numeric input cells (styled, unlocked, validated by :meth:`Book.number`)."""
    for k, v in enumerate(values):
        book.number(ws, r0 + k, c, float(v), fmt=FMT_COORD)


def _record_sheet(book: Book, rec, sheet: str, columns: list[str], derived: list[str], notes: dict[str, str],
                  mm_columns, data: dict, texts: dict[str, list[str]],
                  row_formulas: Callable[[dict[str, str]], Iterable[tuple[str, str]]]):
    """One sheet of records, the part Records (length records) and Points (point records) share
    (docs/recordings.md section 3): the header, the recordings' ``columns`` followed by
    temperature_C, time_s, group and the extra columns of the recordings that have them, then the
    ``derived`` columns (units shown by :func:`shown` with ``mm_columns``, ``notes`` on the
    headers); the numbers ``data`` (and temperature_C, time_s) as input cells; per record its id,
    the text columns ``texts``, group and the extra columns, and the formulas ``row_formulas(L)``
    yields as (column, formula) with L the record's cell of every column.  Returns the sheet, the
    column index {key: column} and the records' :class:`Row` s."""
    ws = book.sheet(sheet)
    cols, data = list(columns), dict(data)
    for key in ("temperature_C", "time_s"):
        if getattr(rec, key) is not None:
            cols.append(key)
            data[key] = getattr(rec, key)
    if rec.group is not None:
        cols.append("group")
        texts = {**texts, "group": rec.group}
    # the recordings' own extra columns are the user's names: shown as they are, kept apart from the
    # column keys (an extra column 'd_mm' or 'http://x' is neither a derived column nor an effect's)
    extras = list(rec.extra)
    ci = {k: i + 1 for i, k in enumerate(cols)}
    xi = {k: len(cols) + i + 1 for i, k in enumerate(extras)}
    ci.update({k: len(cols) + len(extras) + i + 1 for i, k in enumerate(derived)})
    taken = {shown(h, mm_columns) for h in cols + derived}
    heads = ([shown(h, mm_columns) for h in cols] + [f"{h} (recordings)" if h in taken else h for h in extras]
             + [shown(h, mm_columns) for h in derived])
    book.header(ws, 1, 1, heads, [notes.get(h) for h in cols] + [None] * len(extras) + [notes.get(h) for h in derived])
    # the headers wrap (an effect's column is named "squareness_xy: squareness_xy (µm per µrad)"):
    # the columns are as wide as their numbers, fewer pages across
    for c in range(1, len(heads) + 1):
        cell_ = ws.cell(row=1, column=c)
        cell_.alignment = Alignment(wrap_text=True, vertical="top")
    ws.row_dimensions[1].height = LINE_PT * max(wrapped_lines(t, HEADER_WIDTH) for t in heads) + 2
    for k, v in data.items():
        _input_column(book, ws, 2, ci[k], v)
    texts = {"id": rec.ids, **texts}
    rows = []
    for a in range(rec.n):
        r = a + 2
        rows.append(Row(sheet, r, ci))
        for k, v in texts.items():
            book.text(ws, r, ci[k], v[a])
        for k, v in rec.extra.items():
            book.text(ws, r, xi[k], v[a])
        L = {k: cell(r, ci[k]) for k in ci}
        for k, f in row_formulas(L):
            book.formula(ws, r, ci[k], f, fmt=FMT_MM if k.endswith("_mm") or k.endswith("_um") else NUMBER_FORMAT)
    ws.freeze_panes = "B2"
    # portrait: 60 records a page; the ids repeated on every page across
    book.print_setup(ws, min_scale=RECORDS_SCALE, landscape=False, title_columns="A:A", footer_pt=FOOTER_PT)
    return ws, ci, rows


def _length_formulas(L: dict[str, str]) -> Iterator[tuple[str, str]]:
    """A length record's row: d = X2 - X1 and its length, the direction n_a, the ram positions
    X - p of both ends (Forbes 2025 section 5.3), the residual in µm."""
    for ax in "xyz":
        yield f"d{ax}_mm", f"={L[ax + '2']}-{L[ax + '1']}"
    yield "d_mm", f"=SQRT({L['dx_mm']}^2+{L['dy_mm']}^2+{L['dz_mm']}^2)"
    for ax in "xyz":
        yield f"na{ax}", f"={L['d' + ax + '_mm']}/{L['d_mm']}"
        for e in "12":
            yield f"u{ax}{e}_mm", f"={L[ax + e]}-{L['p' + e + ax]}"
    yield "residual_um", f"=({L['measured_mm']}-{L['reference_mm']})*1000"


def length_records(book: Book, diag: Diagnosis, inputs: dict):
    prep = diag.prep
    rec, D = prep.rec, prep.design
    cols: list[str] = ["id", "x1", "y1", "z1", "x2", "y2", "z2", "reference_mm", "measured_mm"]
    if D.N1 is not None:
        cols += ["n1x", "n1y", "n1z", "n2x", "n2y", "n2z"]
    cols += ["p1x", "p1y", "p1z", "p2x", "p2y", "p2z", "probe1", "probe2"]
    derived = ["dx_mm", "dy_mm", "dz_mm", "d_mm", "nax", "nay", "naz", "ux1_mm", "uy1_mm", "uz1_mm",
               "ux2_mm", "uy2_mm", "uz2_mm", "residual_um", "u_um", "z"]
    chosen_cols = [f"{e}:{l}" for e, l in diag.sel_labels if e != "alignment"]
    after = ["fitted_um", "residual_after_um", "z_after"]
    notes = {"residual_um": "r = (measured - reference) * 1000: the simulation predicts 0",
             "u_um": "standard uncertainty of the residual under the simulation: sqrt(C_aa) (Cov sheet)",
             "z": "standardized residual r/u", "nax": "n_a = (x2 - x1)/d, the direction of the length",
             "ux1_mm": "ram position x - p (Forbes 2025 section 5.3, multiple probes)",
             "fitted_um": "sum of the chosen effects: row of X times b (GLS sheet)",
             "residual_after_um": "r - fitted", "z_after": "(r - fitted)/u"}
    P1, P2 = D.P1, D.P2
    pid = D.probe_ids
    data = {"x1": rec.X1_mm[:, 0], "y1": rec.X1_mm[:, 1], "z1": rec.X1_mm[:, 2],
            "x2": rec.X2_mm[:, 0], "y2": rec.X2_mm[:, 1], "z2": rec.X2_mm[:, 2],
            "reference_mm": rec.reference_mm, "measured_mm": rec.measured_mm,
            "p1x": P1[:, 0], "p1y": P1[:, 1], "p1z": P1[:, 2], "p2x": P2[:, 0], "p2y": P2[:, 1], "p2z": P2[:, 2]}
    if D.N1 is not None:
        for e, N in (("1", rec.N1), ("2", rec.N2)):
            for a, ax in enumerate("xyz"):
                data[f"n{e}{ax}"] = N[:, a]
    ws, ci, rows = _record_sheet(book, rec, "Records", cols, derived + chosen_cols + after, notes, LENGTH_MM_COLUMNS,
                                 data, {"probe1": [pid[k] for k in D.k1], "probe2": [pid[k] for k in D.k2]},
                                 _length_formulas)
    obs = {"sheet": "Records", "rows": [R.row for R in rows], "ci": ci, "chosen_cols": chosen_cols,
           "first_X": ci[chosen_cols[0]] if chosen_cols else None, "n_align": 0, "row_of_obs": rows}
    travel = travel_cells(book, diag, inputs, "Records",
                           {ax: [ci[f"u{ax}1_mm"], ci[f"u{ax}2_mm"]] for ax in "xyz"}, rec.n)
    # the middle of the probed positions along each axis (thermal gradient, section 7)
    pos = {ax: ",".join(block(2, ci[f"{ax}{e}"], rec.n, 1, "Records") for e in "12") for ax in "xyz"}
    travel.update({f"pos_{ax}": (f"MIN({r})", f"MAX({r})") for ax, r in pos.items()})
    for label in chosen_cols:
        for a, R in enumerate(rows):
            _design_cell(book, ws, R.row, ci[label], label, rec.ids[a],
                         lambda name, par: length_formula(name, par, R, inputs["probe_cells"], travel))
    return rows, obs


def _value_or_formula(book: Book, ws, r: int, c: int, f: str | float) -> None:
    if isinstance(f, str):
        book.formula(ws, r, c, f, fmt="0.000000E+00")
    else:
        ws.cell(row=r, column=c).value = float(f)


def _design_cell(book: Book, ws, r: int, c: int, label: str, outlier_key: str,
                 formula: Callable[[str, str], str]) -> None:
    """The cell of the chosen effect ``label`` (``name:parameter``) on a record's row: an outlier
    left out (docs/recordings.md section 7) has its own mean-shift column, 1 on the row of the
    record (length) or coordinate (point) ``outlier_key`` names and 0 elsewhere; any other effect
    is the formula of the row ``formula(name, parameter)`` gives (:mod:`.formulas`)."""
    name, par = label.split(":", 1)
    _value_or_formula(book, ws, r, c, (1.0 if par == outlier_key else 0.0) if name == "outlier" else formula(name, par))


def point_records(book: Book, diag: Diagnosis, inputs: dict):
    prep = diag.prep
    rec, D = prep.rec, prep.design
    cols = ["id", "x_nom", "y_nom", "z_nom", "x", "y", "z"]
    if rec.N is not None:
        cols += ["nx", "ny", "nz"]
    cols += ["px", "py", "pz", "probe"]
    derived = ["yx_mm", "yy_mm", "yz_mm", "ux_mm", "uy_mm", "uz_mm"]
    notes = {"yx_mm": "nominal point in machine coordinates y = R0 x_nom + t0 (Inputs)",
             "ux_mm": "ram position y - p"}
    data = {"x_nom": rec.X_nom_mm[:, 0], "y_nom": rec.X_nom_mm[:, 1], "z_nom": rec.X_nom_mm[:, 2],
            "x": rec.X_mm[:, 0], "y": rec.X_mm[:, 1], "z": rec.X_mm[:, 2],
            "px": D.P[:, 0], "py": D.P[:, 1], "pz": D.P[:, 2]}
    if rec.N is not None:
        for a, ax in enumerate("xyz"):
            data[f"n{ax}"] = rec.N[:, a]
    R0, t0 = inputs["R0"], inputs["t0"]

    def point_formulas(L: dict[str, str]) -> Iterator[tuple[str, str]]:
        """y = R0 x_nom + t0, the nominal point in machine coordinates, and the ram position y - p."""
        for a, ax in enumerate("xyz"):
            yield (f"y{ax}_mm", f"={R0.cell(a, 0)}*{L['x_nom']}+{R0.cell(a, 1)}*{L['y_nom']}"
                                f"+{R0.cell(a, 2)}*{L['z_nom']}+{t0.cell(a, 0)}")
            yield f"u{ax}_mm", f"={L['y' + ax + '_mm']}-{L['p' + ax]}"

    _, ci, prow = _record_sheet(book, rec, "Points", cols, derived, notes, POINT_MM_COLUMNS, data,
                                {"probe": [D.probe_ids[k] for k in D.k]}, point_formulas)
    # centroid of the nominal points on Inputs
    wi = book.wb["Inputs"]
    crow = inputs["c_row"]
    centroid = {}
    for a, ax in enumerate("xyz"):
        book.text(wi, crow, 1 + 2 * a, f"c{ax}_mm")
        book.formula(wi, crow, 2 + 2 * a, f"=AVERAGE({block(2, ci[f'y{ax}_mm'], rec.n, 1, 'Points')})")
        centroid[ax] = cell(crow, 2 + 2 * a, "Inputs")
    # one row per coordinate
    wc = book.sheet("Coords")
    dims = D.dims
    al = [l for e, l in diag.sel_labels if e == "alignment"]
    chosen_cols = [f"{e}:{l}" for e, l in diag.sel_labels if e != "alignment"]
    header = ["point", "axis", "residual_um", "u_um", "z"] + al + chosen_cols + \
             ["fitted_um", "residual_after_um", "z_after", "baseline_um", "residual_before_um"]
    cc = {k: i + 1 for i, k in enumerate(header)}
    book.header(wc, 1, 1, [shown(h, ()) for h in header], [
        None, None, "r = (x - y) * 1000 (y: nominal in machine coordinates)",
        "standard uncertainty of the residual after the baseline alignment: sqrt(C_qq - a_q Ma^-1 a_q')",
        "(r - baseline)/u", *["alignment (nuisance): translation µm, small rotation µrad about the centroid"] * len(al),
        *[None] * len(chosen_cols), "row of X (effects) times b", "r - alignment - fitted",
        "(r - alignment - fitted)/u", "alignment of the baseline fit (alignment columns times b0)",
        "r - baseline"])
    travel = travel_cells(book, diag, inputs, "Points", {ax: [ci[f"u{ax}_mm"]] for ax in "xyz"}, rec.n)
    rows = []
    for i in range(rec.n):
        P = prow[i]
        for a in range(dims):
            r = 2 + dims * i + a
            ax = "xyz"[a]
            R = Row("Coords", r, cc)
            rows.append(R)
            book.text(wc, r, cc["point"], rec.ids[i])
            book.text(wc, r, cc["axis"], ax)
            book.formula(wc, r, cc["residual_um"], f"=({P[ax]}-{P['y' + ax + '_mm']})*1000")
            for lab in al:
                _value_or_formula(book, wc, r, cc[lab], alignment_formula(lab, a, P, centroid))
            for label in chosen_cols:
                _design_cell(book, wc, r, cc[label], label, f"{rec.ids[i]}.{ax}",
                             lambda name, par: point_formula(name, par, a, P, centroid, inputs["probe_cells"], travel))
    wc.freeze_panes = "C2"
    obs = {"sheet": "Coords", "rows": [R.row for R in rows], "ci": cc, "chosen_cols": chosen_cols,
           "first_X": cc[al[0]] if al else cc.get(chosen_cols[0]) if chosen_cols else None,
           "n_align": len(al), "row_of_obs": rows}
    return rows, obs
