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
