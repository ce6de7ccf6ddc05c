"""The words of the artefact check (:mod:`sim.artefacts`), made here only (decisions 0059 and
0067): channel names and units, sizes with SI prefixes, the mains frequencies, the formulas
``analysis.json`` names, an artefact's description, a rejection's reason and a step's notes.

They stay in sim/ because they are data, not only output: a step file stores them (``reason``,
``notes``, each artefact's ``text``; docs/run-format.md), written when the step is measured,
and a report of an earlier run reads them as stored.  The decisions read the values
(:class:`~sim.artefacts.quality.Artefact`'s kind and fields, ``StepQuality.rejected_by``);
tests/bench/test_decisions_are_values.py makes every function here say codes only and checks
that they stay the same."""

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


def artefact(a) -> str:
    """The words of one :class:`~sim.artefacts.quality.Artefact` ``a`` (its ``describe``)."""
    where = f"on the {LABEL[a.channel]} ({a.channel})"
    size = si(a.size, UNIT[a.channel])
    if a.kind == "line_interference":
        return f"a {a.freq_Hz:.4g} Hz line of {size} {where}, not locked to the drive ({a.evidence}); removed"
    if a.kind == "unsettled_transient":
        what = f"{a.freq_Hz:.4g} Hz " if math.isfinite(a.freq_Hz) else ""
        done = {"removed": "; removed", "trimmed": "; the first periods were dropped"}.get(a.action, "")
        if not a.decay_per_s > 0:
            advice = (f"settle {'at least' if a.settle_at_least else 'about'} {a.settle_cycles} more cycles"
                      if a.settle_cycles else "settle longer")
            return (f"an unsettled {what}vibration of {size} {where} ({a.evidence}), "
                    f"not decaying measurably within the record: {advice}{done}")
        return (f"an unsettled {what}transient of {size} {where} at the record start, "
                f"decaying at {a.decay_per_s:.3g} /s (time constant {1e3 / a.decay_per_s:.3g} ms; "
                f"{a.evidence}): settle {a.settle_cycles} more cycles{done}")
    if a.kind == "clipping":
        return (f"clipping {where}: flat at {size} for {1e3 * a.duration_s:.3g} ms "
                f"from t = {a.time_s:.4g} s ({a.evidence})")
    if a.kind == "dropout":
        return (f"a drop-out {where}: the value {size} held for {1e3 * a.duration_s:.3g} ms "
                f"from t = {a.time_s:.4g} s ({a.evidence})")
    if a.kind == "offset_drift":
        return f"an offset drift {where} of {size} over the record ({a.evidence}); removed"
    return f"{a.kind} {where}"


def mains_hint(fm_Hz: float, gap_Hz: float, k: int, drive_Hz: float, periods: int, line_Hz: float,
               line_channel: str, periods_needed: int) -> str:
    """Mains at ``fm_Hz`` too close to drive harmonic ``k`` to be separated in ``periods``
    periods: why it is named (a line seen at ``line_Hz`` on ``line_channel``, or, when that
    is '', the gate failed on harmonic ``k``) and the periods needed."""
    why = (f"a {line_Hz:.4g} Hz line was found on the {LABEL[line_channel]}" if line_channel
           else f"harmonic {k} is what changed")
    return (f"mains hum, if present, at {fm_Hz:g} Hz lies {gap_Hz:.2g} Hz from drive harmonic {k} "
            f"({k * drive_Hz:.4g} Hz) and cannot be separated from the response in {periods} periods "
            f"({why}): measure at least {periods_needed} periods")


def same_vibration(decaying: bool, channel: str) -> str:
    """The evidence of a line that is the transient (``decaying``) or the free vibration seen
    on another ``channel`` at its frequency."""
    return f"at the frequency of the {'transient' if decaying else 'free vibration'} on the {LABEL[channel]}"


def periods_dropped(dropped: int, periods: int) -> str:
    """The note of a step whose first periods were dropped for an unsettled transient."""
    return f"first {dropped} of {periods} periods dropped (unsettled transient)"


def noisy(ratio: float, limit: float) -> str:
    """The note of a step whose displacement residual is ``ratio`` of its fundamental (over ``limit``)."""
    return (f"noisy: displacement residual {100 * ratio:.3g} % of the fundamental "
            f"(limit {100 * limit:g} %; used with its noise as weight)")


