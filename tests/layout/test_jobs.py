"""The task-kind contract: every registered kind's job module provides what
:class:`generator.taskkind.TaskKind` names, with the same parameters, so that build, new, read,
demo and the templates never ask a kind what it has."""

from __future__ import annotations

import inspect

import pytest

from cmmwb.generator.jobs import JOBS, job
from cmmwb.generator.quantities import ToleranceKeys
from cmmwb.generator.taskfile import KINDS
from cmmwb.generator.taskkind import TaskKind, always_exact, no_type_a, no_verdicts

#: the members of the contract: data (checked by type) and functions (checked by signature)
DATA = {"EXAMPLES": (list, tuple), "NEW_TASK": str, "NEW_TASK_FILES": dict, "TOLERANCE_KEYS": ToleranceKeys}
FUNCTIONS = [name for name, member in vars(TaskKind).items()
             if inspect.isfunction(member) and not name.startswith("_")]


def test_the_registry_has_every_kind_a_task_file_may_name():
    assert tuple(JOBS) == KINDS
    assert all(job(kind) is JOBS[kind] for kind in KINDS)


def test_the_contract_names_the_hooks_once_probed_with_hasattr():
    assert {"load", "compute", "write_book", "write_plots", "summary", "force_exact", "add_type_a", "quantities",
            "verdicts", "read_book"} == set(FUNCTIONS)
    assert set(DATA) == set(TaskKind.__annotations__)


@pytest.mark.parametrize("kind", KINDS)
def test_every_registered_kind_satisfies_the_protocol(kind):
    mod = JOBS[kind]
    assert isinstance(mod, TaskKind)            # runtime_checkable: every member is there
    for name, types in DATA.items():
        assert isinstance(getattr(mod, name), types), (kind, name)
    for name in FUNCTIONS:
        expected = list(inspect.signature(getattr(TaskKind, name)).parameters)[1:]   # without self
        got = list(inspect.signature(getattr(mod, name)).parameters)
        assert got == expected, (kind, name, got, expected)


def test_the_default_hooks_are_where_a_kind_has_no_use_for_them():
    """Only the feature kind approximates (its large V_A) and only budgets carry type A inputs."""
    assert [k for k in KINDS if JOBS[k].force_exact is not always_exact] == ["feature"]
    assert [k for k in KINDS if JOBS[k].add_type_a is not no_type_a] == ["budget"]
    assert [k for k in KINDS if JOBS[k].verdicts is not no_verdicts] == ["pointcloud"]


def test_the_default_hooks_change_nothing():
    results = {"name": "x", "characteristics": []}
    assert always_exact(object()) is None
    assert no_verdicts(object(), results) == []
    assert no_type_a(results) is None and results == {"name": "x", "characteristics": []}
