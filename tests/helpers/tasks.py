"""Task files written for tests: random point clouds with several probes, large plates (beyond the
native-formula limit), the 120-point bore, small feature tasks for every element type."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from cmmwb.generator.feature import book as feature_book
from cmmwb.xlfuncs.model.hyperparameters import in_table

from tests.helpers import EXAMPLES

ALL_FACTORS = dict(sigma_R_um=0.2, sigma_S_ppm=0.7, sigma_Sa_ppm=0.8, sigma_Q_ppm=0.9, sigma_PQ_um=0.2,
                   sigma_ET_um=0.3, lambda_ET_mm=150, sigma_ER_urad=4.0, lambda_ER_mm=350,
                   sigma_P0_um=0.1, sigma_P_um=0.15, lambda_P=0.5)


def parameters_toml(params) -> str:
    """The ``[parameters]`` table of a task file holding ``params`` (a core ``Parameters``, e.g.
    Forbes 2025 Table 3 MPE1 from ``cmmwb.xlfuncs.model``), so that tests do not type it out."""
    return "[parameters]\n" + "".join(f"{k} = {getattr(params, k)!r}\n" for k in in_table("parameters"))


def machine_task_toml(params, probes, *, name: str = "cmm", extra: str = "") -> str:
    """A pointcloud task file that only describes the machine (what ``cmmwb simulate``,
    ``diagnose`` and ``calibrate`` read): ``params`` as its ``[parameters]``, ``probes`` as
    ``(id, offset_mm)`` pairs, ``extra`` TOML lines after ``[task]`` (e.g. an ``[mpe]`` table)."""
    text = f'[task]\nkind = "pointcloud"\nname = "{name}"\n{extra}\n' + parameters_toml(params)
    for pid, offset in probes:
        text += f'\n[[probes]]\nid = "{pid}"\noffset_mm = [{", ".join(repr(float(v)) for v in offset)}]\n'
    return text


#: a [workpiece] table with every term of the factor W (docs/workpiece.md): an aluminium part at 23.5 °C,
#: 0.4 K across it, corrected with a nominal alpha 1e-6/K off the part's, held at (10, -20, 5) mm
WORKPIECE_ALL_TERMS = """[workpiece]
alpha_ppm_per_K = 23.1
u_alpha_ppm_per_K = 1.0
T_degC = 23.5
u_T_K = 0.3
dT_K = 0.4
alpha_corr_ppm_per_K = 22.1
fixture_mm = [10.0, -20.0, 5.0]
"""


def write_random_task(folder: Path, seed: int, m: int = 8, probes: int = 2, name: str | None = None,
                      labels: list[str] | None = None, mpe: bool = True, workpiece: str = "") -> Path:
    rng = np.random.default_rng(seed)
    X = rng.uniform(-300, 300, (m, 3))
    N = rng.normal(size=(m, 3))
    N /= np.linalg.norm(N, axis=1)[:, None]
    labels = labels or [f"Q{i + 1}" for i in range(m)]
    rows = ["id,x,y,z,nx,ny,nz,probe"]
    for i in range(m):
        rows.append(",".join([labels[i], *(f"{v:.17g}" for v in X[i]), *(f"{v:.17g}" for v in N[i]),
                              f"P{i % probes + 1}"]))
    name = name or f"random_{seed}"
    (folder / f"{name}.csv").write_text("\n".join(rows) + "\n")
    probe_txt = ""
    for k in range(probes):
        off = rng.uniform(-40, 40, 3)
        probe_txt += f'[[probes]]\nid = "P{k + 1}"\noffset_mm = [{off[0]:.17g}, {off[1]:.17g}, {off[2]:.17g}]\n'
        if k == 1:
            probe_txt += "sigma_PQ_um = 0.3\nsigma_P0_um = 0.05\n"
        probe_txt += "\n"
    params = "\n".join(f"{k} = {v}" for k, v in ALL_FACTORS.items())
    mpe_txt = '[mpe]\nA_um = 1.5\nB_mm = 400\nK = 2\n' if mpe else ""
    path = folder / f"{name}.toml"
    path.write_text(f'[task]\nkind = "pointcloud"\nname = "{name}"\n\n{mpe_txt}\n[parameters]\n{params}\n\n'
                    f'{probe_txt}[points]\nfile = "{name}.csv"\n' + (f"\n{workpiece}" if workpiece else ""))
    return path


def write_large_task(folder: Path, m: int, name: str, *, star: bool = True, labels=None, seed: int = 5,
                     mpe: bool = True, distances: tuple = ()) -> Path:
    """m points on a plate 800 x 800 x 200 mm probed with three probes; distances from the first
    point to every other (``star``) plus one more, the given (from, to) ``distances``, or every
    pair."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-400, 400, (m, 3))
    X[:, 2] *= 0.25
    N = rng.normal(size=(m, 3))
    N /= np.linalg.norm(N, axis=1)[:, None]
    labels = labels or [f"F{i + 1}" for i in range(m)]
    rows = ["id,x,y,z,nx,ny,nz,probe"] + [
        ",".join([labels[i], *(f"{v:.17g}" for v in X[i]), *(f"{v:.17g}" for v in N[i]), f"P{i % 3 + 1}"])
        for i in range(m)]
    (folder / f"{name}.csv").write_text("\n".join(rows) + "\n")
    params = "\n".join(f"{k} = {v}" for k, v in ALL_FACTORS.items())
    dist = (f'[[distances]]\nfrom = "{labels[0]}"\nto = "*"\ngroup = "star"\n\n'
            f'[[distances]]\nfrom = "{labels[1]}"\nto = "{labels[2]}"\n') if star else ""
    dist += "".join(f'[[distances]]\nfrom = "{a}"\nto = "{b}"\n\n' for a, b in distances)
    mpe_txt = "[mpe]\nA_um = 1.5\nB_mm = 400\nK = 2\n" if mpe else ""
    path = folder / f"{name}.toml"
    path.write_text(f'''[task]
kind = "pointcloud"
name = "{name}"

{mpe_txt}
[parameters]
{params}

[[probes]]
id = "P1"
offset_mm = [0, 0, -50]

[[probes]]
id = "P2"
offset_mm = [20, 40, -30]
sigma_PQ_um = 0.3
sigma_P0_um = 0.05

[[probes]]
id = "P3"
offset_mm = [-30, 0, -10]
lambda_P = 0.8

[points]
file = "{name}.csv"

{dist}''')
    return path



