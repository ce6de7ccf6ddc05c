"""The analysis in the technician's terms: what the data show, beside the model's parameters.

A fitted second mode's f_p = sqrt(k_th/J) / 2 pi is a parameter inside the model; what a
technician sees on the measured accelerance |A1/P1| is a dip (the anti-resonance) and a
peak above it (the resonance), both moved away from f_p by the coupling to the carriage's
feed motion.  :func:`accelerance_pair` finds them in the data.  Velocity-dependent friction
is identifiable only as alpha/v_ref: :func:`speed_friction` states it at the speed the rig
file names (``friction_v_ref_m_per_s``), or says which speed it chose.  Every figure is
rounded to what its interval supports (:mod:`.rounding`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .rounding import interval_text, value_text


@dataclass(frozen=True)
class Extremum:
    """A dip or peak of the measured accelerance: the vertex of a parabola through the grid
    point and its two neighbours (log f, log |A|), bracketed by those neighbours."""

    freq_Hz: float
    low_Hz: float             # the grid points either side: the extremum lies between them
    high_Hz: float
    levels: int               # force levels that show it

    def text(self) -> str:
        return bracket_text(self.freq_Hz, self.low_Hz, self.high_Hz)


def bracket_text(freq_Hz: float, low_Hz: float, high_Hz: float) -> str:
    """'180 Hz (grid points 130 to 216 Hz)': rounded to what the bracket supports."""
    return (f"{value_text(freq_Hz, low_Hz, high_Hz, ' Hz')} (grid points "
            f"{value_text(low_Hz, math.nan, math.nan)} to {value_text(high_Hz, math.nan, math.nan, ' Hz')})")


def _vertex(f: np.ndarray, a: np.ndarray, i: int) -> float:
    x, y = np.log(f[i - 1:i + 2]), np.log(a[i - 1:i + 2])
    c2, c1, _ = np.polyfit(x, y, 2)
    if c2 == 0:
        return float(f[i])
    return float(np.exp(np.clip(-c1 / (2 * c2), x[0], x[2])))


def accelerance_pair(freq_Hz, accelerance_abs, level, window_Hz: tuple[float, float]
                     ) -> tuple[Extremum | None, Extremum | None]:
    """(anti-resonance, resonance) of the measured |A1/P1| inside ``window_Hz``: per force
    level, the lowest grid point that is a local minimum below the window's largest value
    above it, and that largest value; the median over the levels that show them.  None
    where no level shows one inside the window (an extremum on the window's edge is not
    one the data resolve)."""
    f_all, a_all, lv_all = (np.asarray(v, float) for v in (freq_Hz, accelerance_abs, level))
    dips, peaks = [], []
    for lv in np.unique(lv_all):
        idx = np.flatnonzero((lv_all == lv) & (f_all >= window_Hz[0]) & (f_all <= window_Hz[1]))
        idx = idx[np.argsort(f_all[idx])]
        f, a = f_all[idx], a_all[idx]
        if f.size < 4:
            continue
        i = int(np.argmin(a))
        if 0 < i < f.size - 1:
            dips.append((_vertex(f, a, i), f[i - 1], f[i + 1]))
            j = i + 1 + int(np.argmax(a[i + 1:]))
            if j < f.size - 1:
                peaks.append((_vertex(f, a, j), f[j - 1], f[j + 1]))

    def combine(found):
        if not found:
            return None
        v = np.array(found)
        return Extremum(float(np.median(v[:, 0])), float(v[:, 1].min()), float(v[:, 2].max()), len(found))
    return combine(dips), combine(peaks)


def second_mode_phrase(p: dict) -> str:
    """The verdict's words for a second (pitching) mode: the measured pair first, then the
    model's parameters (``p``: :meth:`Analysis.cause_parameters` of "second_mode")."""
    def iv(name, scale=1.0, unit=""):
        q = p[name]
        return interval_text(q["value"] * scale, q["low"] * scale, q["high"] * scale, unit)
    seen = []
    for name, what in (("anti_resonance_Hz", "an anti-resonance"), ("resonance_Hz", "a resonance")):
        e = p.get(name)
        if e:
            seen.append(f"{what} at {bracket_text(e['value'], e['low'], e['high'])}")
    data = (f" (the measured accelerance has {' and '.join(seen)})" if seen
            else " (the measured accelerance shows no dip and peak the grid resolves)")
    return (f"a second (pitching) mode{data}; in the model: sqrt(k_th/J)/2 pi = {iv('frequency', unit=' Hz')}, "
            f"damping ratio {iv('damping_ratio', 100, ' %')}, coupling m h^2/J = {iv('coupling')}")


def speed_friction(beta: tuple[float, float, float], v_ref: float) -> dict:
    """alpha = beta v_ref with its interval (only beta = alpha/v_ref is identifiable)."""
    lo, hi = sorted((beta[1] * v_ref, beta[2] * v_ref))
    return dict(value=beta[0] * v_ref, low=lo, high=hi, unit="1")


def speed_friction_phrase(p: dict) -> str:
    """The verdict's words for velocity-dependent friction, at the v_ref of ``p``, naming
    where that speed comes from."""
    a, v = p["alpha"], p["v_ref"]
    where = {"rig": "the rig file's friction_v_ref_m_per_s"}.get(
        v.get("source"), "chosen here: the speed at the friction resonance, 2 pi f_res x_s; the rig file names none")
    return (f"friction rising with speed: {interval_text(100 * a['value'], 100 * a['low'], 100 * a['high'], ' %')} "
            f"higher at v_ref = {value_text(1e3 * v['value'], math.nan, math.nan, ' mm/s')} ({where}; only "
            f"alpha/v_ref is identifiable, so at another speed v it is alpha v/v_ref)")
