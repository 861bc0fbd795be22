"""A simulated plate with planted form and position errors: the reference part of the
characteristics (tests, the demo book, the QIF test bed's nominal plate stand-in).

Plate 100 x 80 x 10 mm (x, y, z), datum A the bottom face (z = 0), B the left face (x = 0),
C the front face (y = 0); two through holes of nominal diameter 10 mm at (30, 40) and (70, 40).
Planted (mm): A bowed by 3 µm (form), the right face D tilted by 12 µm over its height
(perpendicularity), the top face T tilted 6 µm over the length (parallelism) with a 2 µm wave
along the line L (straightness), hole H1 at (30.012, 39.994) with its axis tilted 5 µm over
10 mm and a three-lobed 3 µm form, diameter 10.021; H2 at (70.004, 40.006), diameter 10.012,
with a two-lobed 2 µm form on its section K (roundness).  Points are exact on the planted
surfaces (the measurement errors are what V_X describes; the Monte Carlo draws them).
"""

from __future__ import annotations

import numpy as np

from .characteristics import CharacteristicSpec, FeatureSpec, FrameSpec

__all__ = ["plate"]


def _face(points, normal):
    P = np.asarray(points, float)
    return P, np.tile(np.asarray(normal, float), (P.shape[0], 1))


def _hole(cx, cy, r, levels, n_per, tilt_x, lobes, amp, phase=0.0, taper=0.0, twist=0.3):
    P, N = [], []
    for lv, z in enumerate(levels):
        for j in range(n_per):
            th = 2 * np.pi * j / n_per + phase + twist * lv
            rr = r + amp * np.cos(lobes * th) + taper * (z - 5.0) / 10.0
            c = np.array([cx + tilt_x * z / 10.0, cy])
            P.append([c[0] + rr * np.cos(th), c[1] + rr * np.sin(th), z])
            N.append([-np.cos(th), -np.sin(th), 0.0])      # material normal points to the axis
    return np.array(P), np.array(N)