#: points of the bore (above the feature workbook's native limit)
M = 120


def write_bore_task(folder: Path, name: str = "bore120") -> Path:
    rng = np.random.default_rng(7)
    tilt = 0.1
    rows = ["id,x,y,z,nx,ny,nz,probe"]
    for q, (z, t) in enumerate((z, t) for z in np.linspace(-20, 20, 5)
                               for t in np.linspace(0, 2 * np.pi, 24, endpoint=False)):
        r = 25 + rng.normal(0, 0.002)                   # 2 µm form error
        c, s = np.cos(t), np.sin(t)
        X = (100 + r * c, 50 + r * s * np.cos(tilt) - z * np.sin(tilt), -30 + r * s * np.sin(tilt) + z * np.cos(tilt))
        N = (c, s * np.cos(tilt), s * np.sin(tilt))
        rows.append(",".join([f"B{q + 1}", *(f"{v:.12g}" for v in (*X, *N)), "P1" if q % 2 else "P2"]))
    assert len(rows) == M + 1 and M > feature_book.FEATURE_NATIVE_MAX_POINTS
    (folder / f"{name}.csv").write_text("\n".join(rows) + "\n")
    path = folder / f"{name}.toml"
    path.write_text(f'''[task]
kind = "feature"
name = "{name}"

[feature]
type = "cylinder"
axis_hint = [0, -0.1, 1]
reference_mm = [100, 50, -30]
weights = {{ B3 = 0.5, B7 = 0 }}

[points]
file = "{name}.csv"
{FULL_MODEL}
[[probes]]
id = "P2"
offset_mm = [30.0, 10.0, -40.0]
sigma_PQ_um = 0.3
''')
    return path



