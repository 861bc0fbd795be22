"""The index of ``cmmwb demo``: one entry per workbook the demo writes (:data:`ITEMS`: which paper's
result or which lab question it shows, and the sheet to look at first), and the page written from
it beside the books (:func:`write_index`: ``index.html`` to open in a browser, ``index.md`` to read
as text), with the command that rebuilds each book.

A new demo item is one more :class:`DemoItem` in :data:`ITEMS`; ``tests/cli/test_documented_commands.py``
fails, naming the book, while a workbook the demo writes has no entry (or an entry names a book
or a sheet the demo does not write).  Books are described as they are: the sheet names are those
of today's workbooks.
"""

from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path

from . import __version__
from .workbook.atomic import Staging


@dataclass(frozen=True)
class DemoItem:
    """One workbook of the demo, described for a person who opens the demo folder."""

    book: str             # its path in the demo folder (``budget/knuckle.xlsx``)
    shows: str            # which paper's result it reproduces, or what it is an example of
    first_sheet: str      # the sheet to look at first
    look_for: str         # what that sheet shows (other sheets it names in `backticks`)
    question: str = ""    # the lab question it answers, if it is the demo's answer to one
    group: str = ""       # the heading it is listed under (default: its folder's)


#: the headings of the index, by the demo's folders (a book's ``group`` may name another)
GROUPS = {
    "characteristic": "A drawing's characteristics, decided against their tolerances",
    "pointcloud": "Forbes 2025: distances measured on a step gauge, the six influence factors",
    "budget": "Wojtyła/Płowucha 2023: budgets from the E_L,MPE formula",
    "feature": "Forbes 2022 + 2025: fitted features under the six-factor V_X, and Tables 1-8 of partial features",
    "diagnose": "The mismatch locator: recordings against the machine's model",
    "validate": "The loop a lab runs: recordings -> calibrate -> validate on calibrated workpieces (ISO/TS 15530-4)",
}

_STEP = ("26 steps along x, {probes}; Forbes 2025 Table 3's {mpe} parameters")
_F22 = "Forbes 2022 Table {n}: {what}"
_PLANNING = "Planning"
_PLANNING_LOOK = "the table's rows of s(a); the u of the points actually fitted are on `Budget`"

