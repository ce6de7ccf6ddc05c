"""Reproduce the seed's numerical figures (Sakai 2020, Figs. 3-4 and 6-13) from the model,
and the trend of its section 4 (Figs. 15-17: the feed and pitching modes' resonances fall
as the force rises) from the simulated rig's pitching model.

``reproduce(out_dir)`` writes one PNG and one CSV per figure plus an index (README.md for
people, summary.csv for programs) naming the seed figure each file corresponds to and the
key numbers (resonance frequencies and compliances).  Everything is dimensionless:
u = x/x_s, F/F_s, beta = omega/omega_s, tau = omega t, G = u_0/gamma0 (seed Eq. 9).

Figures are drawn on :class:`matplotlib.figure.Figure` objects (Agg canvas), never through
pyplot, so this module neither needs nor changes a global matplotlib backend.

Longer than 600 lines: one job, the seed's figures; each ``figNN`` function computes its
figure, draws it and hands its key numbers to the index, which :func:`write_index` writes
from them, so a figure and the line of the index that checks it stay side by side.
"""

from __future__ import annotations

import csv
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from .dynamics import Integrator, SteadyState, steady_state
from .features import CycleFeatures, cycle_features
from .frf import FrequencyResponse, Peak, find_peaks
from .masing import MasingFriction
from .shooting import frf_shooting
from .virgin import SakaiCurve

if TYPE_CHECKING:
    from .rig import RigModel

log = logging.getLogger(__name__)

SHAPE_FACTORS = (0.5, 1.5)
GAMMA0_FIG6 = 0.6
# Seed Figs. 7-11: the frequencies A, B, C marked in Fig. 6.
SEED_FREQUENCIES = {0.5: {"A": 0.54, "B": 0.90, "C": 1.65},
                    1.5: {"A": 0.45, "B": 0.71, "C": 1.40}}
VIRGIN_SHAPE_FACTORS = (0.3, 0.5, 1.5, 3.0)
HISTORY_SAMPLES = 4000          # samples per recorded steady period
COLOURS = {0.5: "tab:blue", 1.5: "tab:red"}


@dataclass(frozen=True)
class Grids:
    """Resolution of every sweep; ``quick`` trades accuracy for a run of a few seconds."""

    fig6_betas: np.ndarray
    fig12_betas: np.ndarray
    fig12_gamma0: tuple[float, ...]
    fig13_betas: np.ndarray          # coarse search for the harmonic peak
    fig13_zoom_points: int           # refinement between the coarse maximum's neighbours
    fig13_gamma0: tuple[float, ...]
    pitch_levels_N: tuple[float, ...] = (0.1, 3.0, 100.0)   # Figs. 15-17: force amplitudes
    pitch_freqs_Hz: np.ndarray | None = None                # coarse sweep (None: 24 points)

    @classmethod
    def for_run(cls, quick: bool) -> Grids:
        if quick:
            return cls(np.linspace(0.2, 2.0, 37), np.linspace(0.2, 3.0, 29), (0.4, 0.8),
                       np.geomspace(0.4, 5.0, 25), 7, (0.2, 0.6, 0.9),
                       (0.1, 3.0, 100.0), np.geomspace(40.0, 300.0, 24))
        # The harmonic peak moves up as gamma0 falls (n = 0.5, gamma0 = 0.2: beta ~ 2.5;
        # gamma0 = 0.1: beta ~ 3.7), hence the ranges of Figs. 12 and 13.
        return cls(np.linspace(0.2, 2.0, 200), np.linspace(0.2, 3.0, 200), (0.2, 0.4, 0.6, 0.8, 0.9),
                   np.geomspace(0.4, 5.0, 120), 21,
                   (0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95),
                   (0.1, 0.3, 1.0, 2.0, 3.0, 5.0, 10.0, 30.0, 100.0), np.geomspace(30.0, 300.0, 48))


@dataclass(frozen=True)
class Cycle:
    """A steady response at one of the seed's frequencies A, B, C."""

    n: float
    letter: str
    steady: SteadyState
    features: CycleFeatures


class Report:
    """Collects written files and index rows (file, seed figure, n, gamma0, item, beta, G)."""

    def __init__(self, out_dir: Path):
        self.out_dir = out_dir
        self.files: list[Path] = []
        self.figures: list[tuple[str, str, str]] = []     # (png name, seed figure, what)
        self.rows: list[tuple] = []

    def figure(self, fig: Figure, stem: str, seed_figure: str, what: str) -> Path:
        path = self.out_dir / f"{stem}.png"
        fig.savefig(path, dpi=110)
        self.files.append(path)
        self.figures.append((path.name, seed_figure, what))
        return path

    def table(self, stem: str, columns: list[str], data) -> Path:
        """CSV with one header line of ``name [unit]`` columns."""
        path = self.out_dir / f"{stem}.csv"
        np.savetxt(path, np.asarray(data, dtype=np.float64), delimiter=",", fmt="%.10g",
                   header=",".join(columns), comments="")
        self.files.append(path)
        return path

    def key(self, file: str, seed_figure: str, n, gamma0, item: str, beta: float, G: float):
        self.rows.append((file, seed_figure, n, gamma0, item, beta, G))