def still_ringing(a) -> str:
    """A line at the frequency of the vibration the block before showed: that vibration, weaker."""
    return f"{artefact(a)}: at the frequency of the vibration the block before showed, so that vibration, weaker"


# ---------------------------------------------------------------- one channel's evidence (detectors, cleaning)

def clipped_samples(at_level: int, samples: int, runs: int) -> str:
    return f"{at_level} samples ({100 * at_level / samples:.2g} % of the record) flat at the extreme value in {runs} runs"


def one_value() -> str:
    return "the channel holds one value over the whole record"


def held_runs(runs: int, samples: int, longest: int, off: float, noise: float, quantum: float, unit: str,
              log_chance: float, limit_per_run: float, limit_per_record: float) -> str:
    """Drop-outs: ``runs`` runs of identical samples, the first ``off`` from the signal
    against the noise and the quantum, with the natural log of its chance."""
    chance = f"{math.exp(log_chance):.1g}" if log_chance > -700 else f"1e{log_chance / math.log(10):.0f}"
    return (f"{runs} run(s) of identical samples, {samples} samples in all, longest "
            f"{longest}; during the first the signal (periodic fit) was up "
            f"to {si(off, unit)} from the held value, against a noise of {si(noise, unit)} "
            f"and a quantum of {si(quantum, unit)}: a chance of {chance} "
            f"(limit {limit_per_run:.1g} a run, {limit_per_record:g} per record)")


def trend(z: float) -> str:
    return f"linear + quadratic trend {z:.0f} standard errors from zero"


def line_found(snr: float, of_drive: float) -> str:
    return f"{snr:.0f} standard errors, {of_drive:.3f} x the drive frequency"


def decaying_sinusoid(decay_per_s: float, se_per_s: float) -> str:
    return f"a decaying sinusoid fitted, decay rate {decay_per_s:.3g} +- {se_per_s:.2g} /s"


def falling_differences(periods_falling: int, periods: int, z_first: float) -> str:
    return (f"the difference between consecutive periods falls over the first {periods_falling} "
            f"of {periods} periods (first by {z_first:.0f} standard errors above the noise)")


def free_vibration(accel: float, disp: float, freq_Hz: float, ratio: float, phase_deg: float, z_accel: float,
                   z_disp: float, decay_per_s: float, decay_se: float, significant: bool, record_ms: float) -> str:
    """A component both motion sensors see as one motion; its decay rate when fitted (NaN: not)."""
    rate = ""
    if not math.isnan(decay_se):
        rate = (f"; decay rate {decay_per_s:.2g} +- {decay_se:.2g} /s" + ("" if significant else ", not significant")
                + f" in a {record_ms:.3g} ms record")
    return (f"a free vibration of the carriage, not interference: the accelerometer's {si(accel, 'm/s^2')} "
            f"at {freq_Hz:.4g} Hz is -(2 pi f)^2 times the probe's {si(disp, 'm')} (ratio {ratio:.2f}, "
            f"phase {phase_deg:+.0f} deg; {z_accel:.0f} and {z_disp:.0f} standard errors){rate}")


# ---------------------------------------------------------------- whose line it is (attribute_lines' evidence)

def leakage_of_source(evidence: str, line_Hz: float, guard: float, harmonic: int) -> str:
    return (f"{evidence}; leakage of the {line_Hz:.4g} Hz line of the source, which lies within "
            f"{guard:g} record resolutions of drive harmonic {harmonic} here and cannot be "
            f"separated from it: not a source of its own")


def vibration_of_step_before(step: str, freq_Hz: float) -> str:
    return (f"at the frequency of the vibration of the step before ({step}, "
            f"{freq_Hz:.4g} Hz): the rig's own free vibration, not interference")


def near_mode(step: str, freq_Hz: float, others: int) -> str:
    """Near the vibration of ``step`` at ``freq_Hz`` ('' : the measured response's
    resonance) and ``others`` more: the rig's own mode."""
    mode = (f"the {freq_Hz:.4g} Hz vibration of step {step}" if step
            else f"the {freq_Hz:.4g} Hz resonance of the measured response")
    return (f"near {mode}" + (f" and {others} other(s)" if others > 0 else "")
            + ", the rig's own mode: the rig's own free vibration, not interference")


def not_repeated(at_mains: bool, repeat_steps: int) -> str:
    return (f"{'at a mains frequency in too few steps with one amplitude' if at_mains else 'at no mains frequency'}"
            f" and in fewer than {repeat_steps} steps at one frequency, drive frequencies and amplitude: "
            f"the rig's own free vibration, not interference")


