"""The global risks of the ``Decision`` sheet: for each tolerance with a normal prior of its
production process (``process_mean_mm``, ``process_sd_um``), the non-conforming fraction and the
global consumer's and producer's risks of the decision rule (JCGM 106:2012, 9.5), as live
formulas.

The integrals are the fixed Gauss-Legendre panels of :func:`xlfuncs.global_risk.global_risks_normal`,
one ``SUMPRODUCT`` over the node table (named ``decision_gl_x``, ``decision_gl_w``) per panel,
so that the core, ``formulas`` and LibreOffice compute the same sums.
"""

from __future__ import annotations

from typing import Any, Callable

from cmmwb.xlfuncs import conformity as cf
from cmmwb.xlfuncs import global_risk as gr

from ..workbook.book import Book
from ..workbook.styles import FMT_MM, FMT_UM, HEADER_FONT
from ..workbook.xlref import Block, cell, norm_s_dist, quote_sheet

#: the risk table's columns (below the chart), units in the names
RISK_COLUMNS = ["item", "characteristic", "process_mean_mm", "process_sd_um", "u_um", "p_nonconforming",
                "R_C_global", "R_P_global", "T_L_mm", "T_U_mm", "A_L_mm", "A_U_mm", "v1", "v2", "v3", "v4",
                "x_L", "x_U"]
RISK_NOTES = [
    "the row of the decision table", "the characteristic",
    "mean of the characteristic over the production process (input; normal prior, JCGM 106:2012, 9.5)",
    "standard deviation of the characteristic over the production process (input)",
    "the measurement's standard uncertainty u (decision table)",
    "prior probability that an item does not conform, Φ((T_L − μ)/σ₀) + Φ((μ − T_U)/σ₀)",
    "global consumer's risk R_C: an item is accepted and does not conform (JCGM 106:2012, 9.5.2)",
    "global producer's risk R_P: an item is rejected (or not proven to conform) and conforms (9.5.3)",
    "lower tolerance limit (a one-sided tolerance: stand-in μ − 1000·(σ₀ + u), beyond every probability)",
    "upper tolerance limit (or its stand-in μ + 1000·(σ₀ + u))",
    "lower acceptance limit (or its stand-in); the ISO 14253-1 rule accepts its conformance zone",
    "upper acceptance limit (or its stand-in)",
    "(A_L − T_L)/u, clamped to ±12: a panel end of the integral over v = e/u",
    "(A_U − T_U)/u, clamped", "(A_U − T_L)/u, clamped", "(A_L − T_U)/u, clamped",
    "(T_L − μ)/σ₀, clamped: a panel end of the integral over x = (η − μ)/σ₀", "(T_U − μ)/σ₀, clamped"]
FMT_P = "0.000000E+00"


def has_priors(spec) -> bool:
    return any(t.process_sd_um is not None for t in spec.tolerances)


def write_node_table(book: Book, ws, row: int, column: int) -> None:
    """The Gauss-Legendre nodes and weights of one panel on [-1, 1] (named ranges)."""
    book.text(ws, row, column, "Gauss–Legendre x_i (1)", font=HEADER_FONT)
    book.text(ws, row, column + 1, "w_i (1)", font=HEADER_FONT)
    for i, (x, w) in enumerate(zip(gr.GL_NODES, gr.GL_WEIGHTS)):
        ws.cell(row + 1 + i, column).value = x
        ws.cell(row + 1 + i, column + 1).value = w
    n = len(gr.GL_NODES)
    book.define("decision_gl_x", f"{quote_sheet(ws.title)}!{cell(row + 1, column)}:{cell(row + n, column)}")
    book.define("decision_gl_w", f"{quote_sheet(ws.title)}!{cell(row + 1, column + 1)}:{cell(row + n, column + 1)}")


def _clamp(v: str) -> str:
    return f"=MIN(MAX({v},-{gr.GL_RANGE:g}),{gr.GL_RANGE:g})"


