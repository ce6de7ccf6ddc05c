"""Each mode's damping ratios with their names (decision record 0056): the energy balance
at resonance from the run's dwell / refined / nearest step, with its stated mass, and the
half-power ratio with the bracket of its measured crossings, beside the single-mode fit's
(sim.modal).  :func:`add_damping` puts them into each estimate's ``extra``."""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Sequence

import numpy as np

from sim.modal import ModeEstimate
from sim.modal_damping import (
    EnergyBalance,
    StepFRF,
    energy_balance,
    half_power_interval,
    pitch_modal_mass_kg,
    ratio_rel_sd,
)

log = logging.getLogger(__name__)

_KIND = {"R": "refined", "W": "dwell"}
_MODE = {"F": "feed", "P": "pitch"}
_KEY = re.compile(r"^\d+-L\d+-([RW])([FP])\d+-")


def step_kind(key: str) -> tuple[str, str | None]:
    """("dwell" | "refined" | "sweep", the mode a dwell / refined step was for)."""
    m = _KEY.match(key or "")
    return (_KIND[m.group(1)], _MODE[m.group(2)]) if m else ("sweep", None)


def _rel_sd(r: dict, ch: str) -> float:
    try:
        return ratio_rel_sd(complex(r[ch]["amplitude"][0]), float(r[ch]["sigma"]),
                            complex(r["force"]["amplitude"][0]), float(r["force"]["sigma"]))
    except (KeyError, IndexError, TypeError, ValueError):
        return 0.0


def step_frf(r: dict, mode: str) -> StepFRF:
    """The step's receptance for ``mode``'s energy balance: the feed mode's is X1/F1
    (the displacement probe), the pitching mode's the drive point's, -(A1/F1) / w^2 (the
    accelerometer at the drive point)."""
    kind, for_mode = step_kind(r["key"])
    if kind != "sweep" and for_mode != mode:
        kind = "sweep"                        # another mode's dwell / refined step is just a point here
    f = float(r["freq_Hz"])
    if mode == "feed":
        H = complex(r["compliance_m_per_N"]["re"], r["compliance_m_per_N"]["im"])
        return StepFRF(r["key"], f, H, _rel_sd(r, "disp"), kind)
    A = r["accelerance_abs_kg_inv"] * np.exp(1j * r["accelerance_phase_rad"])
    return StepFRF(r["key"], f, complex(-A / (2 * math.pi * f) ** 2), _rel_sd(r, "accel"), kind)


def mode_masses(meta: dict):
    """({mode: (mass in kg, what it is)}, the rig model or None) for the energy balance: the
    pitching mode's mass comes from the model at its resonance (:func:`add_damping`)."""
    rig = meta.get("rig") or {}
    model = None
    from procedures.plan import stored_model
    try:
        model = stored_model(rig)
    except Exception as e:  # noqa: BLE001 - the ratios come out without the model's masses
        log.warning("rig model unreadable for the energy balance's masses: %s", e)
    from ..frf_import import energy_mass_kg, origin_of
    if (origin := origin_of(meta)) is not None:     # imported: the mapping's mass, and only beside a measured force
        feed = (energy_mass_kg(origin), "mass_kg of the import's mapping")
    elif model is not None:
        feed = (float(model.mass_kg), "carriage mass (rig model)")
    else:
        feed = (float(rig.get("expected_mass_kg", math.nan)), "carriage mass ([rig.expected] mass_kg)")
    return {"feed": feed, "pitch": (math.nan, "no rig model: the pitching mode's modal mass is unknown")}, model


def add_damping(modes: Sequence[ModeEstimate], results: list[dict], meta: dict,
                levels_N: Sequence[float]) -> None:
    """Fill ``extra["energy_balance"]`` (sim.modal_damping.EnergyBalance or None) and
    ``extra["half_power"]`` ((zeta, low, high)) of every estimate with a resonance."""
    masses, model = mode_masses(meta)
    by_level: dict[float, list[dict]] = {}
    for r in results:
        li = r.get("level_index", 0)
        lv = float(levels_N[li]) if li < len(levels_N) else float(r["target_force_N"])
        by_level.setdefault(lv, []).append(r)
    for e in modes:
        steps = by_level.get(e.level_N, [])
        if not steps or not math.isfinite(e.resonance_Hz):
            continue
        m, note = masses[e.mode]
        if e.mode == "pitch" and model is not None:
            m, note = pitch_modal_mass_kg(model, e.resonance_Hz)
        e.extra["energy_balance"] = energy_balance([step_frf(r, e.mode) for r in steps], e.resonance_Hz,
                                                   e.resonance_low_Hz, e.resonance_high_Hz, m, note)
        if e.ok and math.isfinite(e.peak):
            f = np.array([float(r["freq_Hz"]) for r in steps])
            curve = (np.array([r["compliance_pp_m_per_N"] for r in steps]) if e.mode == "feed"
                     else np.array([r["accelerance_abs_kg_inv"] for r in steps]))
            e.extra["half_power"] = half_power_interval(*_mean_by_f(f, curve), e.resonance_Hz, e.peak)


