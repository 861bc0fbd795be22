"""pytest hooks of the whole suite: one BLAS thread per xdist worker, the ``numerics`` marker
(``NUMERIC_MODULES``), LibreOffice tests skipped where LibreOffice is missing.  What tests share
(paths, the three-engine comparison, writers of tasks) is in ``tests/helpers/``."""

from __future__ import annotations

import os

import numpy  # noqa: F401  (loads OpenBLAS, so that its threads can be limited below)
import pytest

from cmmwb.generator.workbook.recalc import soffice

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
    "test_calibrate_core", "test_calibrate_loop",
    "test_reml_structured",
    "test_conformity_core", "test_statement_core", "test_dof_core", "test_decision_workbook", "test_provenance",
    "test_readable",
    "test_all_pairs_probe_tables",
    "test_characteristic_decisions",
    "test_budget_dof",
    "test_model_paths",
    "test_diagnose_effect_formulas",
    "test_workpiece", "test_hyperparameters",
}


def pytest_collection_modifyitems(config, items):
    """Marks the numerically sensitive tests (``numerics``).  LibreOffice tests are skipped where
    LibreOffice is missing, except in CI, where a missing LibreOffice is an installation error and
    must fail loudly."""
    for item in items:
        if item.module.__name__.rsplit(".", 1)[-1] in NUMERIC_MODULES:
            item.add_marker(pytest.mark.numerics)
    if soffice() is not None or os.environ.get("CI"):
        return
    skip = pytest.mark.skip(reason="LibreOffice (soffice) not installed")
    for item in items:
        if "libreoffice" in item.keywords:
            item.add_marker(skip)

