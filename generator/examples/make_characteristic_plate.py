"""Writes the characteristic example (the simulated plate of xlfuncs.plate: datum A bottom, B left,
C front; flatness, perpendicularity, position at MMC ...) as a task file and its points table
(run from this folder)."""
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import plate

HERE = Path(__file__).parent
NAME = "characteristic_plate"


def _toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return repr(float(v))


def _stable_unit(n):
    """n normalised until normalising again changes no bit (cmmwb normalises every normal it
    reads; a normal that is a fixed point makes build -> read -> build exact)."""
    n = np.asarray(n, float)
    for _ in range(10):
        m = n / np.linalg.norm(n)
        if np.array_equal(m, n):
            break
        n = m
    return n


def main():
    X, N, feats, frames, chars = plate.plate()
    label = {}
    for f in feats:
        for k, i in enumerate(f.indices, start=1):
            label.setdefault(i, f"{f.name}.{k:02d}")
    rows = ["# The simulated plate of xlfuncs.plate (planted form and position errors), mm",
            "id,x,y,z,nx,ny,nz,probe"]
    for i in range(len(X)):
        rows.append(f"{label[i]}," + ",".join(f"{v:.9f}" for v in X[i]) + ","
                    + ",".join(repr(float(v)) for v in _stable_unit(N[i])) + ",P1")
    (HERE / f"{NAME}.csv").write_text("\n".join(rows) + "\n")
    out = ["# A plate 100 x 80 x 10 mm with two holes: flatness of datum A, perpendicularity, "
           "parallelism,",
           "# form (LS and minimum zone), sizes and position at MMC against A|B|C; planted errors",
           "# (xlfuncs/plate.py). Point-cloud model: Forbes 2025 Table 3 MPE1-like values.",
           "[task]", 'kind = "characteristic"', f'name = "{NAME}"', "",
           "[points]", f'file = "{NAME}.csv"', "",
           "[parameters]", "sigma_R_um = 0.2", "sigma_S_ppm = 0.7", "sigma_Sa_ppm = 0.8",
           "sigma_Q_ppm = 0.9", "sigma_PQ_um = 0.2", "sigma_ET_um = 0.3", "lambda_ET_mm = 150",
           "sigma_ER_urad = 4.0", "lambda_ER_mm = 350", "sigma_P0_um = 0.1", "sigma_P_um = 0.15",
           "lambda_P = 0.5", "", "[[probes]]", 'id = "P1"', "offset_mm = [0.0, 0.0, -50.0]", ""]
    for f in feats:
        out += ["[[features]]", f'name = "{f.name}"', f'type = "{f.element}"',
                f'id_prefix = "{f.name}."']
        if f.axis_hint is not None:
            out.append(f"axis_hint = {_toml_value(f.axis_hint)}")
        out.append("")
    for fr in frames:
        out += ["[[frames]]", f'name = "{fr.name}"', f'primary = "{fr.primary}"',
                f'secondary = "{fr.secondary}"', f'tertiary = "{fr.tertiary}"', ""]
    defaults = plate.CharacteristicSpec("x", "x", ())
    for c in chars:
        out += ["[[characteristics]]", f'name = "{c.name}"', f'type = "{c.type}"',
                f"features = {_toml_value(list(c.features))}"]
        for k in ("method", "frame", "datum", "nominal", "nominal_position_mm", "zone",
                  "material_condition", "size", "internal", "direction", "lsl", "usl",
                  "tolerance_mm"):
            v = getattr(c, k)
            if v is not None and v != getattr(defaults, k):
                out.append(f"{k} = {_toml_value(v)}")
        out.append("")
    (HERE / f"{NAME}.toml").write_text("\n".join(out))


if __name__ == "__main__":
    main()
