"""What the two point-cloud workbooks share (the native one of :mod:`generator.pointcloud.job`
and the large one of :mod:`generator.pointcloud.large_book`): the kind, the Results columns, the
named inputs beside the hyper-parameters, the Results rows, the MPE sheet and the budget chart.
"""

from __future__ import annotations

from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.model.hyperparameters import in_table

from ..workbook.book import Book, ChartSeries, Formula
from ..workbook.xlref import block, cell

KIND = "pointcloud"
MPE_GRID_POINTS = 101
RESULT_COLUMNS = ["from", "to", "d_mm", "u_um", "U_um", *(f"u_{f}_um" for f in pc.FACTORS)]


def extra_inputs(task) -> list[tuple]:
    """The named inputs beside the hyper-parameters: (key, value, unit, meaning, lower bound)."""
    if task.mpe is None:
        return [("K", task.K, "1", "coverage factor for U = K u", 0.0)]
    m = task.mpe
    return [("A_um", m.A_um, "µm", "MPE: E = A + d/B (A)", 0.0),
            ("B_mm", m.B_mm, "mm/µm", "MPE: E = A + d/B (B)", 0.0),
            ("K", m.K, "1", "coverage factor K of eq. (6) and (36); U = K u", 0.0),
            ("P_mm", m.P_mm, "mm", "longest probe length P in eq. (33)", 0.0),
            ("L_max_mm", m.L_max_mm, "mm", "largest distance of the MPE check", 0.0)]


def results_rows(task, first: int, results: dict) -> list[list]:
    """The contract's Results rows: from, to, then references to Budget columns D.. (d, u, U,
    u_R ... u_P, u_W) of the distance in row ``first + q``, each with the core's value
    (``results``, the JSON) to cache."""
    labels = task.cloud.labels
    return [[labels[i], labels[j]] + [Formula(f"={cell(first + q, c, 'Budget')}", v) for c, v in
                                      enumerate((d["d_mm"], d["u_um"], d["U_um"],
                                                 *(d["components_um"][f] for f in pc.FACTORS)), start=4)]
            for q, ((i, j), d) in enumerate(zip(task.pairs, results["distances"]))]


def budget_chart(book: Book, ws, task, first: int) -> None:
    """K u(d) against d, one series per contiguous run of a group (Forbes 2025 Figures 6/7)."""
    from openpyxl.chart import Reference

    series = []
    start, n = 0, len(task.pairs)
    while start < n:
        end = start
        while end + 1 < n and task.groups[end + 1] == task.groups[start]:
            end += 1
        series.append(ChartSeries(task.groups[start] or "distances",
                                  Reference(ws, min_col=4, min_row=first + start, max_row=first + end),
                                  Reference(ws, min_col=6, min_row=first + start, max_row=first + end)))
        start = end + 1
    if task.mpe is not None:
        # the MPE line A + d/B of Forbes 2025 Figures 6/7, from the grid on the MPE sheet
        mp = book.wb["MPE"]
        series.append(ChartSeries("MPE = A + d/B", Reference(mp, min_col=1, min_row=2, max_row=1 + MPE_GRID_POINTS),
                                  Reference(mp, min_col=2, min_row=2, max_row=1 + MPE_GRID_POINTS),
                                  markers=False, colour="000000", dash="solid", bold=True))
    if len(series) <= 13:
        # below the table, on its own printed page
        anchor_row = first + len(task.pairs) + 2
        book.scatter(ws, f"A{anchor_row}", "Expanded uncertainty U = K u(d) against d (Forbes 2025 Figures 6/7)",
                     "d / mm", "U / µm", series, width=24, height=13, x_min=0, y_min=0, page=book)
        book.print_setup(ws, row_breaks=[anchor_row - 1])


#: the legend of the MPE chart, in words, for columns MPE_um ... K_u_ER_um of the 'MPE' sheet
MPE_LEGEND = ("MPE = A + d/B (µm)", "K u(d), eq. (33) (µm)", "K sigma_A: probing, repeatability, eq. (34)",
              "K u_S: scale and squareness", "K u_ET: location errors", "K u_ER: rotation errors x P")