def plate():
    """(X_mm, N, features, frames, characteristics) of the plate of the module docstring."""
    blocks: list[tuple[str, str, np.ndarray, np.ndarray, dict]] = []
    rng = np.random.default_rng(20231)          # fixed: the "roughness" below 0.3 µm

    def rough(n):
        return 0.0003 * rng.uniform(-1.0, 1.0, n)

    # A: bottom face, a 4 µm twist with a 3 µm bump and dip at two corners
    A = []
    for x in np.linspace(5, 95, 5):
        for y in np.linspace(5, 75, 4):
            sx, sy = (x - 50) / 45, (y - 40) / 35
            A.append([x, y, 0.004 * sx * sy + 0.003 * (sx == 1 and sy == 1)
                      - 0.003 * (sx == -1 and sy == 1)])
    A = np.array(A)
    A[:, 2] += rough(len(A))
    blocks.append(("A", "plane", *_face(A, (0, 0, -1)), {}))
    # B: left face, C: front face
    B = [[0.0, y, z] for y in (10, 40, 70) for z in (3, 7)]
    blocks.append(("B", "plane", *_face(B, (-1, 0, 0)), {}))
    C = [[x, 0.0, z] for x in (15, 50, 85) for z in (3, 7)]
    blocks.append(("C", "plane", *_face(C, (0, -1, 0)), {}))
    # D: right face tilted 12 µm over z 0..10, a 3 µm bump at (y 70, z 8), a 2 µm dip at (10, 2)
    D = np.array([[100.0 + 0.012 * z / 10 + 0.003 * (y == 70 and z == 8)
                   - 0.002 * (y == 10 and z == 2), y, z]
                  for y in (10, 30, 50, 70) for z in (2, 5, 8)])
    D[:, 0] += rough(len(D))
    blocks.append(("D", "plane", *_face(D, (1, 0, 0)), {}))
    # T: top face, 6 µm slope along x, a 3 µm dip at (40, 40), a 2 µm bump at (90, 70)
    T = np.array([[x, y, 10.0 + 0.006 * x / 100 - 0.003 * (x == 40 and y == 40)
                   + 0.002 * (x == 90 and y == 70)]
                  for x in (10, 40, 70, 90) for y in (10, 40, 70)])
    T[:, 2] += rough(len(T))
    blocks.append(("T", "plane", *_face(T, (0, 0, 1)), {}))
    # L: a line on the top face at y = 20: a 6 µm bow, 2 µm up at the right end, 2 µm down
    # near the middle
    xs = np.linspace(8, 92, 12)
    L = np.array([[x, 20.0, 10.0 + 0.006 * x / 100 + 0.006 * ((x - 50) / 42) ** 2
                   + 0.002 * (i == 11) - 0.002 * (i == 5)] for i, x in enumerate(xs)])
    L[:, 2] += rough(len(L))
    blocks.append(("L", "line", *_face(L, (0, 0, 1)), {"axis_hint": (1.0, 0.0, 0.0)}))
    # H1, H2: holes as cylinders; K: a section of H2 as a circle in xy
    # H1: a barrel-like form: 3 µm out at 0 and 180 deg of the middle section, 3 µm in at 45 and
    # 225 deg of the lower and at 135 and 315 deg of the upper section (six contact points)
    P1, N1 = _hole(30.012, 39.994, 10.021 / 2, (2.0, 5.0, 8.0), 8, 0.005, 3, 0.0, twist=0.0)
    e1 = 0.5 * rough(len(P1))
    for i, v in {8: 0.005, 12: 0.003, 2: -0.005, 6: -0.003}.items():
        e1[i] += v
    P1 -= N1 * e1[:, None]        # N points into the hole: -N is outward from the axis
    blocks.append(("H1", "cylinder", P1, N1, {"axis_hint": (0.0, 0.0, 1.0)}))
    P2, N2 = _hole(70.004, 40.006, 10.012 / 2, (2.5, 7.5), 8, -0.004, 2, 0.0)
    blocks.append(("H2", "cylinder", P2, N2, {"axis_hint": (0.0, 0.0, 1.0)}))
    PK, NK = _hole(70.004, 40.006, 10.012 / 2, (5.0,), 16, 0.0, 2, 0.0)
    eK = rough(len(PK))
    eK[[0, 8, 4, 12]] += [0.005, 0.003, -0.005, -0.003]
    PK -= NK * eK[:, None]
    blocks.append(("K", "circle", PK, NK, {}))
    X, N, feats = [], [], []
    i0 = 0
    for name, el, P, Nn, kw in blocks:
        X.append(P)
        N.append(Nn)
        feats.append(FeatureSpec(name, el, tuple(range(i0, i0 + len(P))), **kw))
        i0 += len(P)
    frames = [FrameSpec("ABC", "A", "B", "C")]
    chars = [
        CharacteristicSpec("dia_H1", "diameter", ("H1",), lsl=10.0, usl=10.05),
        CharacteristicSpec("dia_H2", "diameter", ("H2",), lsl=10.0, usl=10.05),
        CharacteristicSpec("dist_H1_H2", "distance", ("H1", "H2"), nominal=40.0,
                           lsl=39.95, usl=40.05),
        CharacteristicSpec("width_B_D", "width", ("B", "D"), nominal=100.0, lsl=99.9, usl=100.1),
        CharacteristicSpec("angle_B_C", "angle", ("B", "C"), nominal=90.0, lsl=89.9, usl=90.1),
        CharacteristicSpec("flat_A_LS", "flatness", ("A",), method="LS", tolerance_mm=0.01),
        CharacteristicSpec("flat_A_MZ", "flatness", ("A",), method="MZ", tolerance_mm=0.01),
        CharacteristicSpec("str_L_LS", "straightness", ("L",), method="LS",
                           direction=(0.0, 0.0, 1.0), tolerance_mm=0.01),
        CharacteristicSpec("str_L_MZ", "straightness", ("L",), method="MZ",
                           direction=(0.0, 0.0, 1.0), tolerance_mm=0.01),
        CharacteristicSpec("round_K_LS", "roundness", ("K",), method="LS", tolerance_mm=0.005),
        CharacteristicSpec("round_K_MZ", "roundness", ("K",), method="MZ", tolerance_mm=0.005),
        CharacteristicSpec("cyl_H1_LS", "cylindricity", ("H1",), method="LS", tolerance_mm=0.01),
        CharacteristicSpec("cyl_H1_MZ", "cylindricity", ("H1",), method="MZ", tolerance_mm=0.01),
        CharacteristicSpec("perp_D_A", "perpendicularity", ("D",), frame="ABC",
                           tolerance_mm=0.02),
        CharacteristicSpec("perp_H1_A", "perpendicularity", ("H1",), frame="ABC",
                           zone="diametral", tolerance_mm=0.02),
        CharacteristicSpec("par_T_A", "parallelism", ("T",), frame="ABC", tolerance_mm=0.02),
        CharacteristicSpec("pos_H1_MMC", "position", ("H1",), frame="ABC",
                           nominal_position_mm=(30.0, 40.0), material_condition="MMC",
                           size="dia_H1", internal=True, tolerance_mm=0.05),
        CharacteristicSpec("pos_H2", "position", ("H2",), frame="ABC",
                           nominal_position_mm=(70.0, 40.0), tolerance_mm=0.05),
    ]
    return np.vstack(X), np.vstack(N), feats, frames, chars
