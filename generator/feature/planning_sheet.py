"""The ``Planning`` sheet of the ``feature`` workbook: the analytic approximation H of a partial
feature's patch, V = MINVERSE(H), s = sqrt(diag V) per row (Forbes 2022 Tables 1-8,
xlfuncs.partial)."""

from __future__ import annotations

from ..workbook.book import Book
from ..workbook.xlref import Block, cell
from .fit_sheets import FMT, SMALL
from .task import Task

# -- planning (Tables 1-8) --------------------------------------------------------------------

_ARC = [("alpha_rad", "RADIANS({arc_deg})/2"),
        ("E_c", "SIN({alpha_rad})/{alpha_rad}"),
        ("E_c2", "0.5+SIN(2*{alpha_rad})/(4*{alpha_rad})"),
        ("E_s2", "0.5-SIN(2*{alpha_rad})/(4*{alpha_rad})")]


def planning_templates(pattern: str, space: bool):
    """Helper cells and the upper triangle of H (Excel formula templates with {key}
    placeholders) of the analytic approximations in xlfuncs.partial."""
    if pattern == "circle_arc" and not space:
        return 3, _ARC, {(0, 0): "{E_c2}", (0, 2): "{E_c}", (1, 1): "{E_s2}", (2, 2): 1.0}
    if pattern == "circle_arc":
        return 6, _ARC, {(0, 0): "{E_c2}", (0, 5): "{E_c}", (1, 1): "{E_s2}", (5, 5): 1.0,
                         (2, 2): 1.0, (2, 4): "-({r0_mm}*{E_c})", (3, 3): "{r0_mm}^2*{E_s2}",
                         (4, 4): "{r0_mm}^2*{E_c2}"}
    if pattern in ("sphere_cap", "sphere_full"):
        g = "{gamma_deg}" if pattern == "sphere_cap" else "180"
        helpers = [("gamma_rad", f"RADIANS({g})"), ("cg", "COS({gamma_rad})"),
                   ("h11", "(2/3-{cg}+{cg}^3/3)/(2*(1-{cg}))"),
                   ("h33", "(1-{cg}^3)/(3*(1-{cg}))"),
                   ("h34", "(1-COS(2*{gamma_rad}))/(4*(1-{cg}))")]
        return 4, helpers, {(0, 0): "{h11}", (1, 1): "{h11}", (2, 2): "{h33}", (2, 3): "{h34}",
                            (3, 3): 1.0}
    if pattern == "sphere_band":
        helpers = [("beta_rad", "RADIANS({beta_deg})"), ("sb2", "SIN({beta_rad})^2")]
        return 4, helpers, {(0, 0): "(1-{sb2}/3)/2", (1, 1): "(1-{sb2}/3)/2",
                            (2, 2): "{sb2}/3", (3, 3): 1.0}
    if pattern == "sphere_segment":
        helpers = [("alpha_rad", "RADIANS({arc_deg})/2"),
                   ("h11", "({alpha_rad}+SIN(2*{alpha_rad})/2)/(3*{alpha_rad})"),
                   ("h22", "({alpha_rad}-SIN(2*{alpha_rad})/2)/(3*{alpha_rad})"),
                   ("h14", "PI()*SIN({alpha_rad})/(4*{alpha_rad})")]
        return 4, helpers, {(0, 0): "{h11}", (0, 3): "{h14}", (1, 1): "{h22}",
                            (2, 2): "1/3", (3, 3): 1.0}
    if pattern == "sphere_patch":
        helpers = [("t1", "RADIANS({theta_from_deg})"), ("t2", "RADIANS({theta_to_deg})"),
                   ("p1", "RADIANS({phi_from_deg})"), ("p2", "RADIANS({phi_to_deg})"),
                   ("Ic2", "({t2}-{t1})/2+(SIN(2*{t2})-SIN(2*{t1}))/4"),
                   ("Is2", "({t2}-{t1})/2-(SIN(2*{t2})-SIN(2*{t1}))/4"),
                   ("Isc", "(SIN({t2})^2-SIN({t1})^2)/2"),
                   ("Ic", "SIN({t2})-SIN({t1})"), ("Is", "COS({t1})-COS({t2})"),
                   ("I1", "{t2}-{t1}"),
                   ("c3", "SIN({p2})-SIN({p2})^3/3-SIN({p1})+SIN({p1})^3/3"),
                   ("sc2", "(COS({p1})^3-COS({p2})^3)/3"),
                   ("c2", "({p2}-{p1})/2+(SIN(2*{p2})-SIN(2*{p1}))/4"),
                   ("s2c", "(SIN({p2})^3-SIN({p1})^3)/3"),
                   ("sc", "(SIN({p2})^2-SIN({p1})^2)/2"),
                   ("c1", "SIN({p2})-SIN({p1})"), ("A", "{I1}*{c1}")]
        return 4, helpers, {(0, 0): "{Ic2}*{c3}/{A}", (0, 1): "{Isc}*{c3}/{A}",
                            (0, 2): "{Ic}*{sc2}/{A}", (0, 3): "{Ic}*{c2}/{A}",
                            (1, 1): "{Is2}*{c3}/{A}", (1, 2): "{Is}*{sc2}/{A}",
                            (1, 3): "{Is}*{c2}/{A}", (2, 2): "{I1}*{s2c}/{A}",
                            (2, 3): "{I1}*{sc}/{A}", (3, 3): 1.0}
    if pattern == "plane_rectangle":
        return 3, [], {(0, 0): 1.0, (1, 1): "{half_width_y_mm}^2/3",
                       (2, 2): "{half_width_x_mm}^2/3"}
    if pattern == "line_segment":
        return 4, [], {(0, 0): 1.0, (1, 1): 1.0, (2, 2): "{half_length_mm}^2/3",
                       (3, 3): "{half_length_mm}^2/3"}
    if pattern == "cylinder_patch":
        return 5, _ARC, {(0, 0): "{E_c2}", (0, 4): "{E_c}", (1, 1): "{E_s2}",
                         (2, 2): "{half_height_mm}^2/3*{E_s2}",
                         (3, 3): "{half_height_mm}^2/3*{E_c2}", (4, 4): 1.0}
    if pattern == "cone_patch":
        helpers = _ARC + [
            ("phi_rad", "RADIANS({phi_deg})"), ("cp", "COS({phi_rad})"), ("sp", "SIN({phi_rad})"),
            ("M1", "-(TAN({phi_rad})*{half_height_mm}^2)/(3*{r0_mm})"),
            ("M2", "{half_height_mm}^2/3"),
            ("Ew", "{M1}/{cp}-{r0_mm}*{sp}"),
            ("Ew2", "{M2}/{cp}^2-2*{r0_mm}*{sp}*{M1}/{cp}+({r0_mm}*{sp})^2"),
            ("Ewz", "{M2}/{cp}-{r0_mm}*{sp}*{M1}")]
        return 6, helpers, {
            (0, 0): "{cp}^2*{E_c2}", (0, 3): "{cp}*{E_c2}*{Ew}", (0, 4): "{cp}^2*{E_c}",
            (0, 5): "-({E_c}*{M1})", (1, 1): "{cp}^2*{E_s2}", (1, 2): "-({cp}*{E_s2}*{Ew})",
            (2, 2): "{E_s2}*{Ew2}", (3, 3): "{E_c2}*{Ew2}", (3, 4): "{cp}*{E_c}*{Ew}",
            (3, 5): "-({E_c}*{Ewz}/{cp})", (4, 4): "{cp}^2", (4, 5): "-({M1})",
            (5, 5): "{M2}/{cp}^2"}
    raise ValueError(pattern)


