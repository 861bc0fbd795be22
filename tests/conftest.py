"""pytest hooks of the whole suite: one BLAS thread per xdist worker, the ``numerics`` marker
(``NUMERIC_MODULES``), LibreOffice and Gnumeric tests skipped where the engine is missing, the
Open XML validator over every workbook a test writes, and the session's count of the cells each
engine gave the tests.  What tests share (paths, the four-engine comparison, writers of tasks) is
in ``tests/helpers/``."""

from __future__ import annotations

import os
from collections import Counter

import numpy  # noqa: F401  (loads OpenBLAS, so that its threads can be limited below)
import pytest

from cmmwb.generator.workbook.recalc import installed

from tests.helpers import ENGINE_CELLS
from tests.helpers.openxml import Watch

if os.environ.get("PYTEST_XDIST_WORKER"):
    # the suite runs as `-n 2` workers on a 2-core machine: one BLAS thread each, or the two
    # workers' BLAS threads fight over the cores (the kernel, OPENBLAS_CORETYPE, is unchanged)
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)

#: Test modules whose assertions compare computed numbers: CI runs them (without LibreOffice) a
#: second time under other OpenBLAS kernels (OPENBLAS_CORETYPE=Haswell, =SkylakeX), because
#: numpy's BLAS sums in another order on another CPU.  Select them with ``-m numerics``.
NUMERIC_MODULES = {
    "test_pointcloud_tables", "test_pointcloud_closed_forms", "test_pointcloud_workbook",
    "test_budget_core", "test_budget_workbook",
    "test_jcgm106_examples",
    "test_features_core", "test_features_workbook", "test_partial_tables", "test_montecarlo",
    "test_blocked", "test_large_workbook", "test_large_feature_workbook", "test_udf", "test_dask",
    "test_diagnose_core", "test_diagnose_book", "test_diagnose_rates",
    "test_templates", "test_roundtrip", "test_lowrank", "test_diagnose_structured", "test_import",
    "test_diagnose_second", "test_exact_option", "test_diagnose_discrepancy", "test_kernels", "test_diagnose_new_candidates",
    "test_field_csv", "test_field_plausibility",
    "test_characteristics", "test_reference_fits", "test_characteristics_workbook",
    "test_qif_characteristics",
    "test_diagnose_structured_lengths", "test_rank_refusal", "test_all_pairs_stream",
    "test_calibrate_core", "test_calibrate_loop", "test_calibrate_verdicts",
    "test_reml_structured",
    "test_conformity_core", "test_statement_core", "test_dof_core", "test_decision_workbook", "test_provenance",
    "test_readable",
    "test_all_pairs_probe_tables",
    "test_characteristic_decisions",
    "test_budget_dof",
    "test_model_paths",
    "test_diagnose_effect_formulas",
    "test_validate_core", "test_validate_cli", "test_validate_book", "test_validate_loop",
    "test_workpiece", "test_hyperparameters",
}


def pytest_collection_modifyitems(config, items):
    """Marks the numerically sensitive tests (``numerics``).  LibreOffice (Gnumeric) tests are
    skipped where LibreOffice (Gnumeric's ssconvert) is missing, except in CI, where a missing
    engine is an installation error and must fail loudly."""
    for item in items:
        if item.module.__name__.rsplit(".", 1)[-1] in NUMERIC_MODULES:
            item.add_marker(pytest.mark.numerics)
    if os.environ.get("CI"):
        return
    for engine, program in (("libreoffice", "LibreOffice (soffice)"), ("gnumeric", "Gnumeric (ssconvert)")):
        if installed(engine):
            continue
        skip = pytest.mark.skip(reason=f"{program} not installed")
        for item in items:
            if engine in item.keywords:
                item.add_marker(skip)


# -- every workbook a test writes passes the Open XML validator (docs/engines.md, Excel) ----------

_watch: Watch | None = None


@pytest.fixture(autouse=True)
def _every_workbook_written_passes_the_open_xml_validator(request, tmp_path_factory):
    """After each test, the ``.xlsx`` files new under this worker's temporary folder (the test's
    ``tmp_path`` and its fixtures' folders) go through the validator: no errors but the
    validator's documented false positives (``tests.helpers.openxml``).  A test that writes
    hostile or other programs' files on purpose is marked ``foreign_books``."""
    global _watch
    yield
    if _watch is None:
        _watch = Watch(tmp_path_factory.getbasetemp())
    found = _watch.check(skip=request.node.get_closest_marker("foreign_books") is not None)
    if found:
        pytest.fail(f"{len(found)} Open XML validator error(s):\n" + "\n".join(found[:20]), pytrace=False)


# -- the session summary: cells per engine, books validated ------------------------------------------

_totals: Counter = Counter()


def _session_counts() -> Counter:
    counts = Counter({f"cells {e}": n for e, n in ENGINE_CELLS.items()})
    if _watch is not None:
        counts.update({"books validated": _watch.validated, "books same as one validated": _watch.same,
                       "validator ms": round(1000 * _watch.seconds)})
    return counts


def pytest_sessionfinish(session):
    if hasattr(session.config, "workeroutput"):          # an xdist worker: hand the counts over
        session.config.workeroutput["cmmwb_counts"] = dict(_session_counts())


def pytest_testnodedown(node, error):
    _totals.update(getattr(node, "workeroutput", {}).get("cmmwb_counts", {}))


def pytest_terminal_summary(terminalreporter):
    counts = _totals or _session_counts()
    if not counts:
        return
    cells = ", ".join(f"{k[6:]} {counts[k]:,}" for k in sorted(counts) if k.startswith("cells "))
    terminalreporter.write_line(f"engine cells the tests read and compared: {cells or 'none'}")
    terminalreporter.write_line(
        f"Open XML validator: {counts['books validated']:,} workbooks validated, {counts['books same as one validated']:,} "
        f"the same as one of them, {counts['validator ms'] / 1000:.0f} s")

