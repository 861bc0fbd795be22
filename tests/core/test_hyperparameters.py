"""One record per hyper-parameter (xlfuncs.model.hyperparameters): the model's Parameters has exactly
the records' fields, every table the rest of cmmwb uses is derived from them, and no module types a
second table of hyper-parameter names (issue 35: "adding a factor changes one table, not seven")."""

from __future__ import annotations

import ast
import dataclasses

from cmmwb.xlfuncs import calibrate, limits, reml
from cmmwb.xlfuncs.model import Parameters, Probe
from cmmwb.xlfuncs.model import hyperparameters as hp

from tests.helpers import ROOT


def test_parameters_has_one_field_per_record_in_record_order():
    assert tuple(f.name for f in dataclasses.fields(Parameters)) == hp.NAMES


def test_probe_overrides_are_the_probes_optional_fields():
    probe_fields = [f.name for f in dataclasses.fields(Probe) if f.name not in ("id", "offset_mm")]
    assert tuple(probe_fields) == hp.PROBE_OVERRIDES == ("sigma_PQ_um", "sigma_P0_um", "sigma_P_um", "lambda_P")


def test_the_roles_of_forbes_2025_eq_28():
    """sigma^2 B with B fixed: R, S (three), PQ, the probe radius; kernels: ET, ER, P (eqs. 21, 25, 27)."""
    assert hp.GP == (("sigma_ET_um", "lambda_ET_mm", "ET"), ("sigma_ER_urad", "lambda_ER_mm", "ER"),
                     ("sigma_P_um", "lambda_P", "P"))
    assert set(hp.LINEAR) >= {"sigma_R_um", "sigma_S_ppm", "sigma_Sa_ppm", "sigma_Q_ppm", "sigma_PQ_um",
                              "sigma_P0_um"}
    assert hp.S_COLUMNS == ("sigma_S_ppm",) + ("sigma_Sa_ppm",) * 3 + ("sigma_Q_ppm",) * 3


def test_the_derived_tables():
    for h in hp.HYPERPARAMETERS:
        assert limits.PLAUSIBLE[h.name][:2] == h.plausible
        assert calibrate.ADVICE[h.name] == h.advice
        assert reml.UNIT[h.name] == h.unit and reml.FACTOR[h.name] == h.factor
    assert reml.NAMES == hp.NAMES and reml.LINEAR == hp.LINEAR and reml.PARTNER == hp.PARTNER
    assert limits.PLAUSIBLE["lambda_P"][2] == "(unit normals)"
    assert Parameters.SIGMAS == hp.MACHINE_SIGMAS


def _string_tables(tree: ast.AST):
    """Literal tuples, lists, sets and dict keys of string constants in a module."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            items = node.elts
        elif isinstance(node, ast.Dict):
            items = [k for k in node.keys if k is not None]
        else:
            continue
        yield node.lineno, [e.value for e in items if isinstance(e, ast.Constant) and isinstance(e.value, str)]


def test_no_module_types_a_second_table_of_hyper_parameter_names():
    """A literal collection naming three or more hyper-parameters outside the records is a second
    table (the probe overrides were typed 9 times, the REML and plausibility tables once each).
    The scripts that wrote the shipped examples (generator/examples/, not a package) write text."""
    names = set(hp.NAMES)
    found = []
    for path in sorted([*ROOT.glob("xlfuncs/**/*.py"), *ROOT.glob("generator/**/*.py")]):
        rel = path.relative_to(ROOT).as_posix()
        if rel == "xlfuncs/model/hyperparameters.py" or rel.startswith("generator/examples/"):
            continue
        for line, strings in _string_tables(ast.parse(path.read_text(encoding="utf-8"))):
            if len(names.intersection(strings)) >= 3:
                found.append(f"{rel}:{line}")
    assert found == []
