"""Running independent block tasks: on local threads (:class:`ThreadBackend`) or on any backend
with ``map(fn, items, shared)`` returning the results in order (:mod:`xlfuncs.distributed`), with
an optional ``progress(done, total)`` callback (:class:`ProgressBar` draws a text bar).

Shared by :mod:`xlfuncs.blocked` and :mod:`xlfuncs.lowrank`, which both cut their work into
blocks; neither imports the other for it.
"""

from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Sequence

__all__ = ["ThreadBackend", "ProgressBar", "run_blocks"]


class ThreadBackend:
    """Runs block tasks on a local thread pool; ``workers=None``: one per core."""

    name = "threads"

    def __init__(self, workers: int | None = None):
        self.workers = workers or os.cpu_count() or 1

    def map(self, fn: Callable, items: Sequence, shared) -> Iterable:
        """``fn(item, shared)`` for every item; results in the order of ``items``."""
        items = list(items)
        if self.workers <= 1 or len(items) <= 1:
            return (fn(it, shared) for it in items)
        return _ordered_pool_map(fn, items, shared, min(self.workers, len(items)))


def _ordered_pool_map(fn, items, shared, workers):
    pool = ThreadPoolExecutor(max_workers=workers)
    try:
        yield from pool.map(lambda it: fn(it, shared), items)
    finally:
        pool.shutdown(cancel_futures=True)


def run_blocks(fn, items: list, shared, backend, progress, weights: Sequence[float] | None = None) -> list:
    """Run the block tasks, report progress (weighted by the work in each block), return the
    results in the order of ``items`` (so sums are reproducible whatever the backend)."""
    backend = backend or ThreadBackend()
    weights = list(weights) if weights is not None else [1.0] * len(items)
    total = float(sum(weights)) or 1.0
    out, done = [], 0.0
    for k, r in enumerate(backend.map(fn, items, shared)):
        out.append(r)
        done += weights[k]
        if progress is not None:
            progress(done, total)
    if progress is not None and not items:
        progress(1.0, 1.0)
    return out


class ProgressBar:
    """``progress(done, total)`` callback drawing ``label [#####     ]  48%  3.1 s`` on a stream.

    Silent for the first ``delay_s`` seconds, so quick runs print nothing; ends the line when
    ``done == total``.  Without a ``stream`` it draws on stderr only when stderr is a terminal: a
    bar of carriage returns is noise in a log file or a pipe (``cmmwb build ... 2>&1 | tee``).
    """

    def __init__(self, label: str = "", stream=None, width: int = 30, delay_s: float = 1.0):
        self.label = label
        if stream is None:
            stream = sys.stderr if _is_terminal(sys.stderr) else None
        self.stream = stream
        self.width = width
        self.delay_s = delay_s
        self.t0 = time.perf_counter()
        self.last = 0.0
        self.shown = False
        self.closed = False

    def __call__(self, done: float, total: float) -> None:
        now = time.perf_counter()
        elapsed = now - self.t0
        finished = done >= total * (1 - 1e-12)
        if self.stream is None or self.closed or (elapsed < self.delay_s and not self.shown):
            return
        if not finished and now - self.last < 0.2:
            return
        self.last = now
        frac = 0.0 if total <= 0 else min(max(done / total, 0.0), 1.0)
        n = int(round(frac * self.width))
        self.stream.write(f"\r{self.label} [{'#' * n}{' ' * (self.width - n)}] {100 * frac:3.0f}%  "
                          f"{elapsed:.1f} s")
        self.shown = True
        if finished:
            self.stream.write("\n")
            self.closed = True
        self.stream.flush()


def _is_terminal(stream) -> bool:
    try:
        return bool(stream is not None and stream.isatty())
    except (AttributeError, ValueError):   # no isatty, or a closed stream
        return False
