"""The ``pointcloud`` task: distance uncertainties from the point-cloud V_X (Forbes 2025).

Workbook sheets: Instructions, Inputs, Points, Coords, V_R ... V_P, V_X, Budget (distances in the
layout of Forbes 2025 Tables 4/5), MPE (C(d) of eq. 36 with Figures 4/5 as a chart), Results.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import blocked as bl
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.distributed import get_backend
from cmmwb.xlfuncs.model.hyperparameters import in_table

from .. import __version__
from ..errors import InputError, model_errors_named
from ..quantities import Cells, Quantity, ToleranceKeys, Verdict, unique_labels
from ..taskcloud import MPE, points_source, read_mpe, read_point_cloud
from ..taskfile import COMMON_TABLES, check_keys, number, place, string, table, task_kind_and_name, text_list
from ..taskkind import always_exact, no_type_a
from ..workbook.book import RESULTS, Book, BookAdditions
from ..workbook.xlref import Block, block, cell
from .book import KIND, MPE_GRID_POINTS, RESULT_COLUMNS, budget_chart, extra_inputs, results_rows, write_mpe
from .vx_sheets import NATIVE_MAX_POINTS, explain_inputs, point_block, write_point_cloud_model

EXAMPLES = ["stepgauge_I_MPE1.toml", "stepgauge_I_MPE2.toml",
            "stepgauge_II_MPE1.toml", "stepgauge_II_MPE2.toml"]
#: the task-kind contract's hooks (generator.taskkind): exact at every size, no type A inputs
force_exact = always_exact
add_type_a = no_type_a


@dataclass
class Task:
    path: Path
    name: str
    cloud: pc.PointCloud
    params: pc.Parameters
    pairs: np.ndarray
    groups: list[str]
    K: float
    mpe: MPE | None = None
    notes: list[str] = field(default_factory=list)
    all_pairs: bool = False  # the distances are every pair i < j in all_pairs order
    points_source: str = ""  # where the points come from, in words (taskcloud.points_source)


def load(path: Path, doc: dict) -> Task:
    path = Path(path)
    kind, name = task_kind_and_name(path, doc)
    check_keys(path, doc, "task file", {"task", "mpe", "parameters", "probes", "points", "distances"} | COMMON_TABLES)
    check_keys(path, table(path, doc, "task"), "task", {"kind", "name", "notes", "K"})
    cloud, params, pts = read_point_cloud(path, doc)
    source = points_source(doc)
    notes = text_list(path, doc["task"], "task", "notes")
    K = number(path, doc["task"], "task", "K", 2.0, positive=True)
    mpe = read_mpe(path, doc, cloud.probes)
    if mpe is not None:
        K = mpe.K
    index = {lab: i for i, lab in enumerate(cloud.labels)}
    raw = doc.get("distances")
    pairs: list[tuple[int, int]] = []
    groups: list[str] = []
    if raw is None:
        pairs_arr = pc.all_pairs(cloud.m)
        if not len(pairs_arr):
            raise InputError("no distances to evaluate (one point only?)", file=path, where="[points]")
        # coincident points are found (and named) by the distance computation itself
        return Task(path, name, cloud, params, pairs_arr, [""] * len(pairs_arr), K, mpe, list(notes),
                    all_pairs=True, points_source=source)
    else:
        if not isinstance(raw, list) or not all(isinstance(d, dict) for d in raw):
            raise InputError("must be a list of {from, to} tables", file=path, where="[[distances]]")
        listed: dict[frozenset, str] = {}
        for n, d in enumerate(raw, start=1):
            section = f"[[distances]] #{n}"
            check_keys(path, d, section, {"from", "to", "group"})
            a = string(path, d, section, "from")
            b = string(path, d, section, "to")
            g = string(path, d, section, "group", "")
            for key, lab in (("from", a), ("to", b)):
                if lab != "*" and lab not in index:
                    raise InputError(f"unknown point {lab!r}", file=path, where=f"{section} {key}")
            if a == "*":
                raise InputError("'*' is allowed for 'to' only", file=path, where=f"{section} from")
            targets = [j for j in range(cloud.m) if j != index[a]] if b == "*" else [index[b]]
            for j in targets:
                if j == index[a]:
                    raise InputError("a distance needs two different points", file=path, where=section)
                pair = frozenset((index[a], j))
                if pair in listed:
                    raise InputError(f"the distance {a}→{cloud.labels[j]} is listed already, at "
                                     f"{place(path, listed[pair])}; each distance once (a tolerance or "
                                     "a plot would not know which)", file=path, where=section)
                listed[pair] = section
                pairs.append((index[a], j))
                groups.append(g)
    if not pairs:
        raise InputError("no distances to evaluate (one point only?)", file=path, where="[points]")
    pairs_arr = np.array(pairs, dtype=int)
    with model_errors_named(file=path, where="[[distances]]"):
        pc.check_pairs(cloud, pairs_arr)
    return Task(path, name, cloud, params, pairs_arr, groups, K, mpe, list(notes), points_source=source)


def compute(task: Task) -> dict:
    pairs = None if task.all_pairs else task.pairs  # None: the row-block path, no index arrays
    with model_errors_named(file=task.path, where="[points]"):
        r = bl.distance_components(task.cloud, task.params, pairs, backend=get_backend(),
                                   progress=bl.ProgressBar(f"{len(task.pairs)} distances"))
    labels = task.cloud.labels
    out = {"name": task.name, "kind": KIND, "version": __version__, "distances": []}
    for q, (i, j) in enumerate(task.pairs):
        u = float(r["u_um"][q])
        out["distances"].append({
            "from": labels[i], "to": labels[j], "group": task.groups[q],
            "d_mm": float(r["d_mm"][q]), "u_um": u, "U_um": task.K * u,
            "components_um": {f: float(r[f"u_{f}_um"][q]) for f in pc.FACTORS},
        })
    out["K"] = task.K
    if task.mpe is not None:
        m = task.mpe
        chk = pc.mpe_check(task.params, m.A_um, m.B_mm, m.K, m.P_mm, m.L_max_mm, MPE_GRID_POINTS)
        scaled = pc.conforming_parameters(task.params, chk.C_max)
        out["mpe_check"] = {
            "K": m.K, "C_max": chk.C_max, "d_at_max_mm": chk.d_at_max_mm, "conforms": chk.conforms,
            "A_um": m.A_um, "B_mm": m.B_mm, "P_mm": m.P_mm, "L_max_mm": m.L_max_mm,
            "grid_points": MPE_GRID_POINTS,
            "conforming_parameters": {k: getattr(scaled, k) for k in in_table("parameters")},
        }
    return out


# -- workbook ----------------------------------------------------------------------------------

def write_book(task: Task, results: dict, path: Path, additions: BookAdditions | None = None) -> None:
    if task.cloud.m > NATIVE_MAX_POINTS:
        # beyond the native V_X sheets: GP blocks as values + Excel add-in formulas
        from .large_book import write_large_book

        write_large_book(task, results, path, additions)
        return
    book = Book(KIND, task.name, f"Point-cloud uncertainty of distances — {task.name}")
    _instructions(book, task)
    layout = write_point_cloud_model(book, task.cloud, task.params, extra_inputs(task))
    budget = _write_budget(book, task, layout)
    if task.mpe is not None:
        write_mpe(book, task)
    budget_chart(book, book.wb["Budget"], task, budget)
    book.results(RESULT_COLUMNS, results_rows(task, budget, results))
    book.save(path, additions)


def _instructions(book: Book, task: Task) -> None:
    book.para("What this workbook computes", bold=True)
    book.para(
        "The standard uncertainty u(d) of distances between measured points and its contributions from six "
        "CMM influence factors, following A. Forbes, 'CMM influence factors and uncertainty associated with "
        "length measurement', Appl. Sci. 2025, 15, 271: the point-cloud variance V_X (eq. 28) is built from "
        "the hyper-parameters on 'Inputs' and the points on 'Points'; each distance's u is the quadratic "
        "form of eq. (29) over the 3x3 blocks of V_X; the components are eq. (30).",
        "No Monte Carlo, no macros: every number is a native formula you can click and follow back.")
    book.gap()
    book.para("How to use it", bold=True)
    book.para(
        "1. Edit the yellow cells only: hyper-parameters and MPE on 'Inputs', probe offsets, point "
        "coordinates and normals on 'Points'. Everything else recalculates.",
        "2. Structural changes (more points, another probe, other distances) go through the task file: "
        "`cmmwb read` this workbook, edit the task, `cmmwb build` again.",
        "3. 'Budget' is the distance table in the layout of Forbes 2025 Tables 4/5; 'Results' is the "
        "machine-readable summary; 'MPE' compares K u(d) with the MPE statement (eq. 36, Figures 4/5).")
    book.gap()
    book.para("Sheets", bold=True)
    book.para(
        "Inputs — hyper-parameters (named cells), probes, V_B of eq. (13).",
        "Points — coordinates x_i (mm), outward unit normals n_i, probe; derived offset p_k(i) and ram position x_i - p_k(i).",
        "Coords — one row per coordinate: the vectors the V blocks are built from, the rows of G_X|S (eq. 11) and G_k (eq. 24).",
        "V_R, V_PQ, V_S, V_ET, V_ER, V_P — the six 3m x 3m contributions (µm²) of the machine; V_W the part's "
        "thermal expansion (docs/workpiece.md; zero while workpiece_enabled = 0); V_X their sum (eq. 28).",
        "Budget — d, u, U and u per factor for each distance (µm).",
        "MPE — C(d) = K u(d)/(A + d/B) from the summary formula (33)-(34), its maximum, 'conforms' (yes when "
        "C_max <= 1) and the conforming rescaling (section 6.8).",
        "Charts: below the tables of 'Budget' (U = K u(d) per group of distances against the MPE line, "
        "Figures 6/7) and 'MPE' (Figures 4/5); each prints on its own page.")
    explain_inputs(book)
    book.gap()
    book.para("Conventions (see docs/errata.md)", bold=True)
    book.para(
        "Units: coordinates mm, uncertainties µm, scale/squareness ppm, rotations µrad; the MPE is A + d/B µm with d in mm.",
        "Scale/squareness, ET and ER act on the ram positions x_i - p_k(i) (Forbes 2025 sections 4.3, 5.3, 5.4).",
        "Probing effects of different probes are independent (section 5.5); P0 is a per-probe radius error.",
        "The MPE check evaluates eq. (33) on a grid of "
        f"{MPE_GRID_POINTS} distances from 0 to L_max; C_max is the grid maximum.",
        *task.notes)


def _write_budget(book: Book, task: Task, layout) -> int:
    ws = book.sheet("Budget")
    nf = len(pc.FACTORS)
    cols = ["from", "to", "group", "d_mm", "u_um", "U_um", *(f"u_{f}_um" for f in pc.FACTORS),
            "dx_mm", "dy_mm", "dz_mm", "nx_mm/mm", "ny_mm/mm", "nz_mm/mm"]
    notes = [None, None, "free label (e.g. LL, RR, LR, FF of Forbes 2025 Figures 6/7)",
             "d_ij = ||x_j - x_i||", "u(d_ij), eq. (30): root sum of squares of the components",
             "U = K u", *["u_F(d_ij) = sqrt(n^T (V_ii + V_jj - V_ij - V_ji) n), eq. (29) on V_F"] * nf,
             "x_j - x_i", None, None, "n_ij = (x_j - x_i)/d_ij", None, None]
    cd, cn = 7 + nf, 10 + nf           # the columns of x_j - x_i and of n_ij
    book.header(ws, 1, 1, cols, notes)
    X = layout.X
    first = 2
    for q, (i, j) in enumerate(task.pairs):
        r = first + q
        book.text(ws, r, 1, task.cloud.labels[i])
        book.text(ws, r, 2, task.cloud.labels[j])
        book.text(ws, r, 3, task.groups[q])
        for a in range(3):
            book.formula(ws, r, cd + a, f"={X.cell(j, a)}-{X.cell(i, a)}")
        dvec = block(r, cd, 1, 3)
        book.formula(ws, r, 4, f"=SQRT(SUMSQ({dvec}))", fmt="0.0000")
        for a in range(3):
            book.formula(ws, r, cn + a, f"={cell(r, cd + a)}/{cell(r, 4)}")
        n = block(r, cn, 1, 3)
        for k, f in enumerate(pc.FACTORS):
            V = layout.V[f]
            s = f"{point_block(V, i, i).ref}+{point_block(V, j, j).ref}-{point_block(V, i, j).ref}-{point_block(V, j, i).ref}"
            book.array(Block("Budget", r, 7 + k, 1, 1),
                       f"=SQRT(MAX(0,SUMPRODUCT(({s})*MMULT(TRANSPOSE({n}),{n}))))", fmt="0.0000")
        book.formula(ws, r, 5, f"=SQRT(SUMSQ({block(r, 7, 1, nf)}))", fmt="0.0000")
        book.formula(ws, r, 6, f"=K*{cell(r, 5)}", fmt="0.0000")
    ws.freeze_panes = "D2"
    for c, w in zip("ABC", (8, 8, 7)):
        ws.column_dimensions[c].width = w
    return first


# -- plots -------------------------------------------------------------------------------------

def write_plots(task: Task, results: dict, out_dir: Path) -> list[Path]:
    from ..workbook import plots

    files = [plots.distance_plot(results, out_dir / f"{task.name}_distances.png")]
    if task.mpe is not None:
        m = task.mpe
        d = np.linspace(0, m.L_max_mm, MPE_GRID_POINTS)
        comp = pc.summary_components_um(d, task.params, m.P_mm)
        files.append(plots.mpe_plot(d, pc.mpe_um(d, m.A_um, m.B_mm), comp, m.K,
                                    out_dir / f"{task.name}_mpe.png", task.name))
    return files


# -- the records of the results (generator.quantities) -----------------------------------------

#: a [[decision.tolerances]] entry names a distance by its two point ids
TOLERANCE_KEYS = ToleranceKeys(("from", "to"), help="from and to = the point ids of a distance")
U_SOURCE = "the point-cloud model V_X of six influence factors (Forbes 2025 eq. (28)-(30))"


def quantities(task: Task, results: dict, k: float = 2.0) -> list[Quantity]:
    """One record per distance (its Results row; U = K u with the task's K, the named input
    ``K``).  ``k`` is not used: a point-cloud task's U has its own coverage factor."""
    ds = results["distances"]
    labels = unique_labels([f"{d['from']}→{d['to']}" for d in ds])
    K = float(results["K"])
    source = f"the distance of two points of {task.points_source}"
    # the columns d_mm, u_um, U_um of Results as "Results!$C$" (+ row): 10^5 distances in seconds
    d_col, u_col, U_col = (cell(1, c, RESULTS)[:-1] for c in (3, 4, 5))
    out = []
    for i, (d, label) in enumerate(zip(ds, labels)):
        r = i + 2
        out.append(Quantity(label=label, value=d["d_mm"], unit="mm", u=d["u_um"], u_unit="µm", k=K, U_unit="µm",
                            symbol=f"d({label})", ident={"from": d["from"], "to": d["to"]},
                            value_source=source, u_source=U_SOURCE,
                            cells=Cells(RESULTS, r, f"{d_col}{r}", f"{u_col}{r}", f"{U_col}{r}", k="K")))
    return out


