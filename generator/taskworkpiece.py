"""The ``[workpiece]`` table of every task kind: the part's temperature, the factor W
(docs/workpiece.md).

```toml
[workpiece]
# enabled = true               # the factor W on/off (the one key); without the table W is off
material = "aluminium"         # or alpha_ppm_per_K = 23.1 (aluminium 23.1, steel 11.5, silicon 2.6)
u_alpha_ppm_per_K = 1.0        # u(alpha), 1e-6/K
T_degC = 23.5                  # the part's mean temperature, or T_readings_degC = [23.3, 23.7]
u_T_K = 0.3                    # u(T) of the thermometer, K
# dT_K = 0.4                   # temperature difference across the part (default: the readings' range)
# corrected = true             # the CMM corrects to 20 °C ...
# alpha_corr_ppm_per_K = 23.1  # ... with this alpha (default: the part's)
# fixture_mm = [0, 0, 0]       # the point the part expands about (where it is held)
```
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from cmmwb.xlfuncs.model.hyperparameters import in_table
from cmmwb.xlfuncs.model.workpiece import MATERIALS, PLAUSIBLE_T_C, REFERENCE_C, Workpiece

from .errors import InputError, model_errors_named
from .taskfile import check_keys, note, number, string, table, vector3

SECTION = "workpiece"
#: the hyper-parameters of the table (u(alpha), u(T): their records)
HYPER_KEYS = in_table(SECTION)
KEYS = {"enabled", "material", "alpha_ppm_per_K", "T_degC", "T_readings_degC", "dT_K", "corrected",
        "alpha_corr_ppm_per_K", "fixture_mm", *HYPER_KEYS}
#: an expansion coefficient beyond any engineering material (10^-6/K): probably a unit mix-up
ALPHA_PLAUSIBLE = 100.0


@dataclass(frozen=True)
class Part:
    """What ``[workpiece]`` gives: the part's thermal state and the hyper-parameters u(alpha), u(T)."""

    workpiece: Workpiece
    u: dict[str, float]          # u_alpha_ppm_per_K, u_T_K
    readings_C: tuple[float, ...] = ()


def _flag(path: Path, tbl: dict, key: str, default: bool) -> bool:
    v = tbl.get(key, default)
    if not isinstance(v, bool):
        raise InputError(f"must be true or false, got {v!r}", file=path, where=f"[{SECTION}] {key}")
    return v


def read_workpiece(path: Path, doc: dict) -> Part | None:
    """The ``[workpiece]`` table of a task file, or None without one (the factor W off)."""
    if SECTION not in doc:
        return None
    tbl = table(path, doc, SECTION)
    check_keys(path, tbl, SECTION, KEYS)
    enabled = _flag(path, tbl, "enabled", True)
    corrected = _flag(path, tbl, "corrected", True)
    material = None
    if "alpha_ppm_per_K" in tbl and "material" in tbl:
        raise InputError("give the part's expansion coefficient once: alpha_ppm_per_K or material (not both)",
                         file=path, where=f"[{SECTION}] material")
    if "alpha_ppm_per_K" in tbl:
        alpha = number(path, tbl, SECTION, "alpha_ppm_per_K")
    elif "material" in tbl:
        material = string(path, tbl, SECTION, "material").strip().lower()
        if material not in MATERIALS:
            raise InputError(f"unknown material {tbl['material']!r}: give alpha_ppm_per_K, or one of "
                             + ", ".join(sorted(MATERIALS)), file=path, where=f"[{SECTION}] material")
        alpha = MATERIALS[material]
    else:
        raise InputError("give the part's expansion coefficient: alpha_ppm_per_K (1e-6/K) or material",
                         file=path, where=f"[{SECTION}]")
    if abs(alpha) > ALPHA_PLAUSIBLE:
        note(f"alpha_ppm_per_K = {alpha:g} 1e-6/K is beyond engineering materials (steel 11.5, aluminium "
             "23.1); built as given -- is it in 1e-6/K?", file=path, where=f"[{SECTION}] alpha_ppm_per_K")
    u = {k: number(path, tbl, SECTION, k, lo=0.0) for k in HYPER_KEYS}
    readings: tuple[float, ...] = ()
    if ("T_degC" in tbl) == ("T_readings_degC" in tbl):
        raise InputError("give the part's temperature: T_degC or T_readings_degC (not both)", file=path,
                         where=f"[{SECTION}]")
    if "T_degC" in tbl:
        T = number(path, tbl, SECTION, "T_degC")
    else:
        raw = tbl["T_readings_degC"]
        where = f"[{SECTION}] T_readings_degC"
        if not isinstance(raw, list) or not raw or any(isinstance(v, bool) or not isinstance(v, (int, float))
                                                       or not math.isfinite(float(v)) for v in raw):
            raise InputError("must be a list of one or more finite temperatures (°C)", file=path, where=where)
        readings = tuple(float(v) for v in raw)
        T = math.fsum(readings) / len(readings)
    if not PLAUSIBLE_T_C[0] <= T <= PLAUSIBLE_T_C[1]:
        note(f"the part's temperature {T:g} °C is outside {PLAUSIBLE_T_C[0]:g}-{PLAUSIBLE_T_C[1]:g} °C, where "
             "CMMs measure; built as given -- is it in °C?", file=path, where=f"[{SECTION}] T_degC")
    dT = number(path, tbl, SECTION, "dT_K", (max(readings) - min(readings)) if readings else 0.0, lo=0.0)
    alpha_corr = number(path, tbl, SECTION, "alpha_corr_ppm_per_K") if "alpha_corr_ppm_per_K" in tbl else None
    if alpha_corr is not None and not corrected:
        raise InputError("the CMM does not correct (corrected = false): leave alpha_corr_ppm_per_K out",
                         file=path, where=f"[{SECTION}] alpha_corr_ppm_per_K")
    fixture = vector3(path, tbl, f"[{SECTION}]", "fixture_mm") if "fixture_mm" in tbl else (0.0, 0.0, 0.0)
    with model_errors_named(file=path, where=f"[{SECTION}]"):
        wp = Workpiece(alpha_ppm_per_K=alpha, T_degC=T, corrected=corrected, alpha_corr_ppm_per_K=alpha_corr,
                       fixture_mm=fixture, dT_K=dT, enabled=enabled, material=material)
    if enabled and abs(wp.bias_ppm()) > 0:
        what = "does not correct to 20 °C" if not corrected else f"corrects with alpha = {wp.alpha_c:g} 1e-6/K"
        note(f"the CMM {what}: the part's expansion of {wp.bias_ppm():.3g} 1e-6 (({alpha:g} - {wp.alpha_c:g}) "
             f"1e-6/K x {T - REFERENCE_C:+.3g} K) is a known systematic error left in the result; cmmwb adds it "
             "to u(eps) in quadrature (docs/workpiece.md) -- correcting it is better", file=path,
             where=f"[{SECTION}]")
    return Part(wp, u, readings)


def apply_workpiece(path: Path, doc: dict, cloud, params):
    """``(cloud, params)`` with the task's ``[workpiece]``: the part on the cloud, u(alpha) and u(T) in
    the parameters (unchanged without the table)."""
    from dataclasses import replace

    part = read_workpiece(path, doc)
    if part is None:
        return cloud, params
    return replace(cloud, workpiece=part.workpiece), replace(params, **part.u)
