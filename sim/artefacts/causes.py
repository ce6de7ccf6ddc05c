"""The artefacts of many steps (:mod:`sim.artefacts`): whose line it is
(:func:`attribute_lines`) and the ``analysis.json`` causes of kind "artefact"
(:func:`artefact_causes`)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .quality import Artefact, StepQuality
from .sentences import FORMULAS, LABEL, LABELS, UNIT, mains, si


def _span(values, unit: str, fmt: str = ".3g") -> str:
    lo, hi = min(values), max(values)
    return f"{lo:{fmt}} {unit}" if f"{lo:{fmt}}" == f"{hi:{fmt}}" else f"{lo:{fmt}}-{hi:{fmt}} {unit}"


def _param(values, unit: str) -> dict:
    v = np.asarray(values, float)
    return dict(value=float(np.median(v)), low=float(v.min()), high=float(v.max()), unit=unit)


def _where(qs: list[StepQuality]) -> str:
    f = [q.freq_Hz for q in qs if math.isfinite(q.freq_Hz)]
    lv = [q.level_N for q in qs if math.isfinite(q.level_N)]
    parts = ([f"at {_span(f, 'Hz')}"] if f else []) + ([_span(lv, "N")] if lv else [])
    return ", ".join(parts)


# ---------------------------------------------------------------------------- many steps: whose line?

REPEAT_STEPS = 3            # a line at one frequency in at least this many steps comes from a steady source
LINE_CLUSTER_REL = 0.002    # ... one frequency: within 0.2 % (at least 0.05 Hz); a mode wanders more with level
MODE_REL = 0.1              # the rig's vibrations within 10 % of a line's frequency are the same mode


def _same_line(f1: float, f2: float) -> bool:
    return abs(f1 - f2) <= max(0.05, LINE_CLUSTER_REL * max(f1, f2))


def _vibration_Hz(a: Artefact) -> bool:
    """An unsettled transient or free vibration with a frequency of its own (the rig's mode)."""
    return a.kind == "unsettled_transient" and math.isfinite(a.freq_Hz)


def attribute_lines(quality: list[tuple[str, StepQuality]],
                    resonances_Hz: tuple[float, ...] = ()) -> list[tuple[str, StepQuality]]:
    """Whose line is it?  The steps of one source in the order they were measured, with
    every ``line_interference`` that is not interference named what it is: the rig's own
    unsettled free vibration (decision record 0045).

    One step cannot tell a weak free vibration seen by one sensor from a hum (decision
    0033); the source can.  A line at a mains frequency (50/60 Hz and harmonics,
    :func:`mains`) is interference: the fundamental, or a harmonic when the family shows in
    at least 2 steps.  Any other line is the rig's own motion when it is
    within ``MODE_REL`` of the frequency of a vibration of the step before (each frequency
    change rings the same mode, whose frequency moves a little with the level), of one
    that any step shows as the rig's (a decaying sinusoid fitted, or probe and accelerometer
    seeing one motion), or of a resonance of the source's own response (``resonances_Hz``:
    the most compliant frequency of each force level, where the rig rings); else it is interference from a steady source when it comes back at
    one frequency (within ``LINE_CLUSTER_REL``) in at least ``REPEAT_STEPS`` steps.  What is
    left, a line in one or two steps at frequencies no steady source explains, is the rig's
    own ringing too (pre-rolling friction damps little at small amplitude).  The rig's own
    becomes an ``unsettled_transient`` without a decay rate of its own, with settle advice
    from the decay rate of the source's fitted transients near its frequency (else of all
    of them), counted as :func:`settle_cycles` counts."""
    lines = [(i, a) for i, (_, q) in enumerate(quality) for a in q.artefacts if a.kind == "line_interference"]
    family: dict[str, set[int]] = {}             # mains base -> steps with a line of its family
    for i, a in lines:
        if mains(a.freq_Hz):
            family.setdefault(mains(a.freq_Hz).split(" (")[0], set()).add(i)

    def is_mains(f: float) -> bool:
        """A mains frequency whose family the source shows: the fundamental, or a harmonic
        (a window of 0.5 % that a stray line at a high frequency can fall into) seen with
        its family in at least 2 steps."""
        src = mains(f)
        return bool(src) and ("harmonic" not in src or len(family[src.split(" (")[0]]) >= 2)

    repeated = {(i, id(a)) for i, a in lines
                if len({i2 for i2, b in lines if _same_line(a.freq_Hz, b.freq_Hz)}) >= REPEAT_STEPS}
    decays = [(a.freq_Hz, a.decay_per_s) for _, q in quality for a in q.artefacts
              if _vibration_Hz(a) and a.decay_per_s > 0]
    modes = [(f"the {a.freq_Hz:.4g} Hz vibration of step {key}", a.freq_Hz)
             for key, q in quality for a in q.artefacts if _vibration_Hz(a)]
    modes += [(f"the {fr:.4g} Hz resonance of the measured response", float(fr)) for fr in resonances_Hz]
    vib: list[list[float]] = [[a.freq_Hz for a in q.artefacts if _vibration_Hz(a)] for _, q in quality]
    out = []
    for i, (key, q) in enumerate(quality):
        arts, changed = [], False
        for a in q.artefacts:
            if a.kind != "line_interference" or is_mains(a.freq_Hz):
                arts.append(a)
                continue
            near = lambda fv: abs(fv / a.freq_Hz - 1) <= MODE_REL          # noqa: E731
            before = [fv for fv in (vib[i - 1] if i else []) if near(fv)]
            mode = [(k, fv) for k, fv in modes if near(fv)]
            if before:
                why = (f"at the frequency of the vibration of the step before ({quality[i - 1][0]}, "
                       f"{before[0]:.4g} Hz): the rig's own free vibration, not interference")
            elif mode:
                why = (f"near {mode[0][0]}"
                       + (f" and {len(mode) - 1} other(s)" if len(mode) > 1 else "")
                       + ", the rig's own mode: the rig's own free vibration, not interference")
            elif (i, id(a)) in repeated:
                arts.append(a)
                continue
            else:
                why = (f"at no mains frequency and in fewer than {REPEAT_STEPS} steps at one frequency: the rig's own "
                       f"free vibration, not interference")
            arts.append(_as_vibration(a, q, why, decays))
            vib[i].append(a.freq_Hz)
            changed = True
        if not changed:
            out.append((key, q))
            continue
        old = {a.describe() for a in q.artefacts}
        notes = ([a.describe() for a in arts] + [n for n in q.notes if n not in old]) if q.notes else []
        out.append((key, replace(q, artefacts=arts, notes=notes)))
    return out


def _as_vibration(a: Artefact, q: StepQuality, why: str, decays: list[tuple[float, float]]) -> Artefact:
    """Line ``a`` of step ``q`` named an unsettled free vibration, with settle advice from
    the decay rates (frequency, rate) the source's fitted transients show."""
    near = [r for fr, r in decays if abs(fr / a.freq_Hz - 1) <= MODE_REL]
    rates = near or [r for _, r in decays]
    cycles, advice, least = 0, "", False
    if not (math.isfinite(a.snr) and math.isfinite(q.record_s) and math.isfinite(q.freq_Hz)):
        pass
    elif rates:
        sigma = float(np.median(rates))
        z = a.snr / max(1.0, sigma * q.record_s / 2)
        cycles = int(math.ceil(q.freq_Hz * math.log(z) / sigma)) if z > 1 else 0
        advice = (f"; settle advice from the decay rate {sigma:.3g} /s of the source's transients"
                  + (" near this frequency" if near else ""))
    elif a.decay_bound_per_s > 0:     # no transient to learn from: the record's own bound, so at least this many
        sigma = a.decay_bound_per_s
        z = a.snr / max(1.0, sigma * q.record_s / 2)
        cycles = int(math.ceil(q.freq_Hz * math.log(z) / sigma)) if z > 1 else 0
        advice = f"; its decay rate is below {sigma:.3g} /s (fit + 2 standard errors)"
        least = True
    return replace(a, kind="unsettled_transient", settle_cycles=cycles, settle_at_least=least,
                   evidence=f"{a.evidence}; {why}{advice}")


def artefact_causes(quality: list[tuple[str, StepQuality]], total: int | None = None) -> list[dict]:
    """``analysis.json`` causes of kind "artefact", aggregated over steps (module doc): one
    cause per family, never one per step.  Lines: the mains family of each mains frequency
    (its harmonics and channels together), and each other steady line frequency; unsettled
    transients and free vibrations: one cause; clipping, drop-outs, offset drift: one per
    channel.

    ``quality``: (step key, quality) of every step whose records were read, with the lines
    attributed (:func:`attribute_lines`); ``total``: the number of steps in the source
    (default: len(quality))."""
    total = len(quality) if total is None else total
    order = {key: i for i, (key, _) in enumerate(quality)}
    hits: dict[tuple, list[tuple[str, StepQuality, Artefact]]] = {}
    lines: list[tuple[str, StepQuality, Artefact]] = []
    for key, q in quality:
        for a in q.artefacts:
            if a.kind == "line_interference":
                lines.append((key, q, a))
            elif a.kind == "unsettled_transient":
                hits.setdefault(("unsettled_transient",), []).append((key, q, a))
            else:
                hits.setdefault((a.kind, a.channel), []).append((key, q, a))
    out = []
    families: dict[str, list] = {}
    for it in sorted(lines, key=lambda it: it[2].freq_Hz):
        src = mains(it[2].freq_Hz)
        fam = src.split(" (")[0] if src else None
        if fam is None:               # a steady line of another source: its frequency cluster
            fam = next((k for k, g in families.items() if not k.endswith("mains")
                        and _same_line(g[-1][2].freq_Hz, it[2].freq_Hz)), f"{it[2].freq_Hz:.6g} Hz")
        families.setdefault(fam, []).append(it)
    for fam, items in families.items():
        out.append(_line_cause(fam, sorted(items, key=lambda it: order[it[0]]), total))
    for (kind, *rest), items in hits.items():
        out.append(_other_cause(kind, rest[0] if rest else "", items, total))
    out.sort(key=lambda c: -len(c["evidence"]["steps"]))
    return out


def _entry(kind: str, channel: str, items, total: int, parameters: dict, sentence: str) -> dict:
    steps = list(dict.fromkeys(k for k, _, _ in items))
    rejected = list(dict.fromkeys(k for k, q, _ in items if q.status == "rejected"))
    return dict(id=kind, kind="artefact", label=LABELS[kind], formula=FORMULAS[kind], channel=channel,
                parameters=parameters, gain=dict(steps_kept=len(steps) - len(rejected), steps_rejected=len(rejected)),
                sentence=sentence,
                evidence=dict(steps=steps, steps_total=total, steps_rejected=rejected,
                              per_step=[dict(step=k, **a.as_dict()) for k, _, a in items]))


def _line_cause(family: str, items, total: int) -> dict:
    """One interference family: the mains of one frequency (any harmonic, any channel) or
    one other steady line.  Its parameters are those of its main line (the channel and
    harmonic in most steps), which a twin can rebuild; the others are in the sentence and
    the evidence."""
    base = float(family.split()[0]) if family.endswith("mains") else 0.0

    def line_of(a: Artefact) -> tuple[str, int]:
        return a.channel, (round(a.freq_Hz / base) if base else 1)

    count: dict[tuple[str, int], set] = {}
    for k, _, a in items:
        count.setdefault(line_of(a), set()).add(k)
    main = max(count, key=lambda c: len(count[c]))
    ch = main[0]
    f = [a.freq_Hz for _, _, a in items if line_of(a) == main]
    amp = [a.size for _, _, a in items if line_of(a) == main]
    n = len({k for k, _, _ in items})
    what = (f"{family} interference" if base else "interference from another source (a pump, a fan, a switching supply)")
    others = sorted(set(count) - {main})
    also = ("; also " + ", ".join((f"{m * base:g} Hz " if base else "") + f"on the {LABEL[c]} ({len(count[(c, m)])} steps)"
                                  for c, m in others)) if others else ""
    sentence = (f"a {np.median(f):.4g} Hz line of {si(float(np.median(amp)), UNIT[ch])} on the {LABEL[ch]} in {n} of "
                f"{total} steps, not locked to the drive: {what}{also}; removed before the fit")
    return _entry("line_interference", ch, items, total,
                  dict(frequency=_param(f, "Hz"), amplitude=_param(amp, UNIT[ch])), sentence)


def _other_cause(kind: str, ch: str, items, total: int) -> dict:
    qs = list({id(q): q for _, q, _ in items}.values())
    n = len(qs)
    arts = [a for _, _, a in items]
    rej = sum(q.status == "rejected" for q in qs)
    fate = (f"{n - rej} kept" if n > rej else "") + (", " if 0 < rej < n else "") + (f"{rej} rejected" if rej else "")
    where = _where(qs)
    if kind == "unsettled_transient":
        chans = sorted({a.channel for a in arts})
        worst = max(arts, key=lambda a: a.settle_cycles)
        cyc = worst.settle_cycles
        tau = [1e3 / a.decay_per_s for a in arts if a.decay_per_s > 0]
        ft = [a.freq_Hz for a in arts if math.isfinite(a.freq_Hz)]
        vib = (f"the rig's own unsettled free vibration near {np.median(ft):.3g} Hz" if ft
               else "the rig's own unsettled free vibration")
        const = f", time constant {_span(tau, 'ms')}" if tau else ""
        advice = f"settle {'at least ' if worst.settle_at_least else ''}{cyc} more cycles" if cyc else "settle longer"
        sentence = (f"steps {where} still vibrating at the record start ({vib}{const}, on the "
                    f"{' and '.join(LABEL[c] for c in chans)}) in {n} of {total} steps: {advice}; "
                    f"{fate} (transient removed or first periods dropped where the record allowed)")
        rates = [a.decay_per_s for a in arts if a.decay_per_s > 0]
        params = dict(settle_cycles_needed=_param([a.settle_cycles for a in arts], "cycles"))
        if rates:
            params["decay_rate"] = _param(rates, "1/s")
        if ft:
            params["frequency"] = _param(ft, "Hz")
        return _entry(kind, ",".join(chans), items, total, params, sentence)
    size = [abs(a.size) for a in arts]
    if kind == "clipping":
        sentence = (f"clipping on the {LABEL[ch]} in {n} of {total} steps ({where}): flat at "
                    f"{si(max(size), UNIT[ch])}, the range of the sensor or its input; {fate}: use a larger range "
                    f"or a lower level")
        params = dict(level=_param(size, UNIT[ch]), time_at_limit=_param([a.duration_s for a in arts], "s"))
    elif kind == "dropout":
        sentence = (f"drop-outs on the {LABEL[ch]} in {n} of {total} steps ({where}): the signal held for up to "
                    f"{1e3 * max(a.duration_s for a in arts):.3g} ms; {fate}: check the cable, connector and "
                    f"acquisition")
        params = dict(duration=_param([a.duration_s for a in arts], "s"))
    else:
        sentence = (f"an offset drift on the {LABEL[ch]} in {n} of {total} steps, up to {si(max(size), UNIT[ch])} "
                    f"over a record (thermal drift of the sensor, or the carriage creeping); removed before the fit")
        params = dict(change=_param(size, UNIT[ch]))
    return _entry(kind, ch, items, total, params, sentence)