def write_mpe(book: Book, task) -> None:
    ws = book.sheet("MPE")
    cols = ["d_mm", "MPE_um", "K_u_um", "K_sigma_A_um", "K_u_S_um", "K_u_ET_um", "K_u_ER_um", "C"]
    notes = ["grid 0 .. L_max_mm", "A + d/B", "K u(d), eq. (33)", "K sigma_A, eq. (34)",
             "K sqrt(sigma_S^2 + sigma_Sa^2 + sigma_Q^2) d", "K sqrt(2 sigma_ET^2 (1 - exp(-d^2/lambda_ET^2)))",
             "K sqrt(2 sigma_ER^2 P^2 (1 - exp(-d^2/lambda_ER^2)))", "C(d) = K u(d)/(A + d/B), eq. (36)"]
    book.header(ws, 1, 1, cols, notes)
    n = MPE_GRID_POINTS
    first = 2
    for k in range(n):
        r = first + k
        d = cell(r, 1)
        book.formula(ws, r, 1, f"=L_max_mm*{k}/{n - 1}", fmt="0.0")
        book.formula(ws, r, 2, f"=A_um+{d}/B_mm", fmt="0.0000")
        book.formula(ws, r, 4, "=K*SQRT(2*(sigma_R_um^2+sigma_PQ_um^2+sigma_P_um^2+2*sigma_P0_um^2))", fmt="0.0000")
        book.formula(ws, r, 5, f"=K*SQRT(sigma_S_ppm^2+sigma_Sa_ppm^2+sigma_Q_ppm^2)*0.001*{d}", fmt="0.0000")
        book.formula(ws, r, 6, f"=K*SQRT(2*sigma_ET_um^2*(1-EXP(-({d}^2)/(lambda_ET_mm^2+(lambda_ET_mm=0)))))",
                     fmt="0.0000")
        book.formula(ws, r, 7, f"=K*SQRT(2*(sigma_ER_urad*0.001*P_mm)^2*(1-EXP(-({d}^2)/(lambda_ER_mm^2+(lambda_ER_mm=0)))))",
                     fmt="0.0000")
        book.formula(ws, r, 3, f"=SQRT(SUMSQ({block(r, 4, 1, 4)}))", fmt="0.0000")
        book.formula(ws, r, 8, f"={cell(r, 3)}/{cell(r, 2)}", fmt="0.0000")
    Crange = block(first, 8, n, 1)
    book.text(ws, 1, 10, "C_max")
    book.formula(ws, 1, 11, f"=MAX({Crange})", name="C_max", fmt="0.0000",
                 note="max of C(d) over the grid, Forbes 2025 section 6.8")
    book.text(ws, 2, 10, "d_at_max_mm")
    book.formula(ws, 2, 11, f"=L_max_mm*(MATCH(C_max,{Crange},0)-1)/{n - 1}", name="d_at_max_mm", fmt="0.0")
    # short: a longer text ran past the last column and the sheet printed at half size
    book.note(book.text(ws, 4, 10, "conforming parameters"),
              "every standard deviation divided by C_max when C_max > 1 (Forbes 2025 section 6.8)")
    r = 5
    for key in in_table("parameters"):     # the machine's (the part's W is not in the MPE statement)
        book.text(ws, r, 10, key)
        scaled = key in pc.Parameters.SIGMAS
        book.formula(ws, r, 11, f"={key}/MAX(1,C_max)" if scaled else f"={key}", fmt="0.0000")
        r += 1
    book.text(ws, 3, 10, "conforms")
    book.formula(ws, 3, 11, '=IF(C_max<=1,"yes","no")', fmt=None,
                 note="yes when K u(d) <= MPE(d) at every grid distance (C_max <= 1), Forbes 2025 eq. (36)")
    ws.freeze_panes = "A2"
    from openpyxl.chart import Reference

    x = Reference(ws, min_col=1, min_row=first, max_row=first + n - 1)
    anchor_row = first + n + 1
    book.scatter(ws, f"A{anchor_row}", "MPE and K u(d) with components (Forbes 2025 Figures 4/5)", "d / mm",
                 "µm", [ChartSeries(MPE_LEGEND[c - 2], x,
                                    Reference(ws, min_col=c, min_row=first, max_row=first + n - 1),
                                    markers=False, colour="000000" if c == 2 else None, bold=c in (2, 3))
                        for c in range(2, 8)],
                 width=24, height=13, x_min=0, y_min=0, page=book)
    book.print_setup(ws, row_breaks=[anchor_row - 1])
