"""The report page a laboratory signs (the ``Summary`` sheet): the layout CMM inspection reports
share, written from records, for any book (the task kinds, a diagnosis, a calibration, a
validation).

* a header: the task, its inputs' identity (SHA-256), the build time and version, the
  ``[report]`` fields (lab, operator, CMM, part, job id, notes): ``(label, text)`` lines;
* one block per result (:class:`PageRow`): the characteristic, its nominal value and lower and
  upper limits, the value, its deviation from the nominal, U, p_c, the decision rule's outcome
  and the conformity statement, a tolerance bar (value ± U drawn in its own tolerance, the
  limits at ±1 as on the Decision sheet); below it the rounded result statement (GUM 7.2.6)
  with the coverage probability of its k (GUM G.1.3, G.3.2: live, k and ν_eff are cells), and
  what the value and U rest on, in words (fitted, typed, nominal geometry; said once for a run of
  results that rest on the same, on each page);
* verdicts besides the decisions (:class:`generator.quantities.Verdict`: the MPE check);
* the decision rule in words.

Every number is a live formula of the cells the rows name (:class:`Live`: a formula
expression and the value the core computed, cached); every text a person or a task file gave
(labels, file names, report fields) is a text cell, and formulas refer to those cells, never
contain the text.  The page prints on as many landscape A4 pages as it needs, scaled to the
page width at no less than :data:`MIN_SCALE` (11 pt text at 8 pt or more), its table header
repeated on every page.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, field
from typing import Any, Sequence

from openpyxl.chart import Reference
from openpyxl.styles import Alignment, Font

from cmmwb.xlfuncs.statement import decimals_for

from ..quantities import Quantity, Verdict
from .book import Book, ChartSeries
from .styles import BOX, HEADER_FONT, TITLE_FONT
from .xlref import cell, col, norm_s_dist

SHEET = "Summary"
#: the table's columns: header -> width (characters); C: header -> number of the column
COLUMNS = {"characteristic": 16, "nominal": 11, "lower limit": 11, "upper limit": 11, "value": 13, "deviation": 10,
           "U": 11, "p_c": 7, "decision": 17, "conformity": 22, "tolerance bar": 13}
C = {name: j + 1 for j, name in enumerate(COLUMNS)}
LAST = len(COLUMNS)
#: the columns right of the printed page that hold what the formulas and bars read
DATA = {name: LAST + 2 + j for j, name in enumerate(
    ["symbol", "k", "nu_eff", "p_cov", "bar_x1", "bar_x2", "bar_y1", "bar_y2", "y", "y_mid", "lsl_x1", "lsl_x2",
     "usl_x1", "usl_x2", "lim_y1", "lim_y2", "al_x1", "al_x2", "au_x1", "au_x2", "acc_y1", "acc_y2"])}
TEXT_WIDTH = 112        #: characters of a wrapped line below a row (columns A-J)
MIN_SCALE = 0.75        #: the page is scaled to its width: at least this with LibreOffice's widest font
BAR_RANGE = 2.0         #: the bar shows -2 ... +2 in units of half the tolerance; beyond: at the edge
NOTE_FONT = Font(italic=True)
ROW_PT = 15             #: the height of every row (points), so that the pages can be counted
#: rows on one printed page: A4 landscape, 17.9 cm between the margins, the page scaled to the
#: width of COLUMNS as LibreOffice prints them (0.26 cm per character: scale 0.76), less a margin
ROWS_PER_PAGE = 42


def _height(row: "PageRow", same: bool = False) -> int:
    """The rows a result's block takes: its numbers, its statement, its source lines (none when
    ``same`` as the block above)."""
    return 2 + (0 if same else sum(len(textwrap.wrap(t, TEXT_WIDTH, subsequent_indent="   ")) for t in row.source))


@dataclass(frozen=True)
class Live:
    """A value the page shows live: ``ref``, a formula expression (no ``=``; cell references,
    defined names, numbers) and ``value``, what the core computed (cached in the file)."""

    ref: str
    value: Any


@dataclass(frozen=True)
class PageRow:
    """One result on the page.  ``value``, ``U`` (in the record's U_unit), ``k`` and ``nu_eff``
    (None: ∞) give the rounded statement; ``nominal``, ``lsl``, ``usl``, ``p_c``, ``decision``
    (the rule's outcome), ``conformity`` (what value and U prove) are shown where given;
    ``decision_note`` a second line under the decision (the rule's name), ``conformity_note``
    under the conformity (the zone); ``note`` the decision column's text when there is no
    decision (``no tolerance given``); ``bar``: the normalised positions (``y``, ``y_minus``,
    ``y_plus``, ``lsl``, ``usl``, ``a_l``, ``a_u``) of the tolerance bar; ``source``: what the
    value and U rest on, in words (lines)."""

    quantity: Quantity
    value: Live
    U: Live
    k: Live
    nu_eff: Live | None = None
    nominal: Live | None = None
    lsl: Live | None = None
    usl: Live | None = None
    p_c: Live | None = None
    decision: Live | None = None
    decision_note: Live | str | None = None
    conformity: Live | None = None
    conformity_note: Live | str | None = None
    note: str | None = None
    bar: dict[str, Live] | None = None
    source: Sequence[str] = field(default_factory=tuple)


@dataclass(frozen=True)
class PageHeader:
    """The page's title and header lines ((label, text): the task, its files' SHA-256, the build,
    the report fields), the decision rule in words (None: no decisions) and the notes under the
    table."""

    title: str
    lines: Sequence[tuple[str, str]]
    rule: str | None = None
    notes: Sequence[str] = ()


def write_report_page(book: Book, header: PageHeader, rows: Sequence[PageRow], verdicts: Sequence[Verdict] = (),
                      *, more: int = 0, sheet: str = SHEET) -> None:
    """The report page ``sheet`` of ``book``.  ``more``: results not listed (see Results)."""
    ws = book.sheet(sheet)
    book.text(ws, 1, 1, header.title, font=TITLE_FONT)
    r = 2
    for label, text in header.lines:
        book.text(ws, r, 1, label, font=HEADER_FONT)
        for part in textwrap.wrap(str(text), TEXT_WIDTH - 20) or [""]:
            book.text(ws, r, 2, part)
            r += 1
    if header.rule:
        book.text(ws, r, 1, "decision rule", font=HEADER_FONT)
        for part in textwrap.wrap(header.rule, TEXT_WIDTH - 20):
            book.text(ws, r, 2, part)
            r += 1
    r += 1
    for v in verdicts:
        r = _verdict(book, ws, r, v)
    if verdicts:
        r += 1
    book.text(ws, r, 1, "Nominal, limits and deviation are in the unit of the value; U in the unit shown.",
              font=NOTE_FONT)
    head = r + 1
    book.header(ws, head, 1, list(COLUMNS), notes=[
        "the result (a label of the task)", "nominal value (the task's, or the tolerance's centre), in the unit of "
        "the value", "lower specification limit, in the unit of the value", "upper specification limit",
        "the value decided on (measured, typed, or the task's own: see the line 'value:' below the row)",
        "value - nominal", "expanded uncertainty U = k·u", "probability of conformance (JCGM 106:2012, 7.3-7.4)",
        "the decision rule's outcome, under the rule named below it",
        "what the value and U prove whatever the rule (ISO 14253-1:2017, 5.2, 5.3)",
        "value ± U (blue) against the specification limits (red) and the acceptance limits (green), "
        "in units of half the tolerance (limits at ±1; one-sided: see the Decision sheet)"])
    for name, width in COLUMNS.items():
        ws.column_dimensions[col(C[name])].width = width
    r = head + 1
    breaks = []
    used = r - 1                     # rows on the current printed page
    previous: Sequence[str] = ()
    for row in rows:
        # what the value and U rest on, said once for a run of results that share it (per page)
        same = tuple(row.source) == tuple(previous)
        height = _height(row, same)
        if used + height > ROWS_PER_PAGE:       # a block is never split across pages
            breaks.append(r)
            used = 1                             # the repeated header row
            same = False
            height = _height(row, same)
        previous = row.source
        r = _row(book, ws, r, row, same)
        used += height
    if more:
        book.text(ws, r, 1, f"... and {more} more results: see the Results sheet.", font=NOTE_FONT)
        r += 1
    r += 1
    for note in header.notes:
        for part in textwrap.wrap(note, TEXT_WIDTH):
            book.text(ws, r, 1, part, font=NOTE_FONT)
            r += 1
    # scaled to the page width: the columns (COLUMNS, 142 characters) print at 0.75 or more
    for row_number in range(1, r + 1):
        ws.row_dimensions[row_number].height = ROW_PT
    book.print_setup(ws, landscape=True, title_rows=(head, head), fit_widths=False, area=f"A1:{col(LAST)}{r}",
                     row_breaks=breaks, footer_pt=11)


def _verdict(book: Book, ws, r: int, v: Verdict) -> int:
    book.text(ws, r, 1, v.label, font=HEADER_FONT)
    value = f"{v.value_cell}" if v.value_cell else repr(float(v.value))
    book.text(ws, r, 2, "value")
    book.formula(ws, r, 3, f"={value}", fmt="0.0000", value=float(v.value))
    book.text(ws, r, 4, "limit")
    book.text(ws, r, 5, v.limit)
    if v.verdict_cell:
        book.formula(ws, r, 7, f"={v.verdict_cell}", fmt=None, value=v.verdict)
    else:
        book.text(ws, r, 7, v.verdict)
    ws.cell(row=r, column=7).font = HEADER_FONT
    r += 1
    for part in textwrap.wrap(v.rule, TEXT_WIDTH - 20):
        book.text(ws, r, 2, part, font=NOTE_FONT)
        r += 1
    return r


def _number_format(decimals: int, unit: str) -> str:
    body = "0" + ("." + "0" * decimals if decimals > 0 else "")
    return f'{body}" {unit}"' if unit else body


def _fitting(decimals: int, values: Sequence[float], unit: str, width: int) -> int:
    """The decimals (at most ``decimals``) with which every value, its sign and ``unit`` fit a
    column ``width`` characters wide: never ``###``; the statement below the row keeps the
    rounding of GUM 7.2.6."""
    whole = max((len(str(int(abs(v)))) + (v < 0) for v in values if math.isfinite(v)), default=1)
    room = width - 2 - whole - (len(unit) + 1 if unit else 0) - 1
    return max(0, min(decimals, room))


def _put(book: Book, ws, r: int, c: int, live: Live | str | None, fmt: str | None, *, dash: str = "—"
         ) -> str | None:
    """A live cell (a text, or a dash); returns its address."""
    if live is None:
        book.text(ws, r, c, dash).alignment = Alignment(horizontal="center")
        return None
    if isinstance(live, str):
        book.text(ws, r, c, live)
        return cell(r, c, absolute=False)
    value = live.value
    book.formula(ws, r, c, f"={live.ref}", fmt=fmt, value=value)
    return cell(r, c, absolute=False)


def _row(book: Book, ws, r: int, row: PageRow, same: bool = False) -> int:
    q = row.quantity
    at = {name: cell(r, j, absolute=False) for name, j in {**C, **DATA}.items()}
    U_now = float(row.U.value)
    try:
        dec_U = decimals_for(U_now)
    except Exception:       # U = 0: nothing to round (the caller lists only U > 0)
        dec_U = 1
    shift = round(math.log10(q.unit_ratio)) if q.unit_ratio > 0 else 0
    dec_value = max(dec_U + shift, 0)
    numbers = [float(x.value) for x in (row.value, row.nominal, row.lsl, row.usl) if isinstance(x, Live)]
    fmt_value = _number_format(_fitting(dec_value, numbers, q.unit, COLUMNS["value"]), q.unit)
    dec_fit = _fitting(max(dec_U, 0), [U_now], q.U_unit, COLUMNS["U"])
    # U keeps its two significant digits (GUM 7.2.6): in powers of ten when its decimals do not fit
    fmt_U = _number_format(dec_fit, q.U_unit) if dec_fit == max(dec_U, 0) else f'0.0E+00" {q.U_unit}"'

    book.text(ws, r, C["characteristic"], q.label, font=HEADER_FONT)
    fmt_plain = _number_format(_fitting(dec_value, numbers + [-abs(n) for n in numbers], "",
                                        min(COLUMNS["nominal"], COLUMNS["deviation"])), "")
    for name in ("nominal", "lsl", "usl"):
        column = {"nominal": "nominal", "lsl": "lower limit", "usl": "upper limit"}[name]
        _put(book, ws, r, C[column], getattr(row, name), fmt_plain)
    _put(book, ws, r, C["value"], row.value, fmt_value)
    if row.nominal is not None:
        dev = float(row.value.value) - float(row.nominal.value)
        book.formula(ws, r, C["deviation"], f"={at['value']}-{at['nominal']}", fmt="+" + fmt_plain + ";-" + fmt_plain
                     + ";" + fmt_plain, value=dev)
    else:
        book.text(ws, r, C["deviation"], "—").alignment = Alignment(horizontal="center")
    _put(book, ws, r, C["U"], row.U, fmt_U)
    _put(book, ws, r, C["p_c"], row.p_c, "0.0000")
    if row.decision is not None:
        _put(book, ws, r, C["decision"], row.decision, None)
        ws.cell(row=r, column=C["decision"]).font = HEADER_FONT
        if row.decision_note is not None:
            _put(book, ws, r + 1, C["decision"], row.decision_note, None)
    else:
        book.text(ws, r, C["decision"], row.note or "no tolerance given", font=NOTE_FONT)
    if row.conformity is not None:
        _put(book, ws, r, C["conformity"], row.conformity, None)
        ws.cell(row=r, column=C["conformity"]).font = HEADER_FONT
        if row.conformity_note is not None:
            _put(book, ws, r + 1, C["conformity"], row.conformity_note, None)
    for name in ("value", "U", "p_c", "decision", "conformity"):
        ws.cell(row=r, column=C[name]).border = BOX
    # the numbers of the statement: symbol (text), k, ν_eff, coverage probability
    book.text(ws, r, DATA["symbol"], q.symbol)
    _put(book, ws, r, DATA["k"], row.k, "0.000")
    if row.nu_eff is not None:
        _put(book, ws, r, DATA["nu_eff"], row.nu_eff, "0.00")
        nu = float(row.nu_eff.value)
    else:
        book.text(ws, r, DATA["nu_eff"], "∞")
        nu = math.inf
    from cmmwb.xlfuncs.dof import coverage_probability

    k, nu_eff = at["k"], at["nu_eff"]
    book.formula(ws, r, DATA["p_cov"], f"=IF(ISNUMBER({nu_eff}),1-TDIST({k},INT({nu_eff}),2),2*{norm_s_dist(k)}-1)",
                 fmt="0.0000", value=coverage_probability(float(row.k.value), nu))
    # the rounded statement (GUM 7.2.6): U to two significant digits, the value to its decimal place
    U, y = at["U"], at["value"]
    Ur = f"ROUND({U},1-INT(LOG10({U})))"
    dU = f"(1-INT(LOG10({Ur})))"
    k_text = f'IF(ABS({k}-ROUND({k},0))<1E-9,FIXED({k},0,TRUE),FIXED({k},2,TRUE))'
    vu, Uu = (f" {q.unit}" if q.unit else ""), (f" {q.U_unit}" if q.U_unit else "")   # dimensionless: no space
    text = (f'={at["symbol"]}&" = "&FIXED({y},{dU}+{shift},TRUE)&"{vu}, U = "&FIXED({Ur},{dU},TRUE)&'
            f'"{Uu} (k = "&{k_text}&", coverage probability ≈ "&FIXED(100*{at["p_cov"]},2,TRUE)&" %)"')
    from cmmwb.xlfuncs.statement import statement

    book.formula(ws, r + 1, 1, text, fmt=None, value=statement(
        q.symbol, float(row.value.value), q.unit, U_now, q.U_unit, float(row.k.value), nu=nu, unit_ratio=q.unit_ratio),
        note="the rounded result statement (GUM 7.2.6) of the cells of this row; the coverage probability of "
             "k with ν_eff (GUM G.1.3, G.3.2)")
    lines: list[str] = []
    for text_line in () if same else row.source:
        lines += textwrap.wrap(text_line, TEXT_WIDTH, subsequent_indent="   ")
    for j, line in enumerate(lines):
        book.text(ws, r + 2 + j, 1, line, font=NOTE_FONT)
    height = 2 + len(lines)
    if row.bar is not None:
        _bar(book, ws, r, height, row.bar)
    return r + height


def _bar(book: Book, ws, r: int, height: int, bar: dict[str, Live]) -> None:
    """The tolerance bar of the block of rows r ... r + height - 1: its data right of the page."""
    def clamp(x: str) -> str:
        return f"MAX(-{BAR_RANGE:g},MIN({BAR_RANGE:g},{x}))"

    def put(name: str, expr: str, value: float) -> None:
        book.formula(ws, r, DATA[name], f"={expr}", fmt="0.000", value=max(-BAR_RANGE, min(BAR_RANGE, value)))

    def const(name: str, v: float) -> None:
        ws.cell(row=r, column=DATA[name]).value = v

    put("bar_x1", clamp(bar["y_minus"].ref), float(bar["y_minus"].value))
    put("bar_x2", clamp(bar["y_plus"].ref), float(bar["y_plus"].value))
    put("y", clamp(bar["y"].ref), float(bar["y"].value))
    for name, v in (("bar_y1", 0.5), ("bar_y2", 0.5), ("y_mid", 0.5), ("lim_y1", 0.0), ("lim_y2", 1.0),
                    ("acc_y1", 0.15), ("acc_y2", 0.85)):
        const(name, v)

    def ref(a: str, b: str) -> Reference:
        return Reference(ws, min_col=DATA[a], max_col=DATA[b], min_row=r, max_row=r)

    series = []
    for key, x1, x2, y1, y2, colour, dash in (("lsl", "lsl_x1", "lsl_x2", "lim_y1", "lim_y2", "D62728", "solid"),
                                              ("usl", "usl_x1", "usl_x2", "lim_y1", "lim_y2", "D62728", "solid"),
                                              ("a_l", "al_x1", "al_x2", "acc_y1", "acc_y2", "2CA02C", "dash"),
                                              ("a_u", "au_x1", "au_x2", "acc_y1", "acc_y2", "2CA02C", "dash")):
        if key not in bar:
            continue
        put(x1, clamp(bar[key].ref), float(bar[key].value))
        put(x2, clamp(bar[key].ref), float(bar[key].value))
        series.append(ChartSeries(key, ref(x1, x2), ref(y1, y2), markers=False, colour=colour, dash=dash))
    series.append(ChartSeries("value ± U", ref("bar_x1", "bar_x2"), ref("bar_y1", "bar_y2"), markers=False,
                              colour="1F77B4", dash="solid", bold=True))
    series.append(ChartSeries("value", ref("y", "y"), ref("y_mid", "y_mid"), colour="000000"))
    width_cm = 0.24 * COLUMNS["tolerance bar"]
    Book.tolerance_bar(ws, f"{col(C['tolerance bar'])}{r}", series, width=width_cm,
                       height=max(1.2, 0.5 * height), x_range=(-BAR_RANGE, BAR_RANGE))