def _frf(betas, gamma0: float, n: float) -> tuple[FrequencyResponse, np.ndarray]:
    return frf_shooting(betas, gamma0, n, integrator=Integrator(n=n))


def _axes_frf(ax, title: str):
    ax.set_xlabel(r"frequency ratio $\beta = \omega/\omega_s$ [-]")
    ax.set_ylabel(r"compliance $G = u_0/\gamma_0$ [-]")
    ax.set_title(title)
    ax.grid(alpha=0.3)


# --- Seed Fig. 3 (and Fig. 1): Masing hysteresis with an inner loop -----------------------


MASING_PATH = (("O", 0.0), ("A", 1.5), ("a", 0.0), ("b", 0.8), ("a", 0.0), ("B", -1.5), ("A", 1.5))
SEGMENT_SAMPLES = 300


def fig03_masing_hysteresis(rep: Report, grids: Grids):
    """O -> A on the virgin curve, outer branch down to a, inner loop a-b-a, on to B, back to A."""
    ends = [u for _, u in MASING_PATH]
    path = np.concatenate([[0.0]] + [np.linspace(u0, u1, SEGMENT_SAMPLES + 1)[1:]
                                     for u0, u1 in zip(ends[:-1], ends[1:])])
    fig = Figure(figsize=(10, 4.5), layout="constrained")
    rows = []
    for j, n in enumerate(SHAPE_FACTORS):
        curve = SakaiCurve(n)
        F = np.concatenate([[0.0], MasingFriction(curve).force(path[1:])])
        rows += [(n, u, f) for u, f in zip(path, F)]
        ax = fig.add_subplot(1, 2, j + 1)
        s = np.linspace(0, 1.6, 200)
        ax.plot(np.r_[-s[::-1], s], np.r_[-curve(s[::-1]), curve(s)], ":", color="grey",
                label="virgin curve (Eq. 1)")
        ax.plot(path, F, color=COLOURS[n], label="Masing rule (Eq. 2), λ = 2")
        seen = set()
        for k, (name, u) in enumerate(MASING_PATH):
            if name not in seen:
                seen.add(name)
                Fk = F[k * SEGMENT_SAMPLES]
                ax.plot(u, Fk, "ko", ms=4)
                ax.annotate(name, (u, Fk), textcoords="offset points", xytext=(4, -13 if Fk > 0 else 5))
        ax.set_xlabel(r"displacement $u = x/x_s$ [-]")
        ax.set_ylabel(r"friction $F/F_s$ [-]")
        ax.set_title(f"Seed Fig. 3: Masing hysteresis, n = {n}")
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    rep.table("fig03_masing_hysteresis", ["n [-]", "u [-]", "F_over_Fs [-]"], rows)
    rep.figure(fig, "fig03_masing_hysteresis", "Fig. 3 (Fig. 1)",
               "friction along O-A-a-b-a-B-A: virgin loading, outer loop, inner loop a-b-a closing")


# --- Seed Fig. 4: virgin loading curves ------------------------------------------------------

def fig04_virgin_curves(rep: Report, grids: Grids):
    u = np.linspace(0.0, 1.5, 301)
    fig = Figure(figsize=(6, 4.5), layout="constrained")
    ax = fig.add_subplot()
    cols = [u]
    for n in VIRGIN_SHAPE_FACTORS:
        f = SakaiCurve(n)(u)
        cols.append(f)
        ax.plot(u, f, label=f"n = {n}")
    ax.axvline(1.0, color="grey", lw=0.8, ls="--")
    ax.text(1.02, 0.05, "rolling region", color="grey")
    ax.text(0.3, 0.05, "pre-rolling region", color="grey")
    ax.set_xlabel(r"displacement $x/x_s$ [-]")
    ax.set_ylabel(r"virgin loading curve $f/F_s$ [-]")
    ax.set_title("Seed Fig. 4: virgin loading curve (Eq. 3, reconstructed)")
    ax.grid(alpha=0.3)
    ax.legend(title="shape factor")
    rep.table("fig04_virgin_curves", ["x_over_xs [-]"] + [f"f_over_Fs_n{n:g} [-]" for n in VIRGIN_SHAPE_FACTORS],
              np.column_stack(cols))
    rep.figure(fig, "fig04_virgin_curves", "Fig. 4", "virgin loading curves f/F_s for several n")


# --- Seed Fig. 6: FRF at gamma0 = 0.6 with peaks and frequencies A, B, C --------------------

def _ordering(peaks: list[Peak], freqs: dict[str, float]) -> str:
    """The seed's claim A < superharmonic next to the harmonic < B < harmonic < C, checked."""
    harmonic = peaks[0].beta
    supers = [p.beta for p in peaks[1:]]
    if not supers:
        return "no superharmonic peak found"
    nearest = max(supers)
    holds = freqs["A"] < nearest < freqs["B"] < harmonic < freqs["C"]
    return (f"A={freqs['A']} < superharmonic={nearest:.3f} < B={freqs['B']} < harmonic={harmonic:.3f}"
            f" < C={freqs['C']}: {'holds' if holds else 'DOES NOT HOLD'}")


