"""One record per result: what every task kind (and the diagnosis, calibration and validation
books) hands to the code every kind shares (decisions, the Decision sheet, the report page, the
cached values), so that the shared code never asks which kind it serves.

A kind's job module returns its records from ``quantities(task, results, k)``
(:class:`generator.taskkind.TaskKind`); each :class:`Quantity` says

* what it is: ``label`` (unique in the task), ``ident`` (the keys that name it in
  ``[[decision.tolerances]]``), ``symbol`` (how a result statement names it: ``d(A1→A2)``);
* its value and uncertainty: ``value`` in ``unit``, ``u`` in ``u_unit``, the coverage factor
  ``k``, U = k·u in ``U_unit``, the effective degrees of freedom ``nu_eff`` (``math.inf``: type
  B only) and the ``coverage_probability`` they give (GUM G.6: 2Φ(k) − 1, or Student's t for a
  finite ν_eff; :func:`cmmwb.xlfuncs.dof.coverage_probability`);
* its specification where the task gives one: ``nominal``, ``lsl``, ``usl`` (the characteristic
  kind's drawing tolerances; the other kinds' tolerances are in ``[[decision.tolerances]]``);
* where the value comes from, in words a laboratory can sign (``value_source``: fitted to the
  measured points of a file, evaluated at the nominal geometry, ...) and where U comes from
  (``u_source``);
* where it sits in the workbook (:class:`Cells`: sheet, row and the cells of value, u, U, k), so
  that formulas on other sheets refer to those cells instead of reading column positions back
  from a finished sheet.

The record is a plain frozen dataclass with no knowledge of the workbook library; a result of a
diagnosis or calibration (an effect's estimate with its u, a fitted hyper-parameter, an E_n value
of a validation) is a :class:`Quantity` too: a value with its u and k, a unit, a source.

:class:`ToleranceKeys` is the other half of a kind's contract with the decisions: how a
``[[decision.tolerances]]`` entry names one of the kind's results, and whether the kind's
results carry their own U (budget, pointcloud) or U = k·u with the ``[decision] k`` (feature,
characteristic).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping

from cmmwb.xlfuncs.dof import coverage_probability

#: the units a decision works in (docs/conformity.md): values and limits in mm, u and U in µm
DECIDABLE_UNITS = ("mm", "µm")


@dataclass(frozen=True)
class Cells:
    """Where a quantity sits in its workbook: formula references (sheet included, absolute:
    ``'Results'!$C$2`` or a defined name) of the cells that hold it.

    ``u_scale``: the u cell times ``u_scale`` is u in the quantity's ``u_unit`` (a feature
    parameter's u cell is in mm, its u in µm: 1000).  ``U``: None when the book holds no U cell
    (U = k·u with the coverage factor of ``k``).  ``k``: a cell or defined name holding the
    coverage factor (``K`` of a point-cloud task, ``decision_k`` of a Decision sheet), or None
    (k = U/u of the cells, or the record's number).  ``limits``: formulas of the cells that hold
    the task's own specification limits ({"lsl": "'Characteristics'!$I$5", "usl": ...}), so
    that a tolerance typed there changes the decision."""

    sheet: str
    row: int
    value: str
    u: str
    U: str | None = None
    u_scale: float = 1.0
    k: str | None = None
    limits: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Quantity:
    """One result of a task (see the module docstring)."""

    label: str
    value: float
    unit: str
    u: float
    u_unit: str
    k: float
    U_unit: str
    symbol: str = ""
    ident: Mapping[str, str] = field(default_factory=dict)
    #: U_unit per u_unit (1 for µm and µm; deg per µrad for an angle stated in deg)
    U_per_u: float = 1.0
    nu_eff: float = math.inf
    nominal: float | None = None
    lsl: float | None = None
    usl: float | None = None
    #: where the value comes from, in words (``fitted to the measured points of part.csv``)
    value_source: str = ""
    #: where u comes from, in words (``the MPE budget (Wojtyła/Płowucha 2023)``)
    u_source: str = ""
    cells: Cells | None = None
    #: True when the task's results give U themselves (their own coverage factor); False when
    #: U = k·u with the coverage factor of ``[decision] k`` (default 2)
    own_U: bool = True
    #: the label of the record decided in this one's place (a position at MMC/LMC: its margin)
    decided_as: str | None = None
    #: why a tolerance this record has is not decided (an angle: the decision works in mm)
    not_decided: str | None = None
    #: the quantity's kind of value in JSON terms ("value", "margin_mm", ...), for its decision
    quantity: str = "value"

    def __post_init__(self):
        if not self.symbol:
            object.__setattr__(self, "symbol", self.label)

    @property
    def U(self) -> float:
        """The expanded uncertainty U = k·u, in ``U_unit``."""
        return self.k * self.u * self.U_per_u

    @property
    def coverage(self) -> float:
        """The coverage probability of k with ν_eff (GUM G.6): 2Φ(k) − 1, or Student's t."""
        return coverage_probability(self.k, self.nu_eff)

    @property
    def unit_ratio(self) -> float:
        """U_unit per unit of the value (1000 for µm and mm; 1 for the same unit), for rounding
        a result statement (GUM 7.2.6)."""
        return UNIT_RATIO.get((self.U_unit, self.unit), 1.0)

    @property
    def decidable(self) -> bool:
        """A decision works in mm and µm (docs/conformity.md): a length with u in µm."""
        return (self.unit, self.u_unit) == DECIDABLE_UNITS

    @property
    def has_tolerance(self) -> bool:
        return self.lsl is not None or self.usl is not None

    def as_dict(self) -> dict[str, Any]:
        """The record as JSON (non-finite numbers as null, ``cells`` as a table)."""
        out = asdict(self)
        out["ident"] = dict(self.ident)
        out["U"] = self.U
        out["coverage_probability"] = self.coverage
        if out["cells"] is not None:
            out["cells"]["limits"] = dict(self.cells.limits)
        return {key: (None if isinstance(v, float) and not math.isfinite(v) else v) for key, v in out.items()}


#: U_unit per value unit
UNIT_RATIO = {("µm", "mm"): 1000.0, ("µrad", "rad"): 1e6, ("µm", "µm"): 1.0}


@dataclass(frozen=True)
class ToleranceKeys:
    """How a kind's ``[[decision.tolerances]]`` entries name its results.

    ``keys``: the keys naming a result (``("from", "to")``: a point-cloud distance); empty when
    the kind's tolerances are fields of its own results (a drawing's characteristics), which
    refuses ``[[decision.tolerances]]``.  ``help``: what the keys mean, for a message.
    ``joiner``: the label of a result named by several keys (``A1→A2``).  ``k_from_decision``:
    the kind's results have u only, U = k·u with ``[decision] k`` (default 2).  ``hint``: what a
    message adds when a named result does not exist."""

    keys: tuple[str, ...]
    help: str = ""
    joiner: str = "→"
    k_from_decision: bool = False
    hint: str = ""
    #: how the kind's own tolerances are decided, in words for the report page
    note: str = ""

    @property
    def own(self) -> bool:
        """The kind's tolerances are on its results (no ``[[decision.tolerances]]``)."""
        return not self.keys

    def label(self, ident: Mapping[str, str]) -> str:
        return self.joiner.join(ident[k] for k in self.keys)


@dataclass(frozen=True)
class Verdict:
    """A verdict a task's results give besides its characteristics' decisions (the MPE check of a
    point-cloud task: C_max <= 1), for the report page: ``label``, the ``value`` and its
    ``value_cell``, the ``limit`` in words (``C_max <= 1``), the ``verdict`` in words and the
    cell that holds it live (``verdict_cell``), and the ``rule`` it was reached under."""

    label: str
    value: float
    limit: str
    verdict: str
    rule: str
    value_cell: str | None = None
    verdict_cell: str | None = None
    unit: str = ""


def unique_labels(labels: list[str]) -> list[str]:
    """Labels made unique in their order: a repeated one gets " (2)", " (3)" ... (a distance
    listed twice)."""
    seen: dict[str, int] = {}
    out = []
    for lab in labels:
        n = seen.get(lab, 0) + 1
        seen[lab] = n
        out.append(lab if n == 1 else f"{lab} ({n})")
    return out