#: one entry per workbook ``cmmwb demo`` writes, in the order the index lists them within a group
ITEMS: tuple[DemoItem, ...] = (
    DemoItem("characteristic/characteristic_plate.xlsx",
             "a simulated plate 100 x 80 x 10 mm with two holes (not from a paper): sizes, distance, "
             "flatness, straightness, roundness, cylindricity (least squares and minimum zone), "
             "perpendicularity, parallelism and positions at MMC against datums A|B|C, each with u "
             "under the six-factor V_X and decided against the drawing-like tolerances of its task",
             "Summary",
             "each characteristic with its limits, value and U, the decision under the rule named there "
             "(conforms, does not conform, cannot be decided), what value and U prove (conformity, "
             "non-conformity or neither proven) and the rounded statement; the `Decision` sheet shows "
             "how each decision follows from the limits",
             question="Does this part conform to its drawing?"),
    DemoItem("characteristic/housing_W.xlsx",
             "an aluminium gearbox housing on the shop floor at 23.5 °C (not from a paper; docs/workpiece.md): "
             "two bearing bores 400 mm apart, the CMM correcting to 20 °C with the nominal alpha, "
             "u(alpha) = 1e-6/K and u(T) = 0.3 K in the task's [workpiece]: the seventh factor W, the part's "
             "own expansion, beside the machine's six",
             "Characteristics",
             "u of the 400 mm bore distance, 3.15 µm, most of it the part's temperature (u_W = 3.11 µm: "
             "1.40 from alpha, 2.77 from T, in the JSON's components and the factor chart), against a few "
             "tenths of a µm for the diameters' W and none for the flatness; the `Inputs` sheet holds the "
             "workpiece inputs and u(eps)"),
    DemoItem("pointcloud/stepgauge_I_MPE1.xlsx",
             "Forbes 2025 section 7, Table 4 and Figures 4-7: " + _STEP.format(probes="one probe (scenario I)",
                                                                             mpe="MPE1"),
             "Budget",
             "u of each distance and its six components (R, PQ, S, ET, ER, P) in the layout of Table 4, "
             "with the chart of Figures 6/7",
             question="How uncertain is each measured distance, and which influence factor dominates?"),
    DemoItem("pointcloud/stepgauge_I_MPE2.xlsx",
             "Forbes 2025 section 7, Table 4 and Figures 4-7: " + _STEP.format(probes="one probe (scenario I)",
                                                                             mpe="MPE2"),
             "MPE",
             "C(d) of eq. (36) against the MPE statement: with the MPE2 parameters C_max exceeds 1 (the "
             "model violates the MPE), and the sheet gives the rescaling that conforms",
             question="Is my machine's uncertainty model consistent with its MPE specification?"),
    DemoItem("pointcloud/stepgauge_II_MPE1.xlsx",
             "Forbes 2025 section 7, Table 5 and Figures 4-7: " + _STEP.format(
                 probes="left and right faces probed with two probes (scenario II)", mpe="MPE1"),
             "Budget", "Table 5's distances and their components, with the chart of Figures 6/7"),
    DemoItem("pointcloud/stepgauge_II_MPE2.xlsx",
             "Forbes 2025 section 7, Table 5 and Figures 4-7: " + _STEP.format(
                 probes="left and right faces probed with two probes (scenario II)", mpe="MPE2"),
             "Budget", "Table 5's distances and their components, with the chart of Figures 6/7"),
    DemoItem("budget/knuckle.xlsx",
             "Wojtyła/Płowucha 2023 section 4, Tables 1-9: the steering knuckle, positions of four "
             "hole axes and distances in the datum system, from E_L,MPE = 3 + L/250 µm",
             "S4_position",
             "the budget of hole S4's position in the paper's layout (input, value, ∂l/∂x_i, u_i, "
             "contribution, u_c, U); every characteristic has such a sheet",
             question="How large is a position's uncertainty from the machine's MPE alone (no error model)?"),
    DemoItem("feature/cylinder_bore.xlsx",
             "a bore of diameter 50 mm, 4 rings of 12 points, 50 mm stylus, under the full six-factor "
             "point-cloud model (Forbes 2025 Table 3, MPE1)",
             "Budget", "how each influence factor reaches the axis position, tilt and radius",
             question="How do the machine's errors reach a fitted feature's parameters?"),
    DemoItem("feature/plane_face.xlsx",
             "a milled face measured with two styli, points from a CSV file, one edge point "
             "de-weighted (Forbes 2022 eq. (11)), full six-factor model",
             "Budget", "u of the plane's height and tilts, factor by factor"),
    DemoItem("feature/table1_circle_arc.xlsx", _F22.format(n=1, what="arc of a circle, 2α = 360 ... 20 deg"),
             _PLANNING, _PLANNING_LOOK),
    DemoItem("feature/table2_sphere_cap.xlsx", _F22.format(n=2, what="cap of a sphere, γ = 180 ... 10 deg"),
             _PLANNING, _PLANNING_LOOK),
    DemoItem("feature/table3_sphere_band.xlsx",
             _F22.format(n=3, what="equatorial band of a sphere, β = 90 ... 10 deg"), _PLANNING, _PLANNING_LOOK),
    DemoItem("feature/table4_sphere_segment.xlsx",
             _F22.format(n=4, what="longitudinal segment of a sphere"), _PLANNING, _PLANNING_LOOK),
    DemoItem("feature/table5_cylinder_patch.xlsx", _F22.format(n=5, what="cylindrical patch"),
             _PLANNING, _PLANNING_LOOK),
    DemoItem("feature/table6_cone_angle.xlsx",
             _F22.format(n=6, what="cone frustum of cone angle φ = 0 ... 70 deg"), _PLANNING, _PLANNING_LOOK),
    DemoItem("feature/table7_cone_arc.xlsx", _F22.format(n=7, what="arc segment of a cone, φ = 45 deg"),
             _PLANNING, _PLANNING_LOOK),
    DemoItem("feature/table8_sphere_six.xlsx",
             _F22.format(n=8, what="sphere, six-point strategy (equator and both poles)"),
             "Results", "u of the centre and radius: the column s|X6 of Table 8 (σ_R = 1 µm)"),
    DemoItem("feature/table8_sphere_five.xlsx",
             _F22.format(n=8, what="sphere, five-point strategy (equator and north pole)"),
             "Results", "u of the centre and radius: the column s|X5 of Table 8 (σ_R = 1 µm)"),
    DemoItem("feature/table8_sphere_nine.xlsx",
             _F22.format(n=8, what="sphere, nine-point strategy (equator, a ring at 75.95 deg, north pole)"),
             "Results", "u of the centre and radius: the column s|X9 of Table 8 (σ_R = 1 µm)"),
    DemoItem("diagnose/concealed/diagnosis.xlsx",
             "an ISO 10360-2 test (7 positions x 5 lengths x 3) with a squareness error of 9 µrad "
             "planted, no larger in any record than noise reaches anyway, only in the diagonal lengths",
             "Candidates",
             "each candidate effect with Δχ², p and verdict: the squareness error found, estimated and "
             "named; the records' residuals before and after on `Records`",
             question="Where do my machine's verification recordings disagree with its model, and why?"),
    DemoItem("diagnose/aliased/diagnosis.xlsx",
             "the same test with one probe offset (0, 0, -50) mm and a pitch error EBX of the x carriage "
             "planted: with one offset it looks exactly like an x scale error",
             "Candidates",
             "the x scale error chosen, and the planted EBX listed as aliased with it, with the "
             "measurement that would separate them"),
    DemoItem("validate/validate_start/validation.xlsx",
             "a simulated machine worse than its type-B model (Forbes 2025 Table 3 MPE1): the lab's "
             "starting tasks validated on step gauges, rings and spheres with calibrated values "
             "(docs/validate.md section 6)",
             "Verdict",
             "the share of rows with E_n <= 1 against the 95.45 % the model claims, and the verdict: the "
             "model does not hold, its cause (the rows deviate more than the model allows, evenly) and "
             "the next step (calibrate); each row's E_n on `Rows`",
             question="Does my uncertainty model hold on this machine?"),
    DemoItem("validate/calibrate/calibration.xlsx",
             "the same machine's verification recordings (an ISO 10360-2 test with three styli, a ball "
             "plate in four passes): its hyper-parameters estimated by REML",
             "Fit",
             "each hyper-parameter's start, estimate and u, or why it is not identifiable from these "
             "records; the fitted model on `Model`, the MPE check and u(d) before and after"),
    DemoItem("validate/validate_fitted/validation.xlsx",
             "the fitted model (calibrate's fitted task) on the same calibrated workpieces, which the "
             "fit never saw",
             "Verdict", "the count and the verdict with the fitted model: the model holds"),
)

