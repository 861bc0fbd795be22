"""Dask backend for the blocked computations of :mod:`xlfuncs.blocked` (optional extra
``pip install "cmmwb[dask]"``).

The blocked functions (:func:`~xlfuncs.blocked.V_A_components`,
:func:`~xlfuncs.blocked.distance_components`, :func:`~xlfuncs.record_covariance.record_covariance`, ...)
split their work into independent row blocks and hand them to a *backend*: any object with
``map(fn, items, shared)`` that returns ``fn(item, shared)`` for every item, in order.  Without
a backend they run on a local thread pool.  :class:`DaskBackend` runs the same blocks as Dask
tasks:

* ``DaskBackend()``: an in-process Dask cluster of threads on this machine;
* ``DaskBackend("tcp://scheduler:8786")``: the workers of an existing Dask cluster (they need
  cmmwb installed); the shared arrays (points, weights) are scattered to the workers once;
* ``DaskBackend(client)``: an existing ``distributed.Client``.

Results are collected in block order, so the numbers are the same as the local path's to the
last bit.  :func:`get_backend` picks the backend from ``CMMWB_SCHEDULER`` (unset or
``local``: local threads; ``dask``: local Dask threads; an address: that cluster), so a batch
of tasks moves to a cluster without code changes.
"""

from __future__ import annotations

import os
from typing import Callable, Iterable, Sequence

from .errors import ModelError

ENV = "CMMWB_SCHEDULER"


class DaskBackend:
    """Block tasks on Dask (see the module docstring).  Use as a context manager or call
    :meth:`close` to shut down a cluster it started."""

    name = "dask"

    def __init__(self, scheduler=None, *, threads: int | None = None):
        try:
            from distributed import Client
        except ImportError:
            raise ModelError('the Dask backend needs the optional extra: pip install "cmmwb[dask]" '
                             '(dask[distributed])') from None
        self._own = True
        self._own_cluster = scheduler is None
        if scheduler is None:
            self.client = Client(processes=False, n_workers=1,
                                 threads_per_worker=threads or os.cpu_count() or 1,
                                 dashboard_address=None)
        elif isinstance(scheduler, str):
            try:
                self.client = Client(scheduler, timeout="20s")
            except (OSError, TimeoutError) as e:
                raise ModelError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
        else:
            self.client = scheduler
            self._own = False

    @property
    def address(self) -> str:
        return self.client.scheduler.address

    def map(self, fn: Callable, items: Sequence, shared) -> Iterable:
        items = list(items)
        if not items:
            return iter(())
        [shared_f] = self.client.scatter([shared], broadcast=True)
        futures = self.client.map(fn, items, shared=shared_f, pure=False)
        return self._results(futures, shared_f)

    @staticmethod
    def _results(futures, shared_f):
        try:
            for f in futures:
                yield f.result()
        finally:
            for f in futures:
                f.release()
            shared_f.release()

    def close(self) -> None:
        if self._own:
            cluster = getattr(self.client, "cluster", None) if self._own_cluster else None
            self.client.close()
            if cluster is not None:
                cluster.close()

    def __enter__(self) -> "DaskBackend":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def get_backend(spec: str | None = None):
    """The backend named by ``spec`` or, when None, by the environment variable
    ``CMMWB_SCHEDULER``: None (local threads) for "" or "local", a local :class:`DaskBackend`
    for "dask", a cluster's :class:`DaskBackend` for a scheduler address."""
    spec = os.environ.get(ENV, "") if spec is None else spec
    spec = spec.strip()
    if spec in ("", "local", "threads"):
        return None
    if spec == "dask":
        return DaskBackend()
    return DaskBackend(spec)
