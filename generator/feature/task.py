"""The data of a ``feature`` task: the fitted element's task as :mod:`generator.feature.job` reads
it from a task file and :mod:`generator.feature.book` writes it to a workbook, and the a-priori
planning of partial features (Forbes 2022 Tables 1-8).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cmmwb.xlfuncs import partial as pa
from cmmwb.xlfuncs import pointcloud as pc

KIND = "feature"

#: a Gauss-Newton step from the fitted values longer than this (mm and rad of the paper
#: parameters, Euclidean norm) means the points or weights changed since the fit: rounding
#: leaves 1e-13 at most on the demo books, moving one point by 0.1 µm gives about 1e-6
STALE_STEP = 1e-9
FIT_CURRENT = "current"
FIT_STALE = "STALE: points changed, refit (cmmwb read + build)"


def fit_state(step_norm: float) -> str:
    """The 'fit_state' of the Results rows: :data:`FIT_CURRENT` or :data:`FIT_STALE`."""
    return FIT_STALE if step_norm > STALE_STEP else FIT_CURRENT


@dataclass
class Planning:
    """The a-priori evaluation: one analytic approximation per value of the sweep key."""

    pattern: str
    sweep: str | None
    values: list[float]
    geometry: dict
    m_points: int
    space: bool = False

    def rows(self) -> list[tuple[float | None, pa.Approximation]]:
        out = []
        for v in (self.values if self.sweep else [None]):
            g = dict(self.geometry)
            if self.sweep:
                g[self.sweep] = v
            out.append((v, planning_approximation(self.pattern, g, self.space)))
        return out


def planning_approximation(pattern: str, g: dict, space: bool) -> pa.Approximation:
    """:func:`xlfuncs.partial.approximation` with the task's key names."""
    g = dict(g)
    if pattern == "circle_arc":
        g["space"] = space
        g.setdefault("r0_mm", 1.0)
    return pa.approximation(pattern, **g)


@dataclass
class Task:
    path: Path
    name: str
    element: str
    circle_plane: str | None          # None: circle in space
    cloud: pc.PointCloud
    params: pc.Parameters
    weights: np.ndarray
    axis_hint: tuple | None
    reference_mm: tuple | None
    max_iter: int
    source: str                       # "[points]" or "[sampling]"
    sampling: dict | None = None
    planning: Planning | None = None
    notes: list[str] = field(default_factory=list)
    va_method: str = "auto"           # [feature] va_method, or "exact" by cmmwb build --exact
    points_source: str = ""           # where the points come from, in words (taskcloud.points_source)
    _fit: object = None
    _unc: object = None
