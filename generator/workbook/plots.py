"""PNG plots beside the workbooks (matplotlib, headless)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

os.environ.setdefault("MPLBACKEND", "Agg")


def pyplot():
    """matplotlib.pyplot with the headless Agg backend."""
    return _plt()


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    # names and groups come from the user's files: a '$' in them is a dollar sign, not mathtext
    # (matplotlib would otherwise parse "$a$b" as a formula and fail on an odd number of '$')
    matplotlib.rcParams["text.parse_math"] = False
    import matplotlib.pyplot as plt

    return plt


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def decade_label(value: float) -> str:
    """A log-axis tick label as plain text: 0.01 ... 1000 as decimals, other powers of ten as
    10 with a superscript exponent (10⁻⁴, 10⁵), anything else in %g."""
    if not value > 0:
        return ""
    e = np.log10(value)
    k = int(round(e))
    if abs(e - k) > 1e-9:
        return f"{value:g}"
    if -2 <= k <= 3:
        return f"{10.0 ** k:g}"
    return "10" + str(k).translate(_SUPERSCRIPT)


def log_scale(ax, axis: str = "y") -> None:
    """A logarithmic ``axis`` ("x" or "y") whose tick labels are plain text.

    :func:`pyplot` turns mathtext off (``text.parse_math``: names from the user's files may hold
    '$'), and matplotlib's default log labels are mathtext (``$\\mathdefault{10^{1}}$``), which
    then print literally; these formatters write no mathtext."""
    from matplotlib.ticker import FuncFormatter

    target = ax.yaxis if axis == "y" else ax.xaxis
    (ax.set_yscale if axis == "y" else ax.set_xscale)("log")
    target.set_major_formatter(FuncFormatter(lambda v, _pos: decade_label(v)))

    def minor(v, _pos):
        # 2 and 5 x a decade are labelled only when the axis spans less than two decades
        lo, hi = sorted(target.get_view_interval())
        if lo <= 0 or np.log10(hi / lo) >= 2:
            return ""
        mantissa = v / 10.0 ** np.floor(np.log10(v) + 1e-9)
        return f"{v:g}" if min(abs(mantissa - 2), abs(mantissa - 5)) < 1e-6 else ""

    target.set_minor_formatter(FuncFormatter(minor))


def _finish(plt, fig, ax, path: Path) -> Path:
    """The line plots' common ending: a light grid, the legend, a tight layout, the PNG written
    and the figure closed."""
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def distance_plot(results: dict, path: Path) -> Path:
    """K u(d) against d per group (Forbes 2025 Figures 6/7), with the MPE line when known."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=110)
    ds = results["distances"]
    groups = list(dict.fromkeys(d.get("group", "") for d in ds))
    markers = "osD^v<>ph*"
    for k, g in enumerate(groups):
        sel = [d for d in ds if d.get("group", "") == g]
        # hollow markers of decreasing size: series that coincide (LL and RR) stay visible
        ax.plot([d["d_mm"] for d in sel], [d["U_um"] for d in sel], markers[k % len(markers)],
                ms=max(3.0, 7.5 - 1.5 * k), mfc="none", label=g or "distances")
    if "mpe_check" in results:
        c = results["mpe_check"]
        dmax = max(d["d_mm"] for d in ds)
        x = np.array([0.0, dmax])
        ax.plot(x, c["A_um"] + x / c["B_mm"], "k-", lw=1, label="MPE A + d/B")
    ax.set_xlabel("d / mm")
    ax.set_ylabel(f"U = K u / µm (K = {results.get('K', 2):g})")
    ax.set_title(results["name"])
    return _finish(plt, fig, ax, path)


def mpe_plot(d, mpe, comp: dict, K: float, path: Path, title: str) -> Path:
    """MPE line, K u(d) and its components (Forbes 2025 Figures 4/5)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=110)
    ax.plot(d, mpe, "k-", lw=1.5, label="MPE A + d/B")
    ax.plot(d, K * comp["u"], "-", lw=2, label="K u(d), eq. (33)")
    ax.plot(d, K * comp["S"], ":", label="K u_S")
    ax.plot(d, K * comp["ET"], "--", label="K u_ET")
    ax.plot(d, K * comp["ER"], "-.", label="K u_ER")
    ax.plot(d, K * comp["A"], "-", lw=0.8, label="K sigma_A")
    ax.set_xlabel("d / mm")
    ax.set_ylabel("µm")
    ax.set_title(f"{title}: MPE check")
    return _finish(plt, fig, ax, path)


def factor_share_plot(labels, shares: dict, title: str, path: Path, *, width: float = 7.0,
                      row_height: float = 0.45, top_down: bool = False, legend_y: float = 1.08) -> Path:
    """One horizontal bar per label, stacked by influence factor: the share u_f^2 / u^2 of each
    factor in the variance (Forbes 2025 section 5.6).  ``shares``: factor -> one share per label,
    in the order the factors are stacked; ``top_down``: the first label at the top."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(width, row_height * len(labels) + 1.6), dpi=110)
    left = np.zeros(len(labels))
    for fac, share in shares.items():
        share = np.asarray(share, float)
        ax.barh(labels, share, left=left, label=fac)
        left += share
    ax.set_xlim(0, 1)
    if top_down:
        ax.invert_yaxis()
    ax.set_xlabel("share of u^2 per influence factor")
    ax.set_title(title)
    ax.legend(fontsize=8, ncol=len(shares), loc="lower center", bbox_to_anchor=(0.5, legend_y))
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)