#: the colours of every book, said once on the index page
COLOURS = ("Pale yellow cells are inputs (pale green: an input that kept its default value); white cells "
           "are formulas you can follow back to the inputs; grey cells are values the Python core "
           "computed when the book was built (a note on each names the function), where a spreadsheet "
           "formula cannot do the work (a fit, a minimum zone, a characteristic's sensitivities, the "
           "blocks of a book too large for native formulas).")


def item(book: str) -> DemoItem | None:
    """The entry of ``book`` (a path in the demo folder), or None."""
    return next((it for it in ITEMS if it.book == book), None)


def write_index(out_dir: Path, rebuild: dict[str, str], force: bool = False) -> list[Path]:
    """``index.html`` and ``index.md`` into ``out_dir`` (all or nothing), from :data:`ITEMS` and
    ``rebuild`` (book path in ``out_dir`` -> the command, run in ``out_dir``, that rebuilds it).
    A book without an entry is still listed, as undescribed; ``force``: an edited page is replaced
    (kept as ``NAME.bak``).  Returns the two files."""
    out_dir = Path(out_dir)
    pages = {"index.html": html_page(rebuild), "index.md": markdown_page(rebuild)}
    with Staging(out_dir, force=force) as tmp:
        for name, text in pages.items():
            (tmp / name).write_text(text, encoding="utf-8", newline="\n")
    return [out_dir / name for name in pages]


def _listed(rebuild: dict[str, str]) -> list[tuple[str, list[tuple[DemoItem, str]]]]:
    """(heading, [(entry, rebuild command)]) in the order of :data:`GROUPS`, then any other group;
    a book the demo wrote without an entry gets a bare one under its folder."""
    entries = [(item(book) or DemoItem(book, "(not described in generator/demo_index.py)", "Instructions", "-"),
                command) for book, command in rebuild.items()]
    order = {book: k for k, book in enumerate(it.book for it in ITEMS)}
    entries.sort(key=lambda e: order.get(e[0].book, len(order)))
    groups: dict[str, list[tuple[DemoItem, str]]] = {}
    for it, command in entries:
        groups.setdefault(it.group or it.book.split("/", 1)[0], []).append((it, command))
    keys = [g for g in GROUPS if g in groups] + [g for g in groups if g not in GROUPS]
    return [(GROUPS.get(g, g), groups[g]) for g in keys]