def fig06_frf(rep: Report, grids: Grids) -> dict[float, str]:
    fig = Figure(figsize=(11, 5.2), layout="constrained")
    rows, checks = [], {}
    for j, n in enumerate(SHAPE_FACTORS):
        fr, rk4 = _frf(grids.fig6_betas, GAMMA0_FIG6, n)
        peaks = find_peaks(fr)
        rows += [(n, b, G, f, c, r) for b, G, f, c, r in
                 zip(fr.beta, fr.G, rk4, fr.converged, fr.gross_rolling)]
        ax = fig.add_subplot(1, 2, j + 1)
        ax.plot(fr.beta, fr.G, color=COLOURS[n], label=f"n = {n}, γ0 = {GAMMA0_FIG6}")
        if rk4.any():
            ax.plot(fr.beta[rk4], fr.G[rk4], ".", color="k", ms=3, label="point from RK4 (fallback)")
        for p in peaks:
            marker = "v" if p.kind == "harmonic" else "^"
            ax.plot(p.beta, p.G, marker, color="k", ms=8, mfc="none",
                    label=f"{p.kind}: β = {p.beta:.3f}, G = {p.G:.3f}")
            rep.key("fig06_frf.png", "Fig. 6", n, GAMMA0_FIG6, f"{p.kind} peak", p.beta, p.G)
        for letter, b in SEED_FREQUENCIES[n].items():
            ax.axvline(b, color="grey", ls="--", lw=0.8)
            ax.text(b, 0.98, f" {letter}", transform=ax.get_xaxis_transform(), color="grey", va="top")
            rep.key("fig06_frf.png", "Fig. 6", n, GAMMA0_FIG6, f"seed frequency {letter}", b,
                    float(np.interp(b, fr.beta, fr.G)))
        checks[n] = _ordering(peaks, SEED_FREQUENCIES[n])
        _axes_frf(ax, f"Seed Fig. 6({'ab'[j]}): FRF, n = {n}, γ0 = {GAMMA0_FIG6}")
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2)
    rep.table("fig06_frf", ["n [-]", "beta [-]", "G [-]", "rk4_fallback [0/1]", "converged [0/1]",
                            "gross_rolling [0/1]"], rows)
    rep.figure(fig, "fig06_frf", "Fig. 6", f"G(beta) at gamma0 = {GAMMA0_FIG6}, peaks and frequencies A, B, C")
    return checks


# --- Seed Figs. 7-11: steady cycles at A, B, C ------------------------------------------------

def steady_cycles() -> dict[tuple[float, str], Cycle]:
    """Steady responses at the seed's frequencies A, B, C for both n (RK4, as the seed)."""
    cycles = {}
    for n in SHAPE_FACTORS:
        for letter, beta in SEED_FREQUENCIES[n].items():
            s = steady_state(GAMMA0_FIG6, beta, n, history_samples=HISTORY_SAMPLES)
            if not s.converged:
                log.warning("cycle at %s (n=%g, beta=%g) is not steady", letter, n, beta)
            assert s.history is not None          # asked for with history_samples
            cycles[n, letter] = Cycle(n, letter, s, cycle_features(s.history))
    return cycles


def _feature_text(c: Cycle) -> str:
    f = c.features
    return (f"VOAD: {'yes' if f.voad else 'no'} ({f.acceleration_sign_changes} sign changes of u'')\n"
            f"VRAR: {'yes' if f.vrar else 'no'} ({f.vrar_count} speed dips)\n"
            f"spike index {f.spike_index:.2f}, circularity {f.circularity:.3f}\n"
            f"G = {c.steady.G:.3f}")


def fig07_09_phase_plane(rep: Report, cycles: dict, letter: str):
    seed_fig = {"A": "Fig. 7", "B": "Fig. 8", "C": "Fig. 9"}[letter]
    stem = f"fig{int(seed_fig[-1]):02d}_phase_plane_{letter}"
    fig = Figure(figsize=(11, 5), layout="constrained")
    rows = []
    for j, n in enumerate(SHAPE_FACTORS):
        c = cycles[n, letter]
        h = c.steady.history
        rows += [(n, c.steady.beta, *r) for r in zip(h.tau, h.u, h.du, h.ddu, h.F)]
        ax = fig.add_subplot(1, 2, j + 1)
        ax.plot(h.u, h.du, color=COLOURS[n], label=f"steady cycle, n = {n}, β = {c.steady.beta}")
        ax.plot(h.u[0], h.du[0], "k.", label="τ = 0 (mod 2π)")
        ax.text(0.02, 0.98, _feature_text(c), transform=ax.transAxes, va="top", fontsize=8,
                bbox=dict(boxstyle="round", fc="white", alpha=0.8))
        vmax = float(np.abs(h.du).max())
        ax.set_ylim(-1.2 * vmax, 1.75 * vmax)           # headroom for the feature box
        ax.set_xlabel(r"displacement $u = x/x_s$ [-]")
        ax.set_ylabel(r"velocity $u' = du/d\tau$ [-]")
        ax.set_title(f"Seed {seed_fig}({'ab'[j]}): phase plane at {letter}, n = {n}, β = {c.steady.beta}")
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
        f = c.features
        rep.key(f"{stem}.png", seed_fig, n, GAMMA0_FIG6,
                f"cycle {letter}: VOAD={f.voad} VRAR={f.vrar} spike={f.spike_index:.3g} "
                f"circularity={f.circularity:.3g}", c.steady.beta, c.steady.G)
    rep.table(stem, ["n [-]", "beta [-]", "tau [-]", "u [-]", "du_dtau [-]", "d2u_dtau2 [-]", "F_over_Fs [-]"], rows)
    rep.figure(fig, stem, seed_fig, f"phase plane u' vs u of the steady cycle at {letter}, VOAD/VRAR annotated")