PLANNING_NOTES = {
    "circle_arc": "H_alpha of Forbes 2022 eq. (16) (Table 1)",
    "sphere_cap": "H_gamma of Forbes 2022 section 5.2 with +cos^3/3 (Table 2)",
    "sphere_full": "whole sphere: H = diag(1/3, 1/3, 1/3, 1) (section 5; Table 8 s|6)",
    "sphere_band": "inverse of V_beta, eq. (19) (Table 3)",
    "sphere_segment": "inverse of V_alpha, eq. (20), with V(4,4) un-inverted (Table 4)",
    "sphere_patch": "H_A/|A| of section 5.1 with the corrected H_A(2,4), H_A(3,3) and H_A(3,4)",
    "plane_rectangle": "H_ab of eq. (22) in the order (z_A, rot_x, rot_y)",
    "line_segment": "line in space: diag(1, 1, a^2/3, a^2/3)",
    "cylinder_patch": "H_a_alpha of section 7 (Table 5)",
    "cone_patch": "H_a_alpha_phi of section 8 in closed form, uniform by area (Tables 6, 7)",
}


def write_planning(book: Book, task: Task, results: dict) -> None:
    plan = task.planning
    pl = results["planning"]
    ws = book.sheet("Planning")
    n, helpers, Hent = planning_templates(plan.pattern, plan.space)
    names = pl["parameter_names"]
    # named geometry inputs
    book.text(ws, 1, 1, f"Planning without data: {plan.pattern}, {PLANNING_NOTES[plan.pattern]}. "
                        "s = sqrt(diag H^-1), u = sigma_R s / sqrt(m) for V_X = sigma_R^2 I "
                        "(Forbes 2022 eq. (15)); u in the parameter's unit (mm, rad)")
    refs: dict[str, str] = {}
    r = 3
    geo = dict(plan.geometry)
    if "theta_deg" in geo:
        geo["theta_from_deg"], geo["theta_to_deg"] = geo.pop("theta_deg")
    if "phi_range_deg" in geo:
        geo["phi_from_deg"], geo["phi_to_deg"] = geo.pop("phi_range_deg")
    if plan.pattern == "circle_arc" and plan.space:
        geo.setdefault("r0_mm", 1.0)
    inputs = [(k, v) for k, v in geo.items()] + [("m_points", plan.m_points)]
    for key, value in inputs:
        book.text(ws, r, 1, key)
        book.input(ws, r, 2, key, value, lo=0.0 if key != "phi_deg" else None)
        refs[key] = key
        r += 1
    book.text(ws, r, 1, "sigma_R_um")
    book.formula(ws, r, 2, "=sigma_R_um", fmt="General", note="from 'Inputs'")
    r += 2
    sweep = plan.sweep
    rows = plan.values if sweep else [None]
    top = r
    head = [sweep or "row"] + [f"s({nm})" for nm in names] + [f"u({nm})" for nm in names]
    book.header(ws, top, 1, head, [f"{'input: ' + sweep if sweep else None}"] +
                [PLANNING_NOTES[plan.pattern]] + [None] * (n - 1) +
                ["u = sigma_R_um * 0.001 * s / sqrt(m_points) (mm or rad)"] + [None] * (n - 1))
    block_top = top + len(rows) + 3
    span = n + 5
    for q, v in enumerate(rows):
        tr = top + 1 + q
        if sweep:
            book.input(ws, tr, 1, None, v)
            refs_q = dict(refs, **{sweep: cell(tr, 1)})
        else:
            book.text(ws, tr, 1, "1")
            refs_q = dict(refs)
        br = block_top + q * span
        book.text(ws, br, 1, f"row {q + 1}" + (f": {sweep} = {v:g}" if sweep else ""))
        for h, (hname, tmpl) in enumerate(helpers):
            book.text(ws, br + 1, 2 + h, hname)
            book.formula(ws, br + 2, 2 + h, "=" + tmpl.format(**refs_q), fmt=FMT)
            refs_q[hname] = cell(br + 2, 2 + h)
        H = Block("Planning", br + 4, 2, n, n)
        Vb = Block("Planning", br + 4, 2 + n + 2, n, n)
        book.text(ws, br + 3, 2, "H")
        book.text(ws, br + 3, 2 + n + 2, "V = MINVERSE(H)")
        for a in range(n):
            for b in range(n):
                rr, cc = br + 4 + a, 2 + b
                if a > b:
                    book.formula(ws, rr, cc, f"={cell(br + 4 + b, 2 + a)}", fmt=FMT)
                    continue
                t = Hent.get((a, b), 0.0)
                if isinstance(t, float):
                    ws.cell(row=rr, column=cc).value = t
                else:
                    book.formula(ws, rr, cc, "=" + t.format(**refs_q), fmt=FMT)
        book.note(ws.cell(row=br + 4, column=2), PLANNING_NOTES[plan.pattern])
        book.array(Vb, f"=MINVERSE({H.ref})", fmt=FMT)
        for p in range(n):
            book.formula(ws, tr, 2 + p, f"=SQRT({Vb.cell(p, p)})", fmt="0.0000")
            book.formula(ws, tr, 2 + n + p,
                         f"=sigma_R_um*0.001*{cell(tr, 2 + p)}/SQRT(m_points)", fmt=SMALL)
    ws.column_dimensions["A"].width = 18