FULL_MODEL = """
[parameters]
sigma_R_um = 0.3
sigma_S_ppm = 1.0
sigma_Sa_ppm = 0.8
sigma_Q_ppm = 0.9
sigma_PQ_um = 0.25
sigma_ET_um = 0.3
lambda_ET_mm = 150
sigma_ER_urad = 5.0
lambda_ER_mm = 300
sigma_P0_um = 0.1
sigma_P_um = 0.15
lambda_P = 0.6

[[probes]]
id = "P1"
offset_mm = [0.0, 0.0, -50.0]
"""

#: small tasks for the element types the shipped examples do not cover cheaply
SMALL_TASKS = {
    "line_space": """
        [task]
        kind = "feature"
        name = "line_space"
        [feature]
        type = "line"
        [sampling]
        pattern = "line_segment"
        center_mm = [120.0, -40.0, 60.0]
        axis = [1.0, 2.0, 0.5]
        half_length_mm = 40.0
        n_points = 8
        [planning]
        sweep = "half_length_mm"
        values = [10, 40, 100]
    """,
    "circle_space": """
        [task]
        kind = "feature"
        name = "circle_space"
        [feature]
        type = "circle"
        circle_plane = "space"
        [sampling]
        pattern = "circle_arc"
        center_mm = [80.0, 30.0, -20.0]
        axis = [0.3, -0.2, 1.0]
        r0_mm = 20.0
        arc_deg = 200.0
        n_points = 10
        [planning]
        sweep = "arc_deg"
        values = [360, 180, 90]
    """,
    "cylinder_small": """
        [task]
        kind = "feature"
        name = "cylinder_small"
        [feature]
        type = "cylinder"
        [sampling]
        pattern = "cylinder_patch"
        center_mm = [-50.0, 120.0, 10.0]
        axis = [0.0, 1.0, 0.1]
        r0_mm = 15.0
        arc_deg = 240.0
        half_height_mm = 25.0
        n_theta = 6
        n_z = 3
        [planning]
        sweep = "arc_deg"
        values = [360, 240, 90]
    """,
    "cone_small": """
        [task]
        kind = "feature"
        name = "cone_small"
        [feature]
        type = "cone"
        reference_mm = [10.0, 20.0, 30.0]
        [sampling]
        pattern = "cone_patch"
        center_mm = [10.0, 20.0, 30.0]
        axis = [0.0, 0.0, 1.0]
        r0_mm = 30.0
        phi_deg = 25.0
        arc_deg = 300.0
        half_height_mm = 15.0
        n_theta = 6
        n_z = 3
        [planning]
        sweep = "phi_deg"
        values = [0, 25, 60]
    """,
    "sphere_patch": """
        [task]
        kind = "feature"
        name = "sphere_patch"
        [feature]
        type = "sphere"
        [sampling]
        pattern = "sphere_patch"
        center_mm = [0.0, 50.0, 100.0]
        r0_mm = 12.0
        theta_deg = [-60.0, 120.0]
        phi_range_deg = [-10.0, 70.0]
        n_theta = 4
        n_phi = 3
        [planning]
    """,
}

#: shipped examples that are cheap to recalculate (planning patterns not covered above)
SHIPPED = ["feature_plane_face.toml", "feature_table1_circle_arc.toml",
           "feature_table8_sphere_nine.toml", "feature_table8_sphere_six.toml"]


def feature_task_path(case: str, tmp: Path) -> Path:
    if case in SMALL_TASKS:
        p = tmp / f"{case}.toml"
        p.write_text(textwrap.dedent(SMALL_TASKS[case]) + FULL_MODEL)
        return p
    return EXAMPLES / case