def _questions(rebuild: dict[str, str]) -> list[DemoItem]:
    return [it for it in ITEMS if it.question and it.book in rebuild]


_INTRO = ("Each workbook computes its results with native spreadsheet formulas; beside it are the same "
          "results as JSON (computed by cmmwb's Python core), PNG plots and the task file it was built "
          "from. Every book opens on its `Instructions` sheet and has a `Results` sheet and a `Summary`, "
          "the report page a lab signs: the results as rounded statements with their decisions, what "
          "they rest on, and the identity of the task and its input files (SHA-256).")
_REBUILD = ("The commands run in this folder (`cmmwb` is the program the README's first command installed: "
            "`.venv/bin/cmmwb` in the clone). Edit a task file first to make the book your own; a book "
            "you edited is kept unless you add `--force` (which keeps a `.bak` copy).")


def markdown_page(rebuild: dict[str, str]) -> str:
    lines = [f"# cmmwb {__version__} demo: which book to open", "", _INTRO, ""]
    lines += ["## Questions a lab asks, and the book that answers each", ""]
    for it in _questions(rebuild):
        lines.append(f"- **{it.question}** Open `{it.book}`, sheet `{it.first_sheet}`: {it.look_for}.")
    lines += ["", COLOURS, ""]
    for heading, entries in _listed(rebuild):
        lines += [f"## {heading}", "", "| book | shows | look first at | rebuild (in this folder) |",
                  "|---|---|---|---|"]
        for it, command in entries:
            lines.append(f"| `{it.book}` | {_cell(it.shows)} | `{it.first_sheet}`: {_cell(it.look_for)} "
                         f"| `{command}` |")
        lines.append("")
    lines += [_REBUILD, ""]
    return "\n".join(lines)


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _code(text: str) -> str:
    """Markdown-style `code` spans of a sentence as HTML <code>, the rest escaped."""
    parts = text.split("`")
    return "".join(f"<code>{html.escape(p)}</code>" if k % 2 else html.escape(p) for k, p in enumerate(parts))


_CSS = ("body{font-family:sans-serif;max-width:75em;margin:1em auto;padding:0 1em;line-height:1.4}"
        "table{border-collapse:collapse;width:100%}th,td{border:1px solid #bbb;padding:.3em .5em;"
        "vertical-align:top;text-align:left}th{background:#eee}code{background:#f4f4f4;padding:0 .2em}"
        "li{margin:.4em 0}")


def html_page(rebuild: dict[str, str]) -> str:
    title = f"cmmwb {__version__} demo: which book to open"
    out = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
           f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body>",
           f"<h1>{html.escape(title)}</h1>", f"<p>{_code(_INTRO)}</p>",
           "<h2>Questions a lab asks, and the book that answers each</h2>", "<ul>"]
    for it in _questions(rebuild):
        out.append(f'<li><b>{html.escape(it.question)}</b> Open <a href="{html.escape(it.book)}">'
                   f"{html.escape(it.book)}</a>, sheet <code>{html.escape(it.first_sheet)}</code>: "
                   f"{_code(it.look_for)}.</li>")
    out += ["</ul>", f"<p>{_code(COLOURS)}</p>"]
    for heading, entries in _listed(rebuild):
        out += [f"<h2>{html.escape(heading)}</h2>", "<table>",
                "<tr><th>book</th><th>shows</th><th>look first at</th><th>rebuild (in this folder)</th></tr>"]
        for it, command in entries:
            out.append(f'<tr><td><a href="{html.escape(it.book)}">{html.escape(it.book)}</a></td>'
                       f"<td>{_code(it.shows)}</td><td><code>{html.escape(it.first_sheet)}</code>: "
                       f"{_code(it.look_for)}</td><td><code>{html.escape(command)}</code></td></tr>")
        out.append("</table>")
    out.append(f"<p>{_code(_REBUILD)}</p>")
    out.append("</body></html>")
    return "\n".join(out) + "\n"
