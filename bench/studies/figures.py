"""Figures of studies (matplotlib, PNG): the compliance map and identification errors."""

from __future__ import annotations

import logging
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
from matplotlib.ticker import FixedLocator, NullFormatter, ScalarFormatter  # noqa: E402

log = logging.getLogger(__name__)


def _grid(t, n: float):
    """(betas, gammas, G_up, G_down, jump, peak) arrays of one n, gamma0 rows x beta columns."""
    d = {c: np.asarray(t.column(c).to_pylist()) for c in ("n", "gamma0", "beta", "G_up", "G_down",
                                                          "jump_region", "peak")}
    sel = d["n"] == n
    gammas = np.unique(d["gamma0"][sel])
    betas = np.unique(d["beta"][sel])
    shape = (gammas.size, betas.size)
    out = {k: np.full(shape, np.nan if k.startswith("G") else 0, dtype=float if k.startswith("G") else object)
           for k in ("G_up", "G_down", "jump_region", "peak")}
    gi = np.searchsorted(gammas, d["gamma0"][sel])
    bi = np.searchsorted(betas, d["beta"][sel])
    for k in out:
        out[k][gi, bi] = d[k][sel]
    return betas, gammas, out


def plot_compliance_map(table, path: Path) -> Path:
    """One panel per n: log colour of G (up sweep) over beta (x) and gamma0 (y); ridges
    (harmonic: white, superharmonic: cyan) and jump regions (up and down sweeps differ:
    hatched, boundaries in black)."""
    ns = sorted(set(table.column("n").to_pylist()))
    cols = min(len(ns), 3)
    rows = -(-len(ns) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(6.0 * cols, 4.6 * rows), squeeze=False)
    G_all = np.asarray(table.column("G_up").to_pylist(), dtype=float)
    G_all = G_all[np.isfinite(G_all) & (G_all > 0)]
    norm = LogNorm(vmin=G_all.min(), vmax=G_all.max()) if G_all.size else None
    for ax, n in zip(axes.flat, ns):
        betas, gammas, g = _grid(table, n)
        mesh = ax.pcolormesh(betas, gammas, g["G_up"], norm=norm, cmap="viridis", shading="nearest")
        for kind, colour, marker in (("harmonic", "white", "o"), ("superharmonic", "cyan", ".")):
            gi, bi = np.nonzero(g["peak"] == kind)
            if gi.size:
                # one harmonic resonance per row: join them into the ridge line
                ax.plot(betas[bi], gammas[gi], marker, color=colour, ms=3 if kind == "harmonic" else 2.5,
                        ls="-" if kind == "harmonic" else "none", lw=1, label=f"{kind} resonance")
        jump = g["jump_region"].astype(bool)
        if jump.any():
            ax.contourf(betas, gammas, jump.astype(float), levels=[0.5, 1.5], colors="none", hatches=["///"])
            ax.contour(betas, gammas, jump.astype(float), levels=[0.5], colors="black", linewidths=1.2)
            ax.plot([], [], color="black", label="jump boundary (up != down)")
        else:
            ax.text(0.98, 0.02, "no jumps: up and down sweeps agree", transform=ax.transAxes,
                    ha="right", va="bottom", fontsize=8, color="white")
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(FixedLocator([t for t in (0.1, 0.2, 0.5, 1, 2, 5, 10) if betas[0] <= t <= betas[-1]]))
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("frequency ratio beta = omega / omega_s")
        ax.set_ylabel("force ratio gamma0 = P0 / F_s")
        ax.set_title(f"compliance G(beta, gamma0), n = {n:g}")
        ax.legend(loc="upper right", fontsize=7, framealpha=0.6)
        fig.colorbar(mesh, ax=ax, label="G = u0 / gamma0 (log)")
    for ax in list(axes.flat)[len(ns):]:
        ax.set_visible(False)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


UNITS = dict(F_s_N="F_s", x_s_m="x_s", n="n", mass_kg="m")


def plot_identification_errors(table, path: Path) -> Path:
    """Per parameter: histogram of the relative error estimate/truth - 1 (per cent), with
    the median, the 95th percentile of |error| and how often the 95 % interval covered
    the truth."""
    par = np.asarray(table.column("parameter").to_pylist())
    err = 100 * np.asarray(table.column("rel_error").to_pylist(), dtype=float)
    cov = np.asarray(table.column("covered").to_pylist(), dtype=bool)
    names = [p for p in UNITS if p in set(par)]
    fig, axes = plt.subplots(1, len(names), figsize=(3.6 * len(names), 3.4), squeeze=False)
    for ax, p in zip(axes.flat, names):
        e, c = err[par == p], cov[par == p]
        e = e[np.isfinite(e)]
        ax.hist(e, bins=max(5, min(30, e.size // 2 or 1)), color="tab:blue", alpha=0.8)
        ax.axvline(0, color="black", lw=0.8)
        ax.set_title(f"{UNITS[p]}: {e.size} rigs")
        ax.set_xlabel("estimate / truth - 1 (%)")
        ax.text(0.02, 0.97, f"median {np.median(e):+.2g} %\n|err| 95th pct {np.percentile(np.abs(e), 95):.2g} %\n"
                f"95 % interval covers: {100 * c.mean():.0f} %", transform=ax.transAxes, va="top", fontsize=7.5,
                bbox=dict(facecolor="white", alpha=0.8, edgecolor="none"))
    axes[0, 0].set_ylabel("rigs")
    fig.suptitle("identification errors over random rigs and noise (one plan)", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