def _two_periods(c: Cycle):
    """Integrate two more periods from the steady state and record them."""
    it = Integrator(n=c.n)
    every = max(1, it.steps_per_period // HISTORY_SAMPLES)
    rec = np.empty((2 * it.steps_per_period // every + 1, 5))
    state = c.steady.state
    assert state is not None                  # steady_state returns its final state
    it.run(state.copy(), GAMMA0_FIG6, c.steady.beta, 2, every, rec)
    return rec


def fig10_11_time_history(rep: Report, cycles: dict, letter: str):
    seed_fig = {"A": "Fig. 10", "B": "Fig. 11"}[letter]
    stem = f"fig{int(seed_fig[-2:]):02d}_time_history_{letter}"
    fig = Figure(figsize=(11, 8), layout="constrained")
    labels = (r"$u''$", r"$u'$", r"$u$", r"$F/F_s$")
    rows = []
    axes = fig.subplots(4, 2, sharex=True)
    for j, n in enumerate(SHAPE_FACTORS):
        c = cycles[n, letter]
        rec = _two_periods(c)
        tau, u, du, ddu, F = rec.T
        rows += [(n, c.steady.beta, *r) for r in zip(tau, ddu, du, u, F)]
        for i, (y, lab) in enumerate(zip((ddu, du, u, F), labels)):
            ax = axes[i, j]
            ax.plot(tau / (2 * math.pi), y, color=COLOURS[n])
            ax.axhline(0, color="grey", lw=0.6)
            ax.set_ylabel(f"{lab} [-]")
            ax.grid(alpha=0.3)
        axes[3, j].plot(tau / (2 * math.pi), GAMMA0_FIG6 * np.sin(tau), "k--", lw=0.8,
                        label=r"excitation $\gamma_0 \sin\tau$")
        axes[3, j].legend(loc="lower right", fontsize=8)
        axes[3, j].set_xlabel(r"time $\tau/2\pi$ [periods]")
        axes[0, j].set_title(f"Seed {seed_fig}({'ab'[j]}): frequency {letter}, n = {n}, β = {c.steady.beta}\n"
                             f"VOAD {'yes' if c.features.voad else 'no'}, "
                             f"VRAR {'yes' if c.features.vrar else 'no'}", fontsize=10)
    rep.table(stem, ["n [-]", "beta [-]", "tau [-]", "d2u_dtau2 [-]", "du_dtau [-]", "u [-]", "F_over_Fs [-]"], rows)
    rep.figure(fig, stem, seed_fig, f"u'', u', u, F/F_s over two steady periods at {letter}")


# --- Seed Fig. 12: FRFs at several force amplitudes ------------------------------------------

def fig12_frf_levels(rep: Report, grids: Grids):
    fig = Figure(figsize=(11, 4.5), layout="constrained")
    rows = []
    for j, n in enumerate(SHAPE_FACTORS):
        ax = fig.add_subplot(1, 2, j + 1)
        for gamma0 in grids.fig12_gamma0:
            fr, rk4 = _frf(grids.fig12_betas, gamma0, n)
            rows += [(n, gamma0, b, G, f) for b, G, f in zip(fr.beta, fr.G, rk4)]
            p = find_peaks(fr)[0]
            line, = ax.plot(fr.beta, fr.G, label=f"γ0 = {gamma0}")
            ax.plot(p.beta, p.G, "v", color=line.get_color(), mfc="none")
            rep.key("fig12_frf_levels.png", "Fig. 12", n, gamma0, "harmonic peak", p.beta, p.G)
        _axes_frf(ax, f"Seed Fig. 12({'ab'[j]}): FRF for several γ0, n = {n}")
        ax.legend(fontsize=8, title="▽ harmonic peak", title_fontsize=8)
    rep.table("fig12_frf_levels", ["n [-]", "gamma0 [-]", "beta [-]", "G [-]", "rk4_fallback [0/1]"], rows)
    rep.figure(fig, "fig12_frf_levels", "Fig. 12", "G(beta) for several force amplitudes gamma0")


# --- Seed Fig. 13: harmonic resonance versus force amplitude --------------------------------

def harmonic_peak(gamma0: float, n: float, grids: Grids) -> tuple[Peak, bool]:
    """Harmonic peak: coarse grid, then a fine grid between the coarse maximum's neighbours.

    Returns the peak and whether the coarse maximum sat on the grid's edge (then the true
    peak may lie outside the grid).
    """
    fr, _ = _frf(grids.fig13_betas, gamma0, n)
    i = int(np.argmax(fr.G))
    edge = i in (0, fr.beta.size - 1)
    if edge:
        log.warning("harmonic peak at the grid edge (beta=%g) for n=%g gamma0=%g", fr.beta[i], n, gamma0)
        return find_peaks(fr)[0], True
    zoom, _ = _frf(np.linspace(fr.beta[i - 1], fr.beta[i + 1], grids.fig13_zoom_points), gamma0, n)
    return find_peaks(zoom)[0], False


def fig13_resonance_vs_force(rep: Report, grids: Grids):
    fig = Figure(figsize=(11, 4.5), layout="constrained")
    ax_b, ax_G = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    rows = []
    for n in SHAPE_FACTORS:
        res = [(g0, *harmonic_peak(g0, n, grids)) for g0 in grids.fig13_gamma0]
        g0s = [r[0] for r in res]
        ax_b.plot(g0s, [r[1].beta for r in res], "o-", color=COLOURS[n], label=f"n = {n}")
        ax_G.plot(g0s, [r[1].G for r in res], "o-", color=COLOURS[n], label=f"n = {n}")
        for g0, p, edge in res:
            rows.append((n, g0, p.beta, p.G, edge))
            rep.key("fig13_resonance_vs_force.png", "Fig. 13", n, g0,
                    "harmonic peak" + (" (AT GRID EDGE)" if edge else ""), p.beta, p.G)
    ax_b.set_ylabel(r"harmonic resonance frequency $\beta_h$ [-]")
    ax_b.set_title("Seed Fig. 13(a): harmonic resonance frequency")
    ax_G.set_ylabel(r"compliance at harmonic resonance $G_h$ [-]")
    ax_G.set_title("Seed Fig. 13(b): compliance at harmonic resonance")
    for ax in (ax_b, ax_G):
        ax.set_xlabel(r"force amplitude $\gamma_0 = P_0/F_s$ [-]")
        ax.grid(alpha=0.3)
        ax.legend()
    rep.table("fig13_resonance_vs_force", ["n [-]", "gamma0 [-]", "beta_h [-]", "G_h [-]", "peak_at_grid_edge [0/1]"],
              rows)
    rep.figure(fig, "fig13_resonance_vs_force", "Fig. 13", "harmonic resonance beta_h and G_h versus gamma0")


# --- Seed Figs. 15-17: feed and pitching modes' resonances against force --------------------

# The pitching rig of bench/defaults/sim_rig_pitch.toml ([rig.model]): carriage and column
# 10 kg, J 0.3 kg m^2 about the guideway, k_th 3e5 N m/rad, h 0.2 m, e 0.1 m; ideal force
# (the seed's FRFs are per measured force) and no sensor noise.
PITCH_MODEL = dict(F_s_N=10.0, x_s_m=10e-6, n=1.5, mass_kg=10.0, friction_alpha=0.5,
                   friction_v_ref_m_per_s=5e-3, pitch_inertia_kg_m2=0.3,
                   pitch_stiffness_N_m_per_rad=3e5, pitch_damping_N_m_s_per_rad=10.0,
                   drive_height_m=0.2, cg_height_m=0.1,
                   force_noise_N=0.0, accel_noise_m_s2=0.0, disp_noise_m=0.0)
PITCH_DAMPING_POINTS, PITCH_DAMPING_SPAN = 13, 0.08   # the damping fit's sweep: +-8 % of the pitch resonance


def pitch_damping(model, level_N: float, f_r: float):
    """The pitching mode's damping ratio at ``level_N`` (sim.modal's single-mode fit to the
    accelerance of the rig model's steady states at PITCH_DAMPING_POINTS over
    f_r (1 +- PITCH_DAMPING_SPAN), :mod:`sim.rig_response`)."""
    from .modal import estimate_mode
    from .rig_response import plant_response
    f = np.linspace(f_r * (1 - PITCH_DAMPING_SPAN), f_r * (1 + PITCH_DAMPING_SPAN), PITCH_DAMPING_POINTS)
    A = plant_response(model, level_N, f).accelerance
    return estimate_mode(f, A, mode="pitch", kind="accelerance", level_N=level_N, guess_zeta=0.02)


def pitch_resonances(model, level_N: float, freqs_Hz):
    """(feed, pitch) resonance frequencies (Hz; NaN when not observed) and the sweep's
    compliance_pp, by the measurement's definitions (decision records 0043, 0054): the feed
    mode is the peak of compliance_pp (seed Eq. 9) below 0.8 x the pitching mode's
    friction-free frequency, the pitching mode the peak of the drive point's |A1/F1| above it; each found
    on the rig model's steady states (:mod:`sim.rig_response`) and refined by golden-section
    search."""
    from .rig_response import line_model, mode_split_Hz, plant_response, resonance_Hz
    m = line_model(model)
    resp = plant_response(m, level_N, freqs_Hz)
    split = mode_split_Hz(m)
    feed = resonance_Hz(resp, m, "compliance_pp", below_Hz=split)[0]
    pitch = resonance_Hz(resp, m, "accelerance", above_Hz=split)[0] if math.isfinite(split) else math.nan
    return feed, pitch, resp.compliance_pp


HZ_TICKS = (10.0, 20.0, 30.0, 50.0, 100.0, 200.0, 300.0, 500.0, 1000.0)
FORCE_TICKS = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)


def _log_ticks(ax, lo: float, hi: float, candidates=HZ_TICKS) -> None:
    """Plain-number x ticks (``candidates`` inside [lo, hi]) on a log axis, minor ticks
    unlabelled: left to itself, a log axis spanning about a decade or less labels its minor
    ticks too ("3x10^1", "4x10^1", ...), which then overlap (issue 32 item 4)."""
    from matplotlib.ticker import NullFormatter
    ticks = [t for t in candidates if lo * (1 - 1e-9) <= t <= hi * (1 + 1e-9)]
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
    ax.xaxis.set_minor_formatter(NullFormatter())


def _other_rig(rep: Report, grids: Grids, freqs, name: str, model: RigModel, colour, ax_feed, ax_pitch,
               ax_z) -> None:
    """A further rig's model (``bench paper --rig A --rig B``): its modes against force in
    its own colour and name, and its own peaks' CSV."""
    rows, damping = [], []
    for level in grids.pitch_levels_N:
        feed, pitch, _ = pitch_resonances(model, level, freqs)
        rows.append((level, feed, pitch))
        if math.isfinite(pitch):
            est = pitch_damping(model, level, pitch)
            damping.append((level, est.damping_ratio))
    levels = [r[0] for r in rows]
    ax_feed.semilogx(levels, [r[1] for r in rows], "o--", color=colour, label=f"rig model {name}: feed")
    ax_pitch.semilogx(levels, [r[2] for r in rows], "s--", color=colour, label=f"rig model {name}: pitch")
    if damping:
        ax_z.plot([d[0] for d in damping], [100 * d[1] for d in damping], "s--", color=colour,
                  label=f"rig model {name}")
    stem = "fig15_17_pitch_resonance_peaks_" + "".join(c if c.isalnum() else "_" for c in name)
    rep.table(stem, ["force [N]", "feed_resonance [Hz]", "pitch_resonance [Hz]"], rows)


def fig15_17_pitch_resonance(rep: Report, grids: Grids, pitch_model: RigModel | None = None,
                             measured: list[dict] | None = None, others: list[tuple[str, RigModel]] | None = None,
                             name: str = ""):
    """Seed Figs. 15 and 17 from the pitching rig's model (``pitch_model``: a rig file's
    [rig.model], default PITCH_MODEL; ``name``: its name on the figure), with a damping
    panel; ``others``: further rigs' (name, [rig.model]), each drawn in the colour of the
    measured run of its position (:func:`_other_rig`); ``measured``: rows of `bench modes`
    (label, mode, level_N, status, resonance_Hz, ..._low/_high, damping_ratio,
    ..._low/_high) drawn over the model's."""
    from .rig import RigModel
    model = pitch_model or RigModel.from_dict(PITCH_MODEL)
    freqs = grids.pitch_freqs_Hz if grids.pitch_freqs_Hz is not None else np.geomspace(40.0, 300.0, 24)
    f_s = model.omega_s / (2 * math.pi)
    fig = Figure(figsize=(18, 4.8), layout="constrained")
    ax_G, ax_feed, ax_pitch, ax_z = (fig.add_subplot(1, 4, i) for i in (1, 2, 3, 4))
    rows, curves, damping = [], [], []
    for level in grids.pitch_levels_N:
        feed, pitch, G = pitch_resonances(model, level, freqs)
        rows.append((level, feed, pitch))
        if math.isfinite(pitch):
            est = pitch_damping(model, level, pitch)
            damping.append((level, est.damping_ratio, est.damping_ratio_low, est.damping_ratio_high))
        curves += [(level, f, g) for f, g in zip(freqs, G)]
        ax_G.loglog(freqs, G, label=f"{level:g} N")
        for item, f_r in (("feed mode resonance", feed), ("pitching mode resonance", pitch)):
            if math.isfinite(f_r):
                G_r = float(np.interp(f_r, freqs, G))
                rep.key("fig15_17_pitch_resonance.png", "Figs. 15-17", model.n, level / model.F_s_N, item,
                        f_r / f_s, G_r * model.F_s_N / model.x_s_m)
    levels = np.array([r[0] for r in rows])
    # several rigs: each rig's model in the colour of the run of its position (rig k, run k)
    colours = [f"C{(k + 2) % 10}" for k in range(1 + len(others or []))] if others else ["tab:blue", "tab:orange"]
    named = f" {name}" if name else ""
    ax_feed.semilogx(levels, [r[1] for r in rows], "o-", color=colours[0],
                     label=f"feed mode: peak of compliance_pp (rig model{named})")
    ax_pitch.semilogx(levels, [r[2] for r in rows], "s-", color=colours[-1] if not others else colours[0],
                      label=f"pitching mode: peak of |A1/F1| (rig model{named})")
    for j, (other, md) in enumerate(others or [], start=1):
        _other_rig(rep, grids, freqs, other, md, colours[j], ax_feed, ax_pitch, ax_z)
    from .plant_effects import mass_matrix
    k0 = SakaiCurve(model.n).stiffness0 * model.F_s_N / model.x_s_m
    for k, text, ls in ((0.0, "no friction stiffness", "--"), (k0, "initial friction stiffness", ":")):
        w2 = np.sort(np.linalg.eigvals(np.linalg.solve(mass_matrix(model),
                                                       np.diag([k, model.pitch_stiffness_N_m_per_rad]))).real)
        f_lin = np.sqrt(np.maximum(w2, 0.0)) / (2 * math.pi)
        if k > 0:
            ax_feed.axhline(f_lin[0], color="grey", ls=ls, lw=0.9, label=f"linear 2-DOF, {text}")
        ax_pitch.axhline(f_lin[1], color="grey", ls=ls, lw=0.9, label=f"linear 2-DOF, {text}")
    _log_ticks(ax_G, float(np.min(freqs)), float(np.max(freqs)))
    ax_G.set_xlabel("frequency [Hz]")
    ax_G.set_ylabel("feed compliance_pp (seed Eq. 9) [m/N]")
    ax_G.set_title("Seed Fig. 15: FRF of the pitching rig per force")
    ax_G.grid(alpha=0.3, which="both")
    ax_G.legend(fontsize=8, title="force amplitude", title_fontsize=8)
    for ax, name in ((ax_feed, "feed"), (ax_pitch, "pitching")):
        ax.set_xlabel("force amplitude [N]")
        ax.set_ylabel(f"{name} mode resonance frequency [Hz]")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    ax_feed.set_xlim(ax_pitch.get_xlim())
    gone = [r[0] for r in rows if not math.isfinite(r[1])]
    if gone:
        ax_feed.text(0.97, 0.5, "no feed peak at\n" + ", ".join(f"{g:g} N" for g in gone), ha="right",
                     transform=ax_feed.transAxes, fontsize=8, color="grey")
    ax_feed.set_title("Seed Fig. 15 (feed mode): falls, then is gone")
    ax_pitch.set_title("Seed Fig. 17: pitching mode falls with force")
    if damping:
        d = np.array(damping, dtype=float)
        err = np.nan_to_num(np.clip(np.vstack([d[:, 1] - d[:, 2], d[:, 3] - d[:, 1]]), 0, None))
        ax_z.errorbar(d[:, 0], 100 * d[:, 1], yerr=100 * err, fmt="s-", color="tab:orange" if not others
                      else colours[0], capsize=3, label=f"pitching mode (rig model{named}, single-mode fit)")
    for k, m in enumerate(measured or []):
        _overlay(ax_feed, ax_pitch, ax_z, m, f"C{(k + 2) % 10}")
    ax_z.set_xscale("log")
    for ax in (ax_feed, ax_pitch, ax_z):
        _log_ticks(ax, float(levels.min()), float(levels.max()), FORCE_TICKS)
    ax_z.set_xlabel("force amplitude [N]")
    ax_z.set_ylabel("pitching mode damping ratio [%]")
    ax_z.set_title("Seed Fig. 17: pitching mode damping ratio")
    ax_z.grid(alpha=0.3, which="both")
    ax_z.legend(fontsize=8)
    if measured:
        for ax in (ax_feed, ax_pitch):
            ax.legend(fontsize=8)
    rep.table("fig17_pitch_damping", ["force [N]", "damping_ratio [-]", "low [-]", "high [-]"], damping)
    rep.table("fig15_17_pitch_resonance", ["force [N]", "freq [Hz]", "compliance_pp [m/N]"], curves)
    # NaN: the mode shows no peak at that force (the feed mode above F_s, as in the seed)
    rep.table("fig15_17_pitch_resonance_peaks", ["force [N]", "feed_resonance [Hz]", "pitch_resonance [Hz]"], rows)
    rep.figure(fig, "fig15_17_pitch_resonance", "Figs. 15 and 17",
               "feed and pitching modes' resonance frequencies against force (pitching rig model; the seed's "
               "Fig. 16, the mode shapes, has no counterpart here); measured modes with damping ratios: "
               "`bench modes RUN ... --out DIR`")
    return rows


def _overlay(ax_feed, ax_pitch, ax_z, run: dict, colour) -> None:
    """One run's measured modes (`bench modes` rows of one label) over the model's."""
    for mode, ax in (("feed", ax_feed), ("pitch", ax_pitch)):
        rs = [r for r in run["rows"] if r["mode"] == mode and r["status"] == "ok"]
        if not rs:
            continue
        F = [r["level_N"] for r in rs]
        v = np.array([r["resonance_Hz"] for r in rs])
        err = np.abs(np.array([[r["resonance_low_Hz"] for r in rs], [r["resonance_high_Hz"] for r in rs]]) - v)
        ax.errorbar(F, v, yerr=err, fmt="o", color=colour, mfc="none", capsize=3, label=f"measured: {run['label']}")
        if mode == "pitch":
            z = np.array([r["damping_fit_fraction"] for r in rs])        # modes.csv (decision 0056)
            zerr = np.abs(np.array([[r["damping_fit_low_fraction"] for r in rs],
                                    [r["damping_fit_high_fraction"] for r in rs]]) - z)
            ax_z.errorbar(F, 100 * z, yerr=100 * zerr, fmt="o", color=colour, mfc="none", capsize=3,
                          label=f"measured: {run['label']}")


# --- Index ------------------------------------------------------------------------------------

def write_index(rep: Report, checks: dict[float, str], quick: bool, seconds: float):
    summary = rep.out_dir / "summary.csv"
    with summary.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["file", "seed_figure", "n [-]", "gamma0 [-]", "item", "beta [-]", "G [-]"])
        for file, fig, n, g0, item, beta, G in rep.rows:
            w.writerow([file, fig, n, g0, item, f"{beta:.6g}", f"{G:.6g}"])
    lines = [
        "# Seed figures reproduced from the model",
        "",
        f"Written by `sim.paper.reproduce` ({'quick, coarse grids' if quick else 'full grids'}; "
        f"{seconds:.1f} s). All quantities dimensionless: u = x/x_s, F/F_s, beta = omega/omega_s, "
        "G = u_0/gamma0. FRFs by half-period shooting (RK4 where it falls back); cycles by RK4 "
        "with 10000 steps per period, as the seed. Figs. 15-17 are in Hz and N, from the steady states "
        "of the simulated pitching rig's model (sim.rig_response; beta = f/f_s and G = compliance_pp F_s/x_s in the "
        "key numbers). Each PNG has a CSV of the same name.",
        "",
        "| file | seed figure | content |",
        "|---|---|---|",
        *[f"| {png} | {fig} | {what} |" for png, fig, what in rep.figures],
        "",
        "## Ordering of the frequencies A, B, C against the peaks (seed section 3.1)",
        "",
        *[f"- n = {n}: {text}" for n, text in checks.items()],
        "",
        "## Key numbers",
        "",
        "| file | seed figure | n | gamma0 | item | beta | G |",
        "|---|---|---|---|---|---|---|",
        *[f"| {f} | {s} | {n} | {g0} | {item} | {beta:.4g} | {G:.4g} |"
          for f, s, n, g0, item, beta, G in rep.rows],
        "",
    ]
    readme = rep.out_dir / "README.md"
    readme.write_text("\n".join(lines))
    rep.files += [readme, summary]


def reproduce(out_dir: Path, *, quick: bool = False, progress=None, pitch_model: RigModel | None = None,
              measured: list[dict] | None = None, pitch_name: str = "",
              other_models: list[tuple[str, RigModel]] | None = None) -> list[Path]:
    """Write the seed's numerical figures (PNG + CSV each) and an index into ``out_dir``.

    ``quick`` uses coarse grids (seconds instead of minutes). ``progress(done, total,
    label)`` is called after each figure. ``pitch_model``: a rig's [rig.model] for Figs. 15
    and 17 (default PITCH_MODEL), named ``pitch_name``; ``other_models``: further rigs'
    (name, [rig.model]) drawn beside it, rig k in the colour of run k; ``measured``: runs'
    modes to overlay there (``[{"label": ..., "rows": [bench modes rows]}]``). Returns the
    paths written.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    grids = Grids.for_run(quick)
    rep = Report(out_dir)
    start = time.perf_counter()
    cycles: dict = {}
    checks: dict = {}
    steps = [
        ("fig03_masing_hysteresis", lambda: fig03_masing_hysteresis(rep, grids)),
        ("fig04_virgin_curves", lambda: fig04_virgin_curves(rep, grids)),
        ("fig06_frf", lambda: checks.update(fig06_frf(rep, grids))),
        ("fig07_phase_plane_A", lambda: (cycles.update(steady_cycles()), fig07_09_phase_plane(rep, cycles, "A"))),
        ("fig08_phase_plane_B", lambda: fig07_09_phase_plane(rep, cycles, "B")),
        ("fig09_phase_plane_C", lambda: fig07_09_phase_plane(rep, cycles, "C")),
        ("fig10_time_history_A", lambda: fig10_11_time_history(rep, cycles, "A")),
        ("fig11_time_history_B", lambda: fig10_11_time_history(rep, cycles, "B")),
        ("fig12_frf_levels", lambda: fig12_frf_levels(rep, grids)),
        ("fig13_resonance_vs_force", lambda: fig13_resonance_vs_force(rep, grids)),
        ("fig15_17_pitch_resonance", lambda: fig15_17_pitch_resonance(rep, grids, pitch_model, measured,
                                                                      other_models, pitch_name)),
    ]
    for done, (label, step) in enumerate(steps, start=1):
        t = time.perf_counter()
        step()
        log.info("%s written in %.1f s", label, time.perf_counter() - t)
        if progress:
            progress(done, len(steps), label)
    write_index(rep, checks, quick, time.perf_counter() - start)
    return rep.files