# modes.csv's damping columns: fractions (not per cent), each definition named
DAMPING_COLUMNS = ("damping_fit_fraction", "damping_fit_low_fraction", "damping_fit_high_fraction",
                   "damping_energy_balance_fraction", "damping_energy_balance_low_fraction",
                   "damping_energy_balance_high_fraction", "energy_balance_mass_kg", "energy_balance_mass",
                   "energy_balance_step", "damping_half_power_fraction", "damping_half_power_low_fraction",
                   "damping_half_power_high_fraction")


def damping_row(e: ModeEstimate) -> dict:
    """modes.csv's DAMPING_COLUMNS of one estimate."""
    nan = math.nan
    if e.phase_resonance:      # a locked point's ratio is the energy balance (decision 0044)
        eb = EnergyBalance(e.damping_ratio, nan, nan, "", "phase resonance", e.resonance_Hz, nan,
                           "the phase-resonance run's mass (backbone.csv)")
        return dict(damping_row_empty(), damping_energy_balance_fraction=eb.value, energy_balance_mass=eb.mass_note)
    eb = e.extra.get("energy_balance")
    # a level whose peak is not located (overdamped/flat, coarse, ...) has no half-power band
    hp = e.extra.get("half_power") or ((e.half_power_damping_ratio, nan, nan) if e.ok else (nan, nan, nan))
    return dict(damping_fit_fraction=e.damping_ratio, damping_fit_low_fraction=e.damping_ratio_low,
                damping_fit_high_fraction=e.damping_ratio_high,
                damping_energy_balance_fraction=eb.value if eb else nan,
                damping_energy_balance_low_fraction=eb.low if eb else nan,
                damping_energy_balance_high_fraction=eb.high if eb else nan,
                energy_balance_mass_kg=eb.mass_kg if eb else nan, energy_balance_mass=eb.mass_note if eb else "",
                energy_balance_step=f"{eb.step_key} ({eb.source}, {eb.f_step_Hz:.6g} Hz)" if eb else "",
                damping_half_power_fraction=hp[0], damping_half_power_low_fraction=hp[1],
                damping_half_power_high_fraction=hp[2])


DAMPING_KINDS = ("fit", "energy_balance", "half_power")
DAMPING_HEADS = {"fit": "single-mode fit", "energy_balance": "energy balance at resonance",
                 "half_power": "half-power"}


def damping_notes(modes: Sequence[ModeEstimate]) -> list[str]:
    """The report's sentences that name each damping ratio's definition and mass."""
    masses = sorted({(e.mode, eb.mass_note, round(eb.mass_kg, 4)) for e in modes
                     if (eb := e.extra.get("energy_balance")) is not None})
    out = ["Damping ratios (per cent; modes.csv holds fractions): **single-mode fit**: the local rational-fraction "
           "fit's zeta; **energy balance at resonance**: |F1| sin(-phase) / (2 m w^2 |X1|) on the dwell step (else "
           "the refined step) nearest the resonance, else a quadratic through the ratios of the 7 sweep steps nearest "
           "it, the definition phase resonance uses; its interval holds the step's noise and its offset from the "
           "resonance (across sweep steps: the curve's standard error and the resonance's interval); **half-power**: (f2 - f1) / (2 f_r) "
           "from the measured points, its interval the bracket of the measured crossings."]
    out += [f"- {mode}: m = {kg:.4g} kg, {note}" for mode, note, kg in masses if math.isfinite(kg)]
    out += [f"- {mode}: no energy balance ({note})" for mode, note, kg in masses if not math.isfinite(kg)]
    return out + [""]


def damping_row_empty() -> dict:
    return {k: ("" if k in ("energy_balance_mass", "energy_balance_step") else math.nan) for k in DAMPING_COLUMNS}


def _mean_by_f(f: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.unique(f)
    return u, np.array([y[f == x].mean() for x in u])
