"""Conformity decisions of a task (JCGM 106:2012, ISO 14253-1:2017), one job per module:

* :mod:`.decide`: the ``[decision]`` table and its tolerances, validated, and the decisions of
  the results JSON (:mod:`xlfuncs.conformity`);
* :mod:`.sheet`: the ``Decision`` sheet, the same decisions as live formulas;
* :mod:`.readback`: the sheet's inputs back into the task file (``cmmwb read``).

The names the rest of the project uses are re-exported here.
"""

from .decide import BONUS_CONDITIONS, characteristic_tolerances, decide_all, margin_label, read_spec, rule_json, symbol
from .readback import read_back
from .sheet import FIRST_ROW, column, write_sheet

__all__ = ["BONUS_CONDITIONS", "FIRST_ROW", "characteristic_tolerances", "column", "decide_all", "margin_label",
           "read_back", "read_spec", "rule_json", "symbol", "write_sheet"]
