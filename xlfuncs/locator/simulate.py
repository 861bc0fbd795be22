"""Simulated recordings: realistic layouts measured by a CMM drawn from the Forbes 2025
point-cloud model, with chosen planted effects (``cmmwb simulate``).

The machine's own errors are drawn factor by factor from the generative model behind eq. (28)
(not from the record covariance that ``diagnose`` computes, so the two are independent checks of
each other):

* R   every probing: N(0, sigma_R^2 I)                                           eq. (8)
* PQ  every probe: one vector N(0, sigma_PQ,k^2 I)                               eq. (9)
* S   seven scale/squareness parameters b ~ N(0, V_B), delta = G(x - p) b       eqs. (10)-(13)
* ET  three independent Gaussian processes over the ram positions x - p         eq. (21)
* ER  three rotation processes alpha, delta = alpha x p                          eqs. (22)-(25)
* P   per probe: radius error e_P0 + process over the normals, along n          eqs. (26)-(27)

The planted effects follow the definitions of ``docs/recordings.md`` section 4, written
here independently of :mod:`xlfuncs.locator.effects` (the angular motions with exact rotation matrices,
lengths recomputed from the disturbed points).

Layouts (machine coordinates in mm, working volume from machine zero):

``iso10360``  ISO 10360-2 length test: 7 positions (x, y, z and the 4 space diagonals) through
              the centre of the volume, 5 bidirectional gauge-block lengths each, repeated
              (each repetition one probe of the task, in turn)
``stepgauge`` step gauge of Forbes 2025 section 7 (26 steps, faces at 20(k-1) and 20(k-1)+10),
              lengths from the first face to every other face (the first probing is shared),
              along x, y and the xy diagonal; with two probes left faces use the first, right
              faces the second (scenario II)
``ballplate`` 5 x 5 ball plate (pitch 100 mm, ball centres) placed rotated in the xy plane,
              measured in passes (one probe per pass); point records
``holeplate`` 4 x 4 hole plate, 4 points on every hole wall with their normals, 2-D records
``spheres``   four spheres at different heights, 13 points each with outward normals, measured
              with every probe; point records
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import pointcloud as pc
from ..errors import ModelError
from ..model import sq_dists
from .recordings import LengthRecords, PointRecords

LAYOUTS = ("iso10360", "stepgauge", "ballplate", "holeplate", "spheres", "scan")
VOLUME_MM = (1000.0, 800.0, 600.0)
EFFECT_NAMES = (
    "scale", "scale_x", "scale_y", "scale_z", "squareness_xy", "squareness_xz", "squareness_yz",
    "thermal_expansion", "probe_radius", "probe_qualification",
    "EAX", "EBX", "ECX", "EAY", "EBY", "ECY", "EAZ", "EBZ", "ECZ", "scale_drift", "offset_drift",
    # second edition (docs/recordings.md section 7)
    "EYX", "EZX", "EXY", "EZY", "EXZ", "EYZ", "reversal_x", "reversal_y", "reversal_z",
    "thermal_gradient_x", "thermal_gradient_y", "thermal_gradient_z", "probe_lobing",
    "periodic_x", "periodic_y", "periodic_z")
#: periodic errors: a, b (µm) and the period (mm)
PERIODIC_NAMES = ("periodic_x", "periodic_y", "periodic_z")
#: straightness E<deviation><carriage>: two coefficients (orders 2 and 3, µm)
STRAIGHTNESS_NAMES = ("EYX", "EZX", "EXY", "EZY", "EXZ", "EYZ")


@dataclass
class Layout:
    """True geometry of a measurement: the probings (tip positions, normals, probe index) and
    the records (length: two probings each; point: one probing each)."""

    kind: str
    name: str
    probes: tuple[pc.Probe, ...]
    X: np.ndarray                      # (m, 3) true tip positions, mm
    N: np.ndarray | None               # (m, 3) outward normals
    k: np.ndarray                      # (m,) probe index
    ids: list[str]
    group: list[str]
    time_s: np.ndarray                 # per record
    I: np.ndarray | None = None        # length records: probing index of each end
    J: np.ndarray | None = None
    X_nom: np.ndarray | None = None    # point records: nominal coordinates (artefact frame)
    planar_z: float | None = None      # point records written as 2-D data at this z
    temperature_C: np.ndarray | None = None
    extra: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.ids)


def _centre() -> np.ndarray:
    return np.array(VOLUME_MM) / 2.0


ISO_DIRECTIONS = {
    "X": (1, 0, 0), "Y": (0, 1, 0), "Z": (0, 0, 1),
    "D1": (1, 1, 1), "D2": (-1, 1, 1), "D3": (1, -1, 1), "D4": (1, 1, -1),
}


def _times(n: int, hours: float) -> np.ndarray:
    return np.arange(1, n + 1) * (hours * 3600.0 / n)


def iso10360(probes, repeats: int = 3, fractions=(0.1, 0.25, 0.4, 0.55, 0.7), hours: float = 6.0,
             positions=tuple(ISO_DIRECTIONS)) -> Layout:
    """ISO 10360-2: 7 positions x 5 lengths x repeats; bidirectional gauge blocks centred at the
    centre of the volume; repetition r uses probe r mod (number of probes)."""
    c = _centre()
    half = np.array(VOLUME_MM) / 2.0 - 25.0
    X, N, K, I, J, ids, grp = [], [], [], [], [], [], []
    for r in range(repeats):
        kprobe = r % len(probes)
        for pos in positions:
            d = np.array(ISO_DIRECTIONS[pos], dtype=float)
            d /= np.linalg.norm(d)
            tmax = float(np.min(half / np.maximum(np.abs(d), 1e-12)))
            for q, f in enumerate(fractions):
                L = round(2 * tmax * f)
                for sgn in (-1.0, 1.0):
                    X.append(c + sgn * 0.5 * L * d)
                    N.append(sgn * d)
                    K.append(kprobe)
                I.append(len(X) - 2)
                J.append(len(X) - 1)
                ids.append(f"{pos}-L{q + 1}-r{r + 1}")
                grp.append(pos)
    n = len(ids)
    return Layout("length", "iso10360", tuple(probes), np.array(X), np.array(N), np.array(K), ids, grp,
                  _times(n, hours), I=np.array(I), J=np.array(J))


def stepgauge(probes, positions=("x", "y", "xy"), steps: int = 26, repeats: int = 1,
              hours: float = 3.0) -> Layout:
    """Forbes 2025 section 7 step gauge: lengths from the first (left) face to every other face."""
    c = _centre()
    dirs = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1), "xy": (1, 1, 0), "x-y": (1, -1, 0), "xz": (1, 0, 1)}
    X, N, K, I, J, ids, grp = [], [], [], [], [], [], []
    two = len(probes) >= 2
    span = 20.0 * (steps - 1) + 10.0
    for r in range(repeats):
        for pos in positions:
            d = np.array(dirs[pos], dtype=float)
            d /= np.linalg.norm(d)
            o = c - 0.5 * span * d + (0, 0, -50.0 * (positions.index(pos)))
            first = None
            for kstep in range(steps):
                for side, off, sgn in (("L", 0.0, -1.0), ("R", 10.0, 1.0)):
                    X.append(o + (20.0 * kstep + off) * d)
                    N.append(sgn * d)
                    K.append(1 if (two and side == "R") else 0)
                    q = len(X) - 1
                    if first is None:
                        first = q
                        continue
                    I.append(first)
                    J.append(q)
                    ids.append(f"{pos}-L1-{side}{kstep + 1}-r{r + 1}")
                    grp.append(f"{pos} L{side}")
    n = len(ids)
    return Layout("length", "stepgauge", tuple(probes), np.array(X), np.array(N), np.array(K), ids, grp,
                  _times(n, hours), I=np.array(I), J=np.array(J))


def _placed(Xn: np.ndarray, angle_deg: float, centre: np.ndarray) -> np.ndarray:
    th = math.radians(angle_deg)
    R = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0, 0, 1.0]])
    Xc = Xn - Xn.mean(axis=0)
    return Xc @ R.T + centre


def ballplate(probes, grid: int = 5, pitch: float = 100.0, passes: int = 2, angle_deg: float = 30.0,
              hours: float = 2.0, z_mm: float = 150.0) -> Layout:
    """Ball plate (ball centres, no normals) in the xy plane; pass p uses probe p mod K, passes
    alternate the scanning direction (serpentine)."""
    grid_pts = [(i, j) for j in range(grid) for i in (range(grid) if j % 2 == 0 else reversed(range(grid)))]
    Xn, ids, grp, K = [], [], [], []
    for p in range(passes):
        seq = grid_pts if p % 2 == 0 else grid_pts[::-1]
        for (i, j) in seq:
            Xn.append((i * pitch, j * pitch, 0.0))
            ids.append(f"B{i + 1}{j + 1}-p{p + 1}")
            grp.append(f"pass {p + 1}")
            K.append(p % len(probes))
    Xn = np.array(Xn)
    centre = _centre().copy()
    centre[2] = z_mm
    X = _placed(Xn, angle_deg, centre)
    n = len(ids)
    return Layout("point", "ballplate", tuple(probes), X, None, np.array(K), ids, grp, _times(n, hours),
                  X_nom=Xn)


def holeplate(probes, grid: int = 4, pitch: float = 120.0, radius: float = 10.0, passes: int = 1,
              angle_deg: float = -20.0, hours: float = 2.0, z_mm: float = 100.0) -> Layout:
    """Hole plate: 4 points on every hole wall (outward surface normal points to the hole axis),
    written as 2-D point records."""
    Xn, N, ids, grp, K = [], [], [], [], []
    for p in range(passes):
        for j in range(grid):
            for i in range(grid):
                for q, phi in enumerate((0.0, 90.0, 180.0, 270.0)):
                    e = np.array([math.cos(math.radians(phi)), math.sin(math.radians(phi)), 0.0])
                    Xn.append(np.array([i * pitch, j * pitch, 0.0]) + radius * e)
                    N.append(-e)
                    ids.append(f"H{i + 1}{j + 1}-{q + 1}-p{p + 1}")
                    grp.append(f"hole {i + 1}{j + 1}")
                    K.append(p % len(probes))
    Xn = np.array(Xn)
    th = math.radians(angle_deg)
    R = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0, 0, 1.0]])
    centre = _centre().copy()
    centre[2] = z_mm
    X = _placed(Xn, angle_deg, centre)
    N = np.array(N) @ R.T
    n = len(ids)
    return Layout("point", "holeplate", tuple(probes), X, N, np.array(K), ids, grp, _times(n, hours),
                  X_nom=Xn, planar_z=z_mm)


def spheres(probes, radius: float = 12.5, hours: float = 2.0) -> Layout:
    """Four spheres at different places and heights, 13 points each (pole and two rings of six),
    measured with every probe."""
    centres = np.array([[250.0, 200.0, 100.0], [750.0, 200.0, 300.0], [750.0, 600.0, 150.0],
                        [250.0, 600.0, 450.0]])
    dirs = [np.array([0.0, 0.0, 1.0])]
    for el in (45.0, 0.0):
        for az in range(0, 360, 60):
            a, e = math.radians(az + (30 if el == 0 else 0)), math.radians(el)
            dirs.append(np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]))
    X, N, ids, grp, K = [], [], [], [], []
    for kp in range(len(probes)):
        for s, c in enumerate(centres):
            for q, d in enumerate(dirs):
                X.append(c + radius * d)
                N.append(d)
                ids.append(f"S{s + 1}-{q + 1}-{probes[kp].id}")
                grp.append(f"sphere {s + 1}")
                K.append(kp)
    X = np.array(X)
    n = len(ids)
    # nominal coordinates in an artefact frame: shifted and rotated copy of the true ones
    th = math.radians(10.0)
    R = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0, 0, 1.0]])
    Xn = (X - X.mean(axis=0)) @ R
    return Layout("point", "spheres", tuple(probes), X, np.array(N), np.array(K), ids, grp,
                  _times(n, hours), X_nom=Xn)


def scan(probes, points: int = 20_000, radius: float = 12.5, hours: float = 2.0,
         z_min: float = 0.0) -> Layout:
    """A dense scan (optical CMM, laser scanner) of the four spheres of :func:`spheres`:
    ``points`` point records, a Fibonacci lattice on each sphere's cap above the normal's
    z = ``z_min``, probes taking turns; nominal coordinates in a shifted, rotated artefact frame."""
    centres = np.array([[250.0, 200.0, 100.0], [750.0, 200.0, 300.0], [750.0, 600.0, 150.0],
                        [250.0, 600.0, 450.0]])
    per = -(-points // 4)
    q = np.arange(per) + 0.5
    z = 1.0 - (1.0 - z_min) * q / per
    phi = q * math.pi * (3.0 - math.sqrt(5.0))
    rxy = np.sqrt(1 - z * z)
    D = np.column_stack([rxy * np.cos(phi), rxy * np.sin(phi), z])
    X = np.concatenate([c + radius * D for c in centres])[:points]
    N = np.concatenate([D] * 4)[:points]
    grp = [f"sphere {1 + i // per}" for i in range(points)]
    ids = [f"S{1 + i // per}-{1 + i % per}" for i in range(points)]
    K = np.arange(points) % len(probes)
    th = math.radians(10.0)
    R = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0, 0, 1.0]])
    Xn = (X - X.mean(axis=0)) @ R
    return Layout("point", "scan", tuple(probes), X, N, K, ids, grp, _times(points, hours), X_nom=Xn)


def layout(name: str, probes, **kw) -> Layout:
    builders = {"iso10360": iso10360, "stepgauge": stepgauge, "ballplate": ballplate,
                "holeplate": holeplate, "spheres": spheres, "scan": scan}
    if name not in builders:
        raise ModelError(f"unknown layout {name!r}; choose one of {', '.join(LAYOUTS)}")
    return builders[name](tuple(probes), **kw)


# ---------------------------------------------------------------------------------------------
# the machine's own errors: a draw from the Forbes 2025 model
# ---------------------------------------------------------------------------------------------

#: above this many points a GP draw uses the low-rank factor (the dense eigen-decomposition
#: would need m^2 numbers)
GP_DENSE_MAX = 5000


def _gp(points: np.ndarray, sigma: float, lam: float, rng, size: int = 1) -> np.ndarray:
    """``size`` independent draws of a Gaussian process with kernel sigma^2 exp(-d^2/lam^2)."""
    m = len(points)
    if sigma <= 0 or m == 0:
        return np.zeros((m, size))
    z = rng.standard_normal((m, size))
    if m > GP_DENSE_MAX:   # a draw from the Nystrom factor K ~ L L^T of xlfuncs.lowrank
        from .. import lowrank as lr

        fac, _trace = lr.controlled_factor(points, 1.0 / lam**2)
        blocks = range(0, m, 8192)
        Lt = [fac.rows(points[i0:i0 + 8192]) for i0 in blocks]          # r x block each
        # (L L^T)^(1/2) z = L (L^T L)^(-1/2) L^T z: the same for any L' = L Q, so the draw does
        # not depend on which pivots (ties on a regular grid) the BLAS kernel led to
        y = sum(Lb @ z[i0:i0 + 8192] for Lb, i0 in zip(Lt, blocks))
        w, V = np.linalg.eigh(sum(Lb @ Lb.T for Lb in Lt))
        keep = w > 1e-12 * w[-1]
        y = V[:, keep] @ ((V[:, keep].T @ y) / np.sqrt(w[keep])[:, None])
        return sigma * np.concatenate([Lb.T @ y for Lb in Lt])
    K = sigma**2 * np.exp(-sq_dists(points, points) / lam**2)
    w, V = np.linalg.eigh(K)
    # the symmetric square root K^(1/2) z, not V diag(w)^(1/2) z: eigenvectors of a degenerate
    # eigenvalue (a symmetric grid has many) are any basis of their space and the BLAS kernel
    # picks it, while K^(1/2) is unique, so a seeded draw is the same on every CPU; eigenvalues
    # below 1e-13 of the largest are rounding (error ~ 1e-16 x the largest) and are dropped
    keep = w > 1e-13 * w[-1]
    return V[:, keep] @ (np.sqrt(w[keep])[:, None] * (V[:, keep].T @ z))


def model_errors(X: np.ndarray, N: np.ndarray | None, k: np.ndarray, probes, params: pc.Parameters,
                 rng) -> np.ndarray:
    """Displacement (µm, m x 3) of every probing drawn from the generative model of eq. (28)."""
    m = len(X)
    P = np.array([p.offset_mm for p in probes], dtype=float)[k]
    U = X - P
    pr = [p.resolved(params) for p in probes]
    delta = params.sigma_R_um * rng.standard_normal((m, 3))
    ePQ = np.array([p.sigma_PQ_um * rng.standard_normal(3) for p in pr])
    delta += ePQ[k]
    b = np.sqrt(pc.V_S_diag_um_per_mm2(params)) * rng.standard_normal(7)   # µm/mm
    b_aa, b_xx, b_yy, b_zz, b_xy, b_xz, b_yz = b
    delta[:, 0] += U[:, 0] * (b_aa + b_xx) + U[:, 1] * b_xy + U[:, 2] * b_xz
    delta[:, 1] += U[:, 1] * (b_aa + b_yy) + U[:, 2] * b_yz
    delta[:, 2] += U[:, 2] * (b_aa + b_zz)
    if params.sigma_ET_um > 0:
        delta += _gp(U, params.sigma_ET_um, params.lambda_ET_mm, rng, 3)
    if params.sigma_ER_urad > 0 and np.any(P):
        alpha = _gp(U, params.sigma_ER_urad, params.lambda_ER_mm, rng, 3)     # µrad
        delta += 1e-3 * np.cross(alpha, P)                                  # µrad * mm = 1e-3 µm
    if N is not None:
        for kk, p in enumerate(pr):
            sel = np.flatnonzero(k == kk)
            if sel.size == 0:
                continue
            e = p.sigma_P0_um * rng.standard_normal()
            if p.sigma_P_um > 0:
                e = e + _gp(N[sel], p.sigma_P_um, p.lambda_P, rng, 1)[:, 0]
            delta[sel] += np.asarray(e)[..., None] * N[sel] if np.ndim(e) else e * N[sel]
    return delta


# ---------------------------------------------------------------------------------------------
# planted effects (docs/recordings.md section 4), written independently of xlfuncs.locator.effects
# ---------------------------------------------------------------------------------------------

def _rot(axis: int, angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    if axis == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 1:
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _per_probe(name: str, v, ids: list[str], labels: str, count: str, *, reference: bool = False,
               finite: bool = False) -> dict:
    """{probe id: vector} of a per-probe effect, checked: known probes, len(labels) components
    (finite ones with ``finite``), not the first (reference) probe with ``reference``."""
    if not isinstance(v, dict):
        raise ModelError(f"{name} needs {{probe id: ({labels})}} in µm")
    for pid, vec in v.items():
        if pid not in ids:
            raise ModelError(f"{name}: unknown probe {pid!r} (probes: {', '.join(ids)})")
        if reference and pid == ids[0]:
            raise ModelError(f"{name}: {pid} is the reference probe (the first); plant the error on another probe")
        if len(vec) != len(labels.split(", ")) or (finite and not np.all(np.isfinite(np.asarray(vec, dtype=float)))):
            raise ModelError(f"{name}: {count} ({labels}) per probe")
    return {pid: np.asarray(vec, dtype=float) for pid, vec in v.items()}


def check_effects(planted: dict, probes) -> dict:
    ids = [p.id for p in probes]
    out = {}
    for name, v in planted.items():
        if name not in EFFECT_NAMES:
            raise ModelError(f"unknown effect {name!r}; choose one of {', '.join(EFFECT_NAMES)}")
        if name == "probe_qualification":
            out[name] = _per_probe(name, v, ids, "dx, dy, dz", "three components", reference=True)
        elif name == "offset_drift":
            vec = np.asarray(v, dtype=float).reshape(-1)
            if vec.shape != (3,):
                raise ModelError("offset_drift needs three components (vx, vy, vz) in µm/h")
            out[name] = vec
        elif name == "probe_lobing":
            out[name] = _per_probe(name, v, ids, "c2, s2, c3, s3, c4, s4", "six numbers", finite=True)
        elif name in PERIODIC_NAMES:
            vec = np.asarray(v, dtype=float).reshape(-1)
            if vec.shape != (3,) or not np.all(np.isfinite(vec)) or vec[2] <= 0:
                raise ModelError(f"{name} needs a, b (µm) and the period (mm, above 0)")
            out[name] = vec
        elif name in STRAIGHTNESS_NAMES:
            vec = np.asarray(v, dtype=float).reshape(-1)
            if vec.shape != (2,) or not np.all(np.isfinite(vec)):
                raise ModelError(f"{name} needs two coefficients (orders 2 and 3 of the travel) in µm")
            out[name] = vec
        else:
            val = float(v)
            if not math.isfinite(val):
                raise ModelError(f"{name}: not a finite number")
            out[name] = val
    return out


def planted_probing(L: Layout, planted: dict, t_probe: np.ndarray, T_probe: np.ndarray) -> np.ndarray:
    """Displacement (µm) of every probing by the planted probing-level effects."""
    X = L.X
    m = len(X)
    P = np.array([p.offset_mm for p in L.probes], dtype=float)[L.k]
    U = X - P
    point = L.kind == "point"
    c = X.mean(axis=0) if point else np.zeros(3)
    Uc = U - c if point else U
    delta = np.zeros((m, 3))
    # scale and squareness: x' = B x (Forbes 2025 eq. 10) on the ram positions
    B = np.zeros((3, 3))
    B += planted.get("scale", 0.0) * np.eye(3)
    for a, ax in enumerate("xyz"):
        B[a, a] += planted.get(f"scale_{ax}", 0.0)
    B[0, 1] += planted.get("squareness_xy", 0.0)
    B[0, 2] += planted.get("squareness_xz", 0.0)
    B[1, 2] += planted.get("squareness_yz", 0.0)
    delta += 1e-3 * Uc @ B.T                      # (µm/m or µrad) * mm = 1e-3 µm
    if "probe_radius" in planted:
        if L.N is None:
            raise ModelError("probe_radius needs a layout with normals")
        delta += planted["probe_radius"] * L.N
    for pid, vec in planted.get("probe_qualification", {}).items():
        kk = [p.id for p in L.probes].index(pid)
        delta[L.k == kk] += vec
    for name in EFFECT_NAMES:
        if name.startswith("E") and name[1] in "ABC" and name in planted:
            rot, car = "ABC".index(name[1]), "XYZ".index(name[2])
            kappa = planted[name] * 1e-6 * 1e-3        # µrad/m -> rad/mm
            for i in range(m):
                Rm = _rot(rot, kappa * U[i, car])
                delta[i] += (Rm @ P[i] - P[i]) * 1000.0
    # straightness (section 7): the carriage deviates along another axis by c2 P2 + c3 P3 of its
    # travel normalized over the travel of the layout's probings (numpy's Legendre series)
    for name in STRAIGHTNESS_NAMES:
        if name in planted:
            dev, car = "XYZ".index(name[1]), "XYZ".index(name[2])
            lo, hi = U[:, car].min(), U[:, car].max()
            s = (U[:, car] - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
            delta[:, dev] += np.polynomial.legendre.legval(s, [0.0, 0.0, *planted[name]])
    # periodic error (section 7): the axis reads off by Re((b - i a) exp(i 2 pi t/P)) = a sin + b cos
    # of its travel t about the middle of the layout's probings
    for a, name in enumerate(PERIODIC_NAMES):
        if name in planted:
            amp_a, amp_b, period = planted[name]
            t = U[:, a] - 0.5 * (U[:, a].min() + U[:, a].max())
            delta[:, a] += np.real((amp_b - 1j * amp_a) * np.exp(2j * np.pi * t / period))
    # probe lobing (section 7): the radius of probe k depends on the azimuth phi of the normal about
    # the stylus axis, e(phi) = sum c_j cos(j phi) + s_j sin(j phi), j = 2..4, along the normal
    for pid, vec in planted.get("probe_lobing", {}).items():
        if L.N is None:
            raise ModelError("probe_lobing needs a layout with normals")
        kk = [p.id for p in L.probes].index(pid)
        phi = np.arctan2(L.N[:, 1], L.N[:, 0])
        on = (L.k == kk) & (np.hypot(L.N[:, 0], L.N[:, 1]) > 0.1)
        e = sum(vec[2 * q] * np.cos(j * phi) + vec[2 * q + 1] * np.sin(j * phi) for q, j in enumerate((2, 3, 4)))
        delta += (e * on)[:, None] * L.N
    # reversal (section 7): +r along the axis where the probe approached in +axis, i.e. against
    # an outward normal pointing to -axis by more than 0.1
    for a, ax in enumerate("xyz"):
        if f"reversal_{ax}" in planted:
            if L.N is None:
                raise ModelError(f"reversal_{ax} needs a layout with normals")
            side = np.sign(-L.N[:, a]) * (np.abs(L.N[:, a]) > 0.1)
            delta[:, a] += planted[f"reversal_{ax}"] * side
    if point:
        if "thermal_expansion" in planted:
            delta += 1e-3 * planted["thermal_expansion"] * (T_probe - 20.0)[:, None] * (X - c)
        for a, ax in enumerate("xyz"):
            # thermal gradient (section 7): the expansion coefficient (ppm/K) at a point is g times
            # its distance along the axis from the centroid, in metres
            if f"thermal_gradient_{ax}" in planted:
                alpha = planted[f"thermal_gradient_{ax}"] * (X[:, a] - c[a]) / 1000.0
                delta += 1e-3 * (alpha * (T_probe - 20.0))[:, None] * (X - c)
        if "scale_drift" in planted:
            delta += 1e-3 * planted["scale_drift"] * (t_probe / 3600.0)[:, None] * Uc
        if "offset_drift" in planted:
            delta += (t_probe / 3600.0)[:, None] * planted["offset_drift"][None, :]
    elif "offset_drift" in planted:
        raise ModelError("offset_drift is a point-record effect (it cancels in lengths)")
    return delta


def simulate(L: Layout, params: pc.Parameters, planted: dict | None = None, seed: int | None = 0,
             temperature_C=None, rng=None):
    """Recordings of layout ``L`` measured by a CMM drawn from the model ``params``, with the
    planted effects ``planted`` ({name: value in the unit of docs/recordings.md section 4}).

    ``temperature_C``: None (no temperature column), a number (constant), a pair (linear ramp
    over the session) or an array (one value per record)."""
    rng = np.random.default_rng(seed) if rng is None else rng
    planted = check_effects(planted or {}, L.probes)
    n = L.n
    t_rec = L.time_s
    if temperature_C is None:
        T_rec = None
        for name in planted:
            if name == "thermal_expansion" or name.startswith("thermal_gradient_"):
                raise ModelError(f"{name} needs temperatures (give temperature_C)")
    elif np.ndim(temperature_C) == 0:
        T_rec = np.full(n, float(temperature_C))
    elif len(temperature_C) == 2 and n != 2:
        T0, T1 = map(float, temperature_C)
        T_rec = T0 + (T1 - T0) * (t_rec - t_rec.min()) / max(np.ptp(t_rec), 1e-9)
    else:
        T_rec = np.asarray(temperature_C, dtype=float).reshape(n)
    # probing times / temperatures: those of the record that uses the probing last
    m = len(L.X)
    if L.kind == "length":
        t_probe = np.zeros(m)
        t_probe[L.I] = t_rec
        t_probe[L.J] = t_rec
        T_probe = np.full(m, 20.0) if T_rec is None else np.zeros(m)
        if T_rec is not None:
            T_probe[L.I] = T_rec
            T_probe[L.J] = T_rec
    else:
        t_probe = t_rec
        T_probe = np.full(m, 20.0) if T_rec is None else T_rec
    delta = model_errors(L.X, L.N, L.k, L.probes, params, rng)
    delta += planted_probing(L, planted, t_probe, T_probe)
    Xind = L.X + delta * 1e-3
    P = np.array([p.offset_mm for p in L.probes], dtype=float)[L.k]
    pid = [p.id for p in L.probes]
    if L.kind == "length":
        I, J = L.I, L.J
        ref = np.linalg.norm(L.X[J] - L.X[I], axis=1)
        meas = np.linalg.norm(Xind[J] - Xind[I], axis=1)
        if "thermal_expansion" in planted:
            meas = meas + 1e-6 * planted["thermal_expansion"] * (T_rec - 20.0) * ref
        for a, ax in enumerate("xyz"):
            # thermal gradient: a coefficient linear along the axis, integrated over the length, is
            # its value at the midpoint; the origin is the middle of the probed positions
            if f"thermal_gradient_{ax}" in planted:
                centre = 0.5 * (L.X[:, a].max() + L.X[:, a].min())
                alpha_mid = planted[f"thermal_gradient_{ax}"] * (0.5 * (L.X[I, a] + L.X[J, a]) - centre) / 1000.0
                meas = meas + 1e-6 * alpha_mid * (T_rec - 20.0) * ref
        if "scale_drift" in planted:
            na = (L.X[J] - L.X[I]) / ref[:, None]
            du = (L.X[J] - P[J]) - (L.X[I] - P[I])
            meas = meas + 1e-6 * planted["scale_drift"] * (t_rec / 3600.0) * np.einsum("ij,ij->i", na, du)
        rec = LengthRecords(kind="length", ids=tuple(L.ids), lines=tuple(range(2, n + 2)),
                            temperature_C=T_rec, time_s=t_rec.copy(), group=tuple(L.group),
                            X1_mm=Xind[I], X2_mm=Xind[J], reference_mm=ref, measured_mm=meas,
                            N1=None if L.N is None else L.N[I], N2=None if L.N is None else L.N[J],
                            P1_mm=P[I], P2_mm=P[J], probe1=tuple(pid[k] for k in L.k[I]),
                            probe2=tuple(pid[k] for k in L.k[J]))
        return rec
    Xm = Xind.copy()
    Xn = L.X_nom.copy()
    if L.planar_z is not None:
        Xm[:, 2] = L.planar_z
        Xn[:, 2] = 0.0
    return PointRecords(kind="point", ids=tuple(L.ids), lines=tuple(range(2, n + 2)),
                        temperature_C=T_rec, time_s=t_rec.copy(), group=tuple(L.group),
                        X_nom_mm=Xn, X_mm=Xm, N=L.N, P_mm=P, probe=tuple(pid[k] for k in L.k))


def plant_field(rec, delta_um):
    """Records with an out-of-library error added: a displacement field ``delta_um(U)`` (µm, n x 3)
    of the ram position U = x - p (mm), as the second edition's ``discrepancy`` candidate sees it
    (docs/recordings.md section 7).  A length sees n_a . (delta(end 2) - delta(end 1)); a point
    moves by delta (in the plane only for planar records)."""
    from dataclasses import replace

    if rec.kind == "length":
        d = rec.X2_mm - rec.X1_mm
        na = d / np.linalg.norm(d, axis=1)[:, None]
        P1 = rec.P1_mm if rec.P1_mm is not None else np.zeros_like(rec.X1_mm)
        P2 = rec.P2_mm if rec.P2_mm is not None else np.zeros_like(rec.X2_mm)
        err = np.einsum("ij,ij->i", na, delta_um(rec.X2_mm - P2) - delta_um(rec.X1_mm - P1))
        return replace(rec, measured_mm=rec.measured_mm + 1e-3 * err)
    P = rec.P_mm if rec.P_mm is not None else np.zeros_like(rec.X_mm)
    dX = 1e-3 * delta_um(rec.X_mm - P)
    if rec.planar:
        dX[:, 2] = 0.0
    return replace(rec, X_mm=rec.X_mm + dX)
