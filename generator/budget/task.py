"""The data of a ``budget`` task (Wojtyła, Płowucha et al. 2023): the models, the characteristics
and the task as :mod:`generator.budget.job` reads them from a task file and
:mod:`generator.budget.book` writes them to a workbook.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from cmmwb.xlfuncs import budget as bd

#: point-name keys of each model (the points a characteristic uses), with their shape
MODEL_KEYS: dict[str, dict[str, int]] = {
    "point_point": {"from": 1, "to": 1},
    "point_line": {"point": 1, "line": 2},
    "point_plane": {"point": 1, "plane": 3},
    "line_line": {"line1": 2, "line2": 2},
    "datum_distance": {"point": 1},
    "position": {"point": 1},
}
MODEL_TEXT = {
    "point_point": "distance of two points, eq. (1)",
    "point_line": "distance of a point from a straight line, eq. (2)",
    "point_plane": "distance of a point from a plane, eq. (3)",
    "line_line": "distance of two straight lines, eq. (4)",
    "datum_distance": "distance of a point from a datum, eqs. (7)-(21), (27)-(35)",
    "position": "position deviation, cylindrical tolerance zone, eq. (22)",
}


@dataclass
class Characteristic:
    """One ``[[characteristics]]`` entry (``index`` is 1-based, for messages)."""

    index: int
    name: str
    model: str
    points: dict                      # model keys -> point name(s), e.g. {"point": "S4"}
    variant: str | tuple[str, str] = "auto"
    datum: str | None = None          # datum_distance
    datums: tuple[str, str] | None = None   # position
    ted_mm: tuple[float, float] | None = None

    @property
    def where(self) -> str:
        return f"[[characteristics]] #{self.index}"


@dataclass
class Task:
    path: Path
    name: str
    mpe: bd.MPE
    points: dict[str, tuple[float, float, float]]
    datum_system: bd.DatumSystem | None
    characteristics: list[Characteristic]
    notes: list[str] = field(default_factory=list)
    #: the part's temperature ([workpiece], the factor W: docs/workpiece.md), or None
    part: bd.Part | None = None


def distance_name(c: Characteristic, i: int) -> str:
    """Name of the i-th (0, 1) datum distance of a position: the paper's l_S4,1, l_S4,2."""
    return f"l_{c.points['point']},{i + 1}"


#: the label of a type A repeatability ([[decision.tolerances]] s_um, n_repeats) in a budget
TYPE_A_INPUT = "repeatability s/√n (type A)"