def verdicts(task: Task, results: dict) -> list[Verdict]:
    """The MPE check (Forbes 2025 eq. (36), section 6.8) when the task has ``[mpe]``."""
    if "mpe_check" not in results:
        return []
    c = results["mpe_check"]
    return [Verdict("MPE check", c["C_max"], "C_max <= 1", MPE_WORDS[bool(c["conforms"])],
                    f"C_max = max over d of K u(d)/(A + d/B) on a grid of {c['grid_points']} distances "
                    f"0 ... {c['L_max_mm']:g} mm (Forbes 2025 eq. (36)); the model meets the MPE statement "
                    "E = A + d/B when C_max <= 1", value_cell="C_max",
                    verdict_cell=f'IF(C_max<=1,"{MPE_WORDS[True]}","{MPE_WORDS[False]}")')]


#: the MPE check in words, by whether C_max <= 1
MPE_WORDS = {True: "meets the MPE (C_max <= 1)", False: "violates the MPE (C_max > 1): divide the sigmas by C_max"}


def read_book(cells, rt, points_file: str) -> None:
    """The way back (``cmmwb read``): :func:`generator.pointcloud.reader.read_pointcloud`."""
    from .reader import read_pointcloud

    read_pointcloud(cells, rt, points_file)


def summary(results: dict) -> list[str]:
    ds = results["distances"]
    longest = max(ds, key=lambda d: d["d_mm"])
    lines = [f"{len(ds)} distances; longest {longest['from']}-{longest['to']} d = {longest['d_mm']:.2f} mm: "
             f"u = {longest['u_um']:.2f} µm, U = {longest['U_um']:.2f} µm"]
    if "mpe_check" in results:
        c = results["mpe_check"]
        lines.append(f"MPE check: C_max = {c['C_max']:.3f} at d = {c['d_at_max_mm']:.0f} mm "
                     f"({MPE_WORDS[bool(c['conforms'])]})")
    return lines


