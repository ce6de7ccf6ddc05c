"""The words of the artefact check: channel names and units, sizes with SI prefixes, the
mains frequencies and the formulas ``analysis.json`` names (:mod:`sim.artefacts`)."""

from __future__ import annotations

import math

LABEL = {"force": "force sensor", "accel": "accelerometer", "disp": "displacement probe"}
UNIT = {"force": "N", "accel": "m/s^2", "disp": "m"}


def si(value: float, unit: str) -> str:
    """'12 nm', '3.1 mN', '0.25 m/s^2': a size in the channel's unit with an SI prefix."""
    if not math.isfinite(value):
        return f"{value} {unit}"
    if unit in ("m", "N"):
        for scale, p in ((1.0, ""), (1e-3, "m"), (1e-6, "u"), (1e-9, "n"), (1e-12, "p")):
            if abs(value) >= scale or scale == 1e-12:
                return f"{value / scale:.3g} {p}{unit}"
    return f"{value:.3g} {unit}"


MAINS_HZ = (50.0, 60.0)
LABELS = {"line_interference": "interference line", "unsettled_transient": "unsettled transient",
          "clipping": "clipping", "dropout": "drop-outs", "offset_drift": "offset drift"}
FORMULAS = {"line_interference": "y_measured = y + a sin(2 pi f_l t + phi), f_l not a multiple of the drive",
            "unsettled_transient": "y_measured = y_periodic + A_0 exp(-sigma t) sin(2 pi f_t t + phi) at the record start",
            "clipping": "y_measured = clip(y, low, high)",
            "dropout": "y_measured = y(t_0) held (or 0) for a time",
            "offset_drift": "y_measured = y + b t + c t^2"}


def mains_line(freq_Hz: float) -> tuple[float, int] | None:
    """(mains frequency, harmonic) when the frequency is a harmonic 1-10 of 50 or 60 Hz
    (within 0.5 %), else None."""
    for base in MAINS_HZ:
        m = round(freq_Hz / base)
        if 1 <= m <= 10 and abs(freq_Hz / (m * base) - 1) < 0.005:
            return base, m
    return None


def mains_family(base_Hz: float) -> str:
    """'50 Hz mains': the words of a mains frequency."""
    return f"{base_Hz:g} Hz mains"


def mains(freq_Hz: float) -> str:
    """'50 Hz mains (harmonic 3)' when :func:`mains_line` finds the frequency a mains
    harmonic, else '' (the words; decisions use :func:`mains_line`)."""
    line = mains_line(freq_Hz)
    if line is None:
        return ""
    base, m = line
    return mains_family(base) + (f" (harmonic {m})" if m > 1 else "")


def not_periodic(channel: str, what: str, score: float, limit: float) -> str:
    """Why the periodicity gate rejected a step: ``what`` (the offset or a harmonic) of
    ``channel`` changed by ``score`` standard errors between the halves of the record."""
    return (f"not periodic enough on the {LABEL.get(channel, channel)} ({channel}): its {what} changes by "
            f"{score:.0f} standard errors between the two halves of the record (limit {limit:g})")
