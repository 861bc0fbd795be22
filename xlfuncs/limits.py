"""The plausible range of a CMM coordinate, and why it is also a precision limit.

A coordinate in mm is held as a float64, whose spacing at magnitude ``x`` is about
``x * 2.2e-16``.  Below 1e5 mm (100 m, larger than any coordinate measuring machine) that
spacing is under 2e-11 mm = 2e-5 nm, far below the 1 nm the uncertainties of this toolkit need;
at 1e12-1e15 mm it is a micrometre or more and distances computed from such coordinates are
wrong.  Every coordinate read from a file must therefore satisfy
``abs(x) <= MAX_COORDINATE_MM`` (see ``docs/input_limits.md``).
"""

from __future__ import annotations

import math

import numpy as np

from .model.hyperparameters import HYPERPARAMETERS

#: largest accepted |coordinate| in mm (100 m)
MAX_COORDINATE_MM = 1e5
#: the resolution every accepted coordinate keeps (mm): 1 nm
RESOLUTION_MM = 1e-6

assert np.spacing(MAX_COORDINATE_MM) < RESOLUTION_MM / 1000  # float64 keeps 1 nm with margin


def coordinate_problem(value_mm: float) -> str | None:
    """Why ``value_mm`` is not a usable coordinate, or None."""
    if not math.isfinite(value_mm):
        return f"{value_mm!r} is not a finite number"
    if abs(value_mm) > MAX_COORDINATE_MM:
        return (f"coordinate {value_mm:g} mm is outside the plausible machine range +-{MAX_COORDINATE_MM:g} mm "
                f"(float64 resolves 1 nm only up to about 4e9 mm; is the unit mm?)")
    return None


# -- plausible values of the model's inputs ------------------------------------------------------

#: What coordinate measuring machines have, orders of magnitude wide (docs/input_limits.md,
#: "Plausible values"): key -> (smallest, largest, unit).  A value outside is accepted (a task
#: may study an extreme machine) but warned about, because the usual cause is a unit mix-up
#: (µm for mm, m for mm) that would otherwise give wrong uncertainties silently.  Zero is never
#: warned about: it switches a factor off.  Typical values (Forbes 2025 Table 3, MPE1): sigmas
#: 0.1-0.3 µm, 0.7 ppm, 4 µrad; length scales 200-400 mm; lambda_P 0.5.  The hyper-parameters'
#: ranges are their records' (:data:`xlfuncs.model.hyperparameters.HYPERPARAMETERS`).
PLAUSIBLE = {
    **{h.name: (*h.plausible, h.range_unit or h.unit) for h in HYPERPARAMETERS},
    "A_um": (0.05, 500.0, "µm"),
    "B_mm": (10.0, 1e6, "mm"),
    "offset_mm": (0.0, 2000.0, "mm"),      # the length of a probe's stylus offset
}

_UNIT_HINTS = {"µm": "a length in mm written as µm is 1000 times too large",
               "mm": "mm, not m or µm",
               "ppm": "1 µm/mm is 1000 ppm",
               "µrad": "1 mrad is 1000 µrad"}


def plausibility_problem(key: str, value: float) -> str | None:
    """Why ``value`` of the input ``key`` is outside :data:`PLAUSIBLE`, or None (also for keys
    without a range, and for 0)."""
    if key not in PLAUSIBLE or value == 0 or not math.isfinite(value):
        return None
    lo, hi, unit = PLAUSIBLE[key]
    if lo <= abs(value) <= hi:
        return None
    side = "larger" if abs(value) > hi else "smaller"
    hint = _UNIT_HINTS.get(unit)
    return (f"{key} = {value:g} {unit} is {side} than what coordinate measuring machines have "
            f"({lo:g} to {hi:g} {unit}); built as given" + (f" -- check the unit: {hint}" if hint else ""))
