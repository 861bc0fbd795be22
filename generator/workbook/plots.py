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
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


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
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)
