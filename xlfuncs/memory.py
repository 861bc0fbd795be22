"""Memory needs estimated before large allocations, refused with a message saying what fits.

The dense parts of the mismatch locator (:mod:`xlfuncs.locator.diagnose`) hold the covariance of the
records as n x n matrices: for length records C = G V_X G^T per factor (R, PQ, S, ET, ER, P),
their sum and its Cholesky factor; for point records V_X of the measured points (3n x 3n, Forbes
2025 eq. 28) and C restricted to the compared coordinates.  :func:`diagnose_bytes` is the
estimate of that peak; large point records use the structured operator of
:mod:`xlfuncs.locator.structured` instead (C = D + U U^T never formed), whose peak grows linearly in n
(measured in bench/results/million_diagnose.md: 386 MB at 1,000 records, 1,602 MB at 200,000,
about 6 KB per record); when the algorithm changes, change this function with it, and the guard
in the CLI follows.
"""

from __future__ import annotations

import math
import os

from .errors import ModelError

#: point and length records with more observations than this use the structured covariance
#: (:mod:`xlfuncs.locator.structured`, :mod:`xlfuncs.locator.structured_lengths`: C = D + U U^T
#: never formed) unless asked otherwise (``diagnose --exact``)
STRUCTURED_MIN_OBS = 6000

#: n x n matrices alive at the peak of a length-record diagnosis (6 factors, sum, factor, spare)
LENGTH_MATRICES = 10
#: (dims n) x (dims n) matrices alive at the peak of a point-record diagnosis, besides V_X
#: (measured with V_X: 2,777 MB at 2,000 records, 15,319 MB at 5,000, about 9.7 and 8.9 doubles
#: per (3n)^2 entry, bench/results/million_equal.md; 6 underestimated by 30 %)
POINT_MATRICES = 9
#: dense point-record diagnosis: the interpreter, numpy and the records besides the matrices
POINT_BASE_BYTES = 256 * 2**20
#: structured point-record diagnosis: a fixed part and bytes per record (measured ~6 KB, with margin)
STRUCTURED_BASE_BYTES = 512 * 2**20
STRUCTURED_BYTES_PER_RECORD = 8 * 2**10


class ResourceError(ModelError):
    """The computation would need more memory than this machine has."""


def diagnose_bytes(kind: str, n_records: int, dims: int = 3, structured: bool = False) -> int:
    """Estimated peak memory (bytes) of :func:`xlfuncs.locator.diagnose.diagnose` on ``n_records``
    (``structured``: the structured operator of point or length records
    (:mod:`xlfuncs.locator.structured_lengths`), linear in n)."""
    n = int(n_records)
    if structured:
        return STRUCTURED_BASE_BYTES + STRUCTURED_BYTES_PER_RECORD * n
    if kind == "length":
        return 8 * LENGTH_MATRICES * n * n
    return POINT_BASE_BYTES + 8 * ((3 * n) ** 2 + POINT_MATRICES * (dims * n) ** 2)


def available_bytes() -> int:
    """Memory this process may still use: MemAvailable, or the address-space limit if lower."""
    avail = None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError):
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = 8 * 2**30
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft not in (resource.RLIM_INFINITY, -1) and soft > 0:
            avail = min(avail, soft)
    except (ImportError, ValueError, OSError):
        pass
    return int(avail)


def _gib(b: float) -> str:
    return f"{b / 2**30:,.1f} GiB" if b >= 2**30 else f"{b / 2**20:,.0f} MiB"


def check_diagnose_fits(kind: str, n_records: int, dims: int = 3, available: int | None = None,
                        structured: bool = False) -> None:
    """Raise :class:`ResourceError` when :func:`diagnose_bytes` exceeds what is available, saying
    how many records would fit."""
    need = diagnose_bytes(kind, n_records, dims, structured)
    have = available_bytes() if available is None else available
    if need <= have:
        return
    if structured:
        fits = max((have - STRUCTURED_BASE_BYTES) // STRUCTURED_BYTES_PER_RECORD, 0)
    else:
        base = diagnose_bytes(kind, 0, dims)            # the estimate is base + per_n2 n^2
        per_n2 = diagnose_bytes(kind, 1, dims) - base
        fits = max(int(math.isqrt(max(have - base, 0) // per_n2)), 0)
    raise ResourceError(f"diagnosing {n_records:,} {kind} records needs about {_gib(need)} of memory, "
                        f"{_gib(have)} are available: at most about {fits:,} records fit; split the "
                        "recordings into smaller files (e.g. by group) and diagnose each")


#: recordings with fewer data lines are parsed before their memory is checked (:func:`check_records_fit`)
PARSE_FIRST_RECORDS = 100_000


def check_records_fit(n_records: int, available: int | None = None) -> None:
    """Raise :class:`ResourceError` when even the least any diagnosis or calibration of
    ``n_records`` records needs (the structured covariance, linear in n: :func:`diagnose_bytes`)
    exceeds what is available -- checked from the number of lines, before the recordings are
    parsed (parsing ten million records alone took 28 s and 3.9 GB before the later refusal).
    Below :data:`PARSE_FIRST_RECORDS` records the file is parsed first (at most about 0.3 s and
    40 MB): their kind is then known and :func:`check_diagnose_fits` says exactly what fits (for a
    few records the dense covariance, 80 n^2 bytes for length records, is the smaller need)."""
    if n_records < PARSE_FIRST_RECORDS:
        return
    need = diagnose_bytes("point", n_records, structured=True)
    have = available_bytes() if available is None else available
    if need <= have:
        return
    fits = max((have - STRUCTURED_BASE_BYTES) // STRUCTURED_BYTES_PER_RECORD, 0)
    raise ResourceError(f"{n_records:,} records: their diagnosis or calibration needs at least about "
                        f"{_gib(need)} of memory (the structured covariance, "
                        f"{STRUCTURED_BYTES_PER_RECORD // 2**10} KB per record), {_gib(have)} are available: "
                        f"at most about {fits:,} records fit; split the recordings into smaller files")
