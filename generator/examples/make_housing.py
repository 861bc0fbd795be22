"""Writes the points table of the workpiece-temperature demo (``housing_W.toml``, docs/workpiece.md;
run from this folder): an aluminium gearbox housing, its mounting face A (z = 0, 480 x 160 mm, bowed
by 2 µm) and two bearing bores H1, H2 of nominal diameter 52 mm, 400 mm apart (axes along z, 5 to
35 mm deep), H2 at 400.006 mm with diameter 52.015 mm and a two-lobed 1.5 µm form, H1 of diameter
52.012 mm with a three-lobed 1 µm form and its axis tilted 3 µm over 20 mm.  The points lie on the planted surfaces (what V_X describes
is the measurement's error, not the part's)."""
from pathlib import Path

import numpy as np
from make_characteristic_plate import _stable_unit  # the same folder (run from it): one fixed-point normal

HERE = Path(__file__).parent
NAME = "housing_W"


def _bore(cx, cy, d, lobes, amp, phase, tilt):
    P, N = [], []
    for z in (10.0, 30.0):
        for j in range(8):
            th = 2 * np.pi * j / 8 + phase + (0.2 if z > 20 else 0.0)
            r = d / 2 + amp * np.cos(lobes * th)
            P.append([cx + tilt * (z - 20.0) / 20.0 + r * np.cos(th), cy + r * np.sin(th), z])
            N.append([-np.cos(th), -np.sin(th), 0.0])          # the material is outside the bore
    return np.array(P), np.array(N)


def points():
    """(labels, X_mm, N) of the housing."""
    labels, X, N = [], [], []
    k = 0
    for x in np.linspace(10, 470, 6):
        for y in (10.0, 80.0, 150.0):
            k += 1
            sx, sy = (x - 240) / 230, (y - 80) / 70
            labels.append(f"A.{k:02d}")
            X.append([x, y, 0.002 * (1 - sx * sx) * (1 - 0.3 * sy * sy)])   # a 2 µm bow
            N.append([0.0, 0.0, -1.0])
    for name, (cx, cy, d, lobes, amp, ph, tilt) in (("H1", (40.0, 80.0, 52.012, 3, 0.001, 0.1, 0.003)),
                                                     ("H2", (440.006, 80.0, 52.015, 2, 0.0015, 0.4, 0.0))):
        P, Nb = _bore(cx, cy, d, lobes, amp, ph, tilt)
        for q in range(len(P)):
            labels.append(f"{name}.{q + 1:02d}")
            X.append(P[q])
            N.append(Nb[q])
    return labels, np.array(X), np.array(N)


def main():
    labels, X, N = points()
    rows = ["# An aluminium gearbox housing: mounting face A and two bearing bores 400 mm apart (mm); "
            "generator/examples/make_housing.py",
            "id,x,y,z,nx,ny,nz,probe"]
    for lab, x, n in zip(labels, X, N):
        rows.append(f"{lab}," + ",".join(f"{v:.9f}" for v in x) + ","
                    + ",".join(repr(float(v)) for v in _stable_unit(n)) + ",P1")
    (HERE / f"{NAME}.csv").write_text("\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