#: files `cmmwb new pointcloud` writes beside the task (never over an existing file)
NEW_TASK_FILES = {"points.csv": '''# A 100 mm gauge block measured on both end faces and a 200 mm one beside it (mm)
id,x,y,z,nx,ny,nz,probe
G1L,0,0,0,-1,0,0,P1
G1R,100,0,0,1,0,0,P1
G2L,0,30,0,-1,0,0,P1
G2R,200,30,0,1,0,0,P1
'''}

NEW_TASK = '''# cmmwb point-cloud task (Forbes 2025): distance uncertainties from six CMM influence factors.
# Units: coordinates mm, uncertainties µm, scale/squareness ppm (1e-6), rotations µrad.
# Build with:  cmmwb build THIS.toml --out DIR

[task]
kind = "pointcloud"
name = "my_pointcloud"          # file stem of the outputs
# K = 2                         # coverage factor for U when there is no [mpe]

[mpe]                           # E = A + L/B (µm, L in mm); K = coverage factor for C(d)
A_um = 1.0
B_mm = 500
K = 2
P_mm = 50                       # longest probe length in eq. (33); default: longest probe offset
# L_max_mm = 1000               # largest distance of the MPE check

[parameters]                    # Forbes 2025 Table 3 (MPE1 column); absent ones are 0
sigma_R_um = 0.20               # repeatability
sigma_S_ppm = 0.7               # global scale
sigma_Sa_ppm = 0.7              # per-axis scale
sigma_Q_ppm = 0.7               # squareness (µrad)
sigma_PQ_um = 0.20              # probe qualification, per probe unless a probe sets its own
sigma_ET_um = 0.2               # location errors (GP)
lambda_ET_mm = 200
sigma_ER_urad = 4.0             # rotation errors (GP)
lambda_ER_mm = 400
sigma_P0_um = 0.10              # probe radius
sigma_P_um = 0.10               # direction-dependent probing (GP)
lambda_P = 0.5

[[probes]]
id = "P1"
offset_mm = [0.0, 0.0, -20.0]   # stylus tip centre from the probe-head reference point
# sigma_PQ_um = 0.1             # optional per-probe override (also sigma_P0_um, sigma_P_um, lambda_P)

[points]
file = "points.csv"             # id,x,y,z,nx,ny,nz,probe  (mm; n = outward unit normal)
# or the points in this file:   rows = [{id = "G1L", x_mm = 0, y_mm = 0, z_mm = 0, nx = -1, ny = 0, nz = 0, probe = "P1"}, ...]

# Optional: which distances (default: every pair of points).  to = "*" means every other point.
# [[distances]]
# from = "F1"
# to = "F2"
# group = "LR"                  # free label used in the charts

# Optional: the part's temperature, the factor W (docs/workpiece.md); without the table W is off.
# [workpiece]
# material = "aluminium"        # or alpha_ppm_per_K = 23.1 (1e-6/K); aluminium 23.1, steel 11.5
# u_alpha_ppm_per_K = 1.0       # u(alpha)
# T_degC = 23.5                 # the part's temperature, or T_readings_degC = [23.3, 23.7]
# u_T_K = 0.3                   # u(T) of the thermometer
# corrected = true              # the CMM corrects to 20 °C (with alpha_corr_ppm_per_K, default alpha)
# fixture_mm = [0, 0, 0]        # where the part is held (it expands about this point)
# enabled = true                # W on/off

# Optional: conformity decisions (docs/conformity.md) and report fields for the Summary sheet.
# [decision]
# rule = "iso14253"             # iso14253 | simple | guarded_acceptance (r) | guarded_rejection (r) | specific_risk (max_pfa)
# [[decision.tolerances]]
# from = "G1L"
# to = "G1R"
# tol_mm = 0.002                # nominal_mm ± tol_mm (nominal: the task's d), or lsl_mm / usl_mm
# measured_mm = 100.0008        # optional; s_um and n_repeats add a type A repeatability
# [report]
# lab = "..."                   # also operator, cmm, artefact, job_id, notes
'''
