"""The task kinds and the modules that handle them (load, compute, write_book, write_plots)."""

from __future__ import annotations

import importlib
from types import ModuleType

JOB_MODULES = {
    "pointcloud": "generator.pointcloud.job",
    "budget": "generator.budget.job",
    "feature": "generator.feature.job",
    "characteristic": "generator.characteristic.job",
}


def job(kind: str) -> ModuleType:
    """The job module of a task kind."""
    return importlib.import_module(JOB_MODULES[kind])


def available() -> list[str]:
    """Kinds whose job module is present in this installation."""
    out = []
    for kind in JOB_MODULES:
        try:
            job(kind)
        except ModuleNotFoundError as e:
            if e.name != JOB_MODULES[kind]:   # present, but something it needs is missing: say so
                raise
            continue
        out.append(kind)
    return out