def component_of(evidence: str, line_Hz: float) -> str:
    return (f"{evidence}; a component of the {line_Hz:.4g} Hz line of this step "
            f"(leakage or a sideband with the drive), not a source of its own")


def beside_leakage(evidence: str, line_Hz: float) -> str:
    return f"{evidence}; beside the leakage of the {line_Hz:.4g} Hz line of the source (not separable in this step): its own too"


def beside_stronger(line_Hz: float) -> str:
    return f"beside the stronger {line_Hz:.4g} Hz line of this step, which is not interference: the rig's own free vibration"


def advice_from_transients(decay_per_s: float, near: bool) -> str:
    return (f"; settle advice from the decay rate {decay_per_s:.3g} /s of the source's transients"
            + (" near this frequency" if near else ""))


def advice_from_bound(decay_per_s: float) -> str:
    return f"; its decay rate is below {decay_per_s:.3g} /s (fit + 2 standard errors)"


# ---------------------------------------------------------------- the causes of many steps (analysis.json)

def _fate(n: int, rejected: int) -> str:
    """'3 kept, 2 rejected': what became of the ``n`` steps of a cause."""
    return ((f"{n - rejected} kept" if n > rejected else "") + (", " if 0 < rejected < n else "")
            + (f"{rejected} rejected" if rejected else ""))


def line_cause(freq_Hz: float, amplitude: float, channel: str, n: int, total: int, base_Hz: float,
               others: list[tuple[str, float, int]], components: int, component_steps: int) -> str:
    """An interference family: its main line (median frequency and amplitude on ``channel``
    in ``n`` of ``total`` steps), the mains ``base_Hz`` (0: another source), its other lines
    (channel, frequency, steps) and its components (leakage, sidebands)."""
    what = (f"{mains_family(base_Hz)} interference" if base_Hz
            else "interference from another source (a pump, a fan, a switching supply)")
    also = ("; also " + ", ".join((f"{f:g} Hz " if base_Hz else "") + f"on the {LABEL[c]} ({k} steps)"
                                  for c, f, k in others)) if others else ""
    comp = (f"; with {components} component(s) of it that the line and the drive make together (leakage, "
            f"sidebands) in {component_steps} steps, not sources of their own") if components else ""
    return (f"a {freq_Hz:.4g} Hz line of {si(amplitude, UNIT[channel])} on the {LABEL[channel]} in {n} of "
            f"{total} steps, not locked to the drive: {what}{also}{comp}; removed before the fit")


def transient_cause(where: str, freq_Hz: float, time_constants: str, channels: list[str], n: int, total: int,
                    cycles: int, at_least: bool, rejected: int) -> str:
    """Steps still vibrating at the record start: where, the vibration's median frequency
    (NaN: not known), its time constants ('' when none decays), the advice."""
    vib = (f"the rig's own unsettled free vibration near {freq_Hz:.3g} Hz" if math.isfinite(freq_Hz)
           else "the rig's own unsettled free vibration")
    const = f", time constant {time_constants}" if time_constants else ""
    advice = f"settle {'at least ' if at_least else ''}{cycles} more cycles" if cycles else "settle longer"
    return (f"steps {where} still vibrating at the record start ({vib}{const}, on the "
            f"{' and '.join(LABEL[c] for c in channels)}) in {n} of {total} steps: {advice}; "
            f"{_fate(n, rejected)} (transient removed or first periods dropped where the record allowed)")


def clipping_cause(channel: str, n: int, total: int, where: str, level: float, rejected: int) -> str:
    return (f"clipping on the {LABEL[channel]} in {n} of {total} steps ({where}): flat at "
            f"{si(level, UNIT[channel])}, the range of the sensor or its input; {_fate(n, rejected)}: use a larger "
            f"range or a lower level")


def dropout_cause(channel: str, n: int, total: int, where: str, longest_s: float, rejected: int) -> str:
    return (f"drop-outs on the {LABEL[channel]} in {n} of {total} steps ({where}): the signal held for up to "
            f"{1e3 * longest_s:.3g} ms; {_fate(n, rejected)}: check the cable, connector and acquisition")


def drift_cause(channel: str, n: int, total: int, change: float) -> str:
    return (f"an offset drift on the {LABEL[channel]} in {n} of {total} steps, up to {si(change, UNIT[channel])} "
            f"over a record (thermal drift of the sensor, or the carriage creeping); removed before the fit")
