"""Conformity decisions of a task (JCGM 106:2012, ISO 14253-1:2017), one job per module:

* :mod:`.decide`: the ``[decision]`` table and its tolerances, validated, and the decisions of
  the results JSON (:mod:`xlfuncs.conformity`);
* :mod:`.sheet`: the ``Decision`` sheet, the same decisions as live formulas;
* :mod:`.readback`: the sheet's inputs back into the task file (``cmmwb read``).

The names the rest of the project uses are re-exported here.
"""

from .decide import DecisionSpec, decide_all, default_spec, own_tolerances, read_spec, rule_json
from .readback import read_back
from .sheet import FIRST_ROW, SHEET, chart_scale_values, column, write_sheet

__all__ = ["FIRST_ROW", "SHEET", "DecisionSpec", "chart_scale_values", "column", "decide_all", "default_spec",
           "own_tolerances", "read_back", "read_spec", "rule_json", "write_sheet"]