def _gl(a: str, b: str, f: Callable[[str], str]) -> str:
    """One panel [a, max(a, b)] of the sum Σ w_i f(m + h x_i) h (a, b already clamped)."""
    hi = f"MAX({a},{b})"
    m, h = f"(({a})+{hi})/2", f"({hi}-({a}))/2"
    x = f"({m}+{h}*decision_gl_x)"
    return f"SUMPRODUCT(decision_gl_w,{f(x)})*{h}"


def write_rows(book: Book, ws, top: int, rows: list[dict], cache: dict[str, Any]) -> int:
    """The risk table from row ``top`` (title, header, one row per prior); returns its last row.

    ``rows``: per tolerance with a prior: item, label, name prefix, the decision (JSON entry), the
    Decision-table cells of u, the tolerance limits and the acceptance limits (None: absent)."""
    book.text(ws, top, 1, "Global risks of the production process (JCGM 106:2012, 9.5): a normal prior "
              "N(μ, σ₀²) of the characteristic, measured with N(η, u²); risks as probabilities (1)", font=HEADER_FONT)
    h = top + 1
    book.header(ws, h, 1, RISK_COLUMNS, notes=RISK_NOTES)
    c = {name: j + 1 for j, name in enumerate(RISK_COLUMNS)}
    V = f"{gr.GL_RANGE:g}"
    for i, row in enumerate(rows):
        r = h + 1 + i
        d = row["decision"]

        def at(name: str, r=r) -> str:
            return cell(r, c[name], absolute=False)

        ws.cell(r, c["item"]).value = row["item"]
        book.text(ws, r, c["characteristic"], row["label"])
        book.input(ws, r, c["process_mean_mm"], f"{row['prefix']}_process_mean_mm", d["process_mean_mm"],
                   fmt=FMT_MM, note="process mean (mm)")
        book.input(ws, r, c["process_sd_um"], f"{row['prefix']}_process_sd_um", d["process_sd_um"], lo=0.0,
                   fmt=FMT_UM, note="process standard deviation (µm)")
        mean, sd, u = at("process_mean_mm"), at("process_sd_um"), at("u_um")
        book.formula(ws, r, c["u_um"], f"={row['u']}", fmt=FMT_UM)
        far = f"1000*({sd}+{u})/1000"
        lims = {"T_L_mm": (row["lsl"], "-"), "T_U_mm": (row["usl"], "+"), "A_L_mm": (row["A_L"], "-"),
                "A_U_mm": (row["A_U"], "+")}
        panels = gr.risk_panels(d["process_mean_mm"], d["process_sd_um"], d["u_um"],
                                cf.Tolerance(d["lsl_mm"], d["usl_mm"]), tuple(d["acceptance_limits_mm"]))
        for name, (ref, sign) in lims.items():
            book.formula(ws, r, c[name], f"={ref}" if ref else f"={mean}{sign}{far}", fmt=FMT_MM)
            cache[at(name)] = panels[name[:3]]
        t_l, t_u, a_l, a_u = (at(n) for n in ("T_L_mm", "T_U_mm", "A_L_mm", "A_U_mm"))
        um = f"({u}/1000)"
        s0 = f"({sd}/1000)"
        ends = {"v1": f"({a_l}-{t_l})/{um}", "v2": f"({a_u}-{t_u})/{um}", "v3": f"({a_u}-{t_l})/{um}",
                "v4": f"({a_l}-{t_u})/{um}", "x_L": f"({t_l}-{mean})/{s0}", "x_U": f"({t_u}-{mean})/{s0}"}
        um_v, s0_v = d["u_um"] / cf.UM_PER_MM, d["process_sd_um"] / cf.UM_PER_MM
        vals = {"v1": (panels["A_L"] - panels["T_L"]) / um_v, "v2": (panels["A_U"] - panels["T_U"]) / um_v,
                "v3": (panels["A_U"] - panels["T_L"]) / um_v, "v4": (panels["A_L"] - panels["T_U"]) / um_v,
                "x_L": (panels["T_L"] - d["process_mean_mm"]) / s0_v,
                "x_U": (panels["T_U"] - d["process_mean_mm"]) / s0_v}
        for name, expr in ends.items():
            book.formula(ws, r, c[name], _clamp(expr), fmt="0.000")
            cache[at(name)] = min(max(vals[name], -gr.GL_RANGE), gr.GL_RANGE)
        v1, v2, v3, v4, x_l, x_u = (at(n) for n in ("v1", "v2", "v3", "v4", "x_L", "x_U"))

        def phi(x: str) -> str:
            return norm_s_dist(x, cumulative=False)

        def cdf(z: str) -> str:
            return norm_s_dist(z)

        def P0(t: str) -> str:
            return cdf(f"(({t})-{mean})/{s0}")

        def Q0(t: str) -> str:
            return cdf(f"({mean}-({t}))/{s0}")

        def shifted(a: str, x: str) -> str:
            return f"{a}-{um}*{x}"

        rc_v = "+".join([
            _gl(f"-{V}", v4, lambda x: f"{phi(x)}*({Q0(shifted(a_l, x))}-{Q0(shifted(a_u, x))})"),
            _gl(v4, v2, lambda x: f"{phi(x)}*({Q0(t_u)}-{Q0(shifted(a_u, x))})"),
            _gl(v1, v3, lambda x: f"{phi(x)}*({P0(t_l)}-{P0(shifted(a_l, x))})"),
            _gl(v3, V, lambda x: f"{phi(x)}*({P0(shifted(a_u, x))}-{P0(shifted(a_l, x))})")])
        rp_v = "+".join([
            _gl(v2, v3, lambda x: f"{phi(x)}*({Q0(shifted(a_u, x))}-{Q0(t_u)})"),
            _gl(v3, V, lambda x: f"{phi(x)}*({Q0(t_l)}-{Q0(t_u)})"),
            _gl(f"-{V}", v4, lambda x: f"{phi(x)}*({P0(t_u)}-{P0(t_l)})"),
            _gl(v4, v1, lambda x: f"{phi(x)}*({P0(shifted(a_l, x))}-{P0(t_l)})")])

        def eta(x: str) -> str:
            return f"({mean}+{s0}*{x})"

        rc_x = "+".join([
            _gl(f"-{V}", x_l, lambda x: f"{phi(x)}*({cdf(f'({eta(x)}-{a_l})/{um}')}-{cdf(f'({eta(x)}-{a_u})/{um}')})"),
            _gl(x_u, V, lambda x: f"{phi(x)}*({cdf(f'({a_u}-{eta(x)})/{um}')}-{cdf(f'({a_l}-{eta(x)})/{um}')})")])
        rp_x = _gl(x_l, x_u, lambda x: f"{phi(x)}*({cdf(f'({a_l}-{eta(x)})/{um}')}+{cdf(f'({eta(x)}-{a_u})/{um}')})")
        pnc = at("p_nonconforming")
        book.formula(ws, r, c["p_nonconforming"], f"={P0(t_l)}+{Q0(t_u)}", fmt=FMT_P,
                     note="JCGM 106:2012, 9.5.1: the fraction of the process outside the tolerance")
        empty = f"{a_l}>{a_u}"
        book.array(Block(ws.title, r, c["R_C_global"], 1, 1),
                   f"=IF({empty},0,IF({u}<={sd},{rc_v},{rc_x}))", fmt=FMT_P,
                   note="JCGM 106:2012, 9.5.2; Gauss-Legendre panels over v = e/u when u <= σ₀, else over "
                        "x = (η − μ)/σ₀ (xlfuncs.global_risk.global_risks_normal; docs/errata.md)")
        book.array(Block(ws.title, r, c["R_P_global"], 1, 1),
                   f"=IF({empty},1-{pnc},IF({u}<={sd},{rp_v},{rp_x}))", fmt=FMT_P,
                   note="JCGM 106:2012, 9.5.3; the same panels")
        cache.update({pnc: d["process_nonconforming"], at("R_C_global"): d["global_consumer_risk"],
                      at("R_P_global"): d["global_producer_risk"], at("u_um"): d["u_um"]})
    return h + len(rows)
