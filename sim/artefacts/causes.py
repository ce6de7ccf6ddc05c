"""The artefacts of many steps (:mod:`sim.artefacts`): whose line it is
(:func:`attribute_lines`) and the ``analysis.json`` causes of kind "artefact"
(:func:`artefact_causes`)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from . import sentences
from .detectors import HARMONIC_GUARD
from .quality import Artefact, StepQuality
from .sentences import FORMULAS, LABELS, UNIT, mains_line


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
COHERENT_FACTOR = 2.0       # a steady source's line keeps its amplitude: within this factor of its median
COMPONENT_SHARE = 0.5       # a line at most this share of a stronger line of its step and channel ...
COMPONENT_RESOLUTIONS = 4.0  # ... within this many record resolutions of it, or at a sideband of it with a
#                              drive harmonic (|f - f_line| or f + f_line a multiple of the drive), is its component


def _same_line(f1: float, f2: float) -> bool:
    return abs(f1 - f2) <= max(0.05, LINE_CLUSTER_REL * max(f1, f2))


def _vibration_Hz(a: Artefact) -> bool:
    """An unsettled transient or free vibration with a frequency of its own (the rig's mode)."""
    return a.kind == "unsettled_transient" and math.isfinite(a.freq_Hz)


def _coherent(sizes: list[float]) -> int:
    """How many of these amplitudes lie within ``COHERENT_FACTOR`` of their median."""
    if not sizes:
        return 0
    mid = float(np.median(sizes))
    return sum(mid / COHERENT_FACTOR <= s <= mid * COHERENT_FACTOR for s in sizes)


def _component_of(a: Artefact, q: StepQuality) -> Artefact | None:
    """The stronger line of ``a``'s step and channel that ``a`` is a component of: what a
    strong line and the drive make together in one record (spectral leakage and a fit that
    splits the line into neighbours, within ``COMPONENT_RESOLUTIONS`` of it; sidebands at
    the line's frequency plus or minus a drive harmonic, within the detector's guard), at
    most ``COMPONENT_SHARE`` of its amplitude.  None when there is none."""
    res = 1.0 / q.record_s if math.isfinite(q.record_s) and q.record_s > 0 else 0.0
    guard = max(HARMONIC_GUARD * res, 0.05)
    for b in sorted(q.artefacts, key=lambda b: -b.size):
        if (b is a or b.kind != "line_interference" or b.channel != a.channel
                or not a.size <= COMPONENT_SHARE * b.size):
            continue
        if abs(a.freq_Hz - b.freq_Hz) <= COMPONENT_RESOLUTIONS * max(res, 0.05):
            return b
        if math.isfinite(q.freq_Hz) and q.freq_Hz > 0:
            for gap in (abs(a.freq_Hz - b.freq_Hz), a.freq_Hz + b.freq_Hz):
                k = round(gap / q.freq_Hz)
                if k >= 1 and abs(gap - k * q.freq_Hz) <= guard:
                    return b
    return None


def attribute_lines(quality: list[tuple[str, StepQuality]],
                    resonances_Hz: tuple[float, ...] = ()) -> list[tuple[str, StepQuality]]:
    """Whose line is it?  The steps of one source in the order they were measured, with
    every ``line_interference`` that is not interference named what it is: a component of
    a stronger line of its step, or the rig's own unsettled free vibration (decision
    records 0045, 0053).

    One step cannot tell a weak free vibration seen by one sensor from a hum (decision
    0033), nor a source from what a strong line and the drive make together; the source
    can.  First, per step, a line at most ``COMPONENT_SHARE`` of a stronger line on its
    channel and within ``COMPONENT_RESOLUTIONS`` of it or at a sideband of it with a drive
    harmonic is that line's component (:func:`_component_of`): it follows the stronger line
    (``part_of_Hz``), it is no source of its own.  Of the others, a line at a mains
    frequency (50/60 Hz and harmonics, :func:`mains`) is mains interference when its family
    comes back over the run: one of its lines (channel, harmonic) in at least
    ``REPEAT_STEPS`` steps with a coherent amplitude (within ``COHERENT_FACTOR`` of its
    median); a mains frequency alone, in one step, makes no hum.  Any other line is the
    rig's own motion when it is within ``MODE_REL`` of the frequency of a vibration of the
    step before (each frequency change rings the same mode, whose frequency moves a little
    with the level), of one that any step shows as the rig's (a decaying sinusoid fitted,
    or probe and accelerometer seeing one motion), or of a resonance of the source's own
    response (``resonances_Hz``: the most compliant frequency of each force level, where
    the rig rings); else it is interference from a steady source when it comes back at one
    frequency (within ``LINE_CLUSTER_REL``) in at least ``REPEAT_STEPS`` steps, at as many
    drive frequencies (a by-product of one drive comes back at that drive only) and with a
    coherent amplitude: what a technician needs to go and look for a pump.  What is left is
    the rig's own ringing too (pre-rolling friction damps little at small amplitude).  The
    rig's own becomes an ``unsettled_transient`` without a decay rate of its own, with
    settle advice from the decay rate of the source's fitted transients near its frequency
    (else of all of them), counted as :func:`settle_cycles` counts."""
    parent: dict[int, Artefact] = {}              # id(line) -> the stronger line it is a component of
    for _, q in quality:
        for a in q.artefacts:
            if a.kind == "line_interference":
                b = _component_of(a, q)
                if b is not None:
                    parent[id(a)] = b
    lines = [(i, a) for i, (_, q) in enumerate(quality) for a in q.artefacts
             if a.kind == "line_interference" and id(a) not in parent]
    groups: dict[tuple[float, str, int], list[tuple[int, float]]] = {}    # (mains base, channel, harmonic)
    for i, a in lines:
        src = mains_line(a.freq_Hz)
        if src is not None:
            base, m = src
            groups.setdefault((base, a.channel, m), []).append((i, a.size))
    hum = {base for (base, _, _), g in groups.items()
           if _coherent([s for _, s in g]) >= REPEAT_STEPS and len({i for i, _ in g}) >= REPEAT_STEPS}

    def is_mains(i: int, a: Artefact) -> bool:
        """At a mains frequency whose family comes back over the run (above): the line of the
        family that does, or another harmonic of it seen in 2 steps or in a step with that
        line (a window of 0.5 % that a stray line at a high frequency can fall into)."""
        src = mains_line(a.freq_Hz)
        if src is None or src[0] not in hum:
            return False
        base, m = src
        g = groups[(base, a.channel, m)]
        if _coherent([s for _, s in g]) >= REPEAT_STEPS or len({i2 for i2, _ in g}) >= 2:
            return True
        return any(key[0] == base and i in {i2 for i2, _ in g2} and _coherent([s for _, s in g2]) >= REPEAT_STEPS
                   for key, g2 in groups.items())

    # where the hum sits within the detector's guard of a drive harmonic it is not separable from
    # it: the step shows no line at its frequency, only its leakage around it (a 50 Hz hum of
    # 8.2 um at a drive of 10.35 Hz, 1.4 resolutions from harmonic 5: "lines" at 46.75 and
    # 55.8 Hz of 1.0 and 0.5 um).  Those weaker lines on its channel are the hum's.
    hidden: dict[int, float] = {}                  # id(line) -> the frequency of the hum it is leakage of
    for (base, ch, _), g in groups.items():
        if base not in hum or _coherent([s for _, s in g]) < REPEAT_STEPS:
            continue
        F = float(np.median([a.freq_Hz for i, a in lines if (i, a.size) in g and a.channel == ch]))
        A = float(np.median([s for _, s in g]))
        with_it = {i for i, _ in g}
        for i, (_, q) in enumerate(quality):
            if i in with_it or not (math.isfinite(q.freq_Hz) and q.freq_Hz > 0 and q.record_s > 0):
                continue
            k = round(F / q.freq_Hz)
            if k >= 1 and abs(F - k * q.freq_Hz) <= HARMONIC_GUARD / q.record_s:
                for a in q.artefacts:
                    if a.kind == "line_interference" and a.channel == ch and a.size <= A and mains_line(a.freq_Hz) is None:
                        hidden[id(a)] = F
    lines = [(i, a) for i, a in lines if id(a) not in hidden]

    def steady(i: int, a: Artefact) -> bool:
        same = [(i2, b) for i2, b in lines if _same_line(a.freq_Hz, b.freq_Hz) and not is_mains(i2, b)]
        drives: list[float] = []                   # the drive frequencies it comes back at
        for i2, _ in same:
            f = quality[i2][1].freq_Hz
            if not any(_same_line(f, d) for d in drives):
                drives.append(f)
        return (len({i2 for i2, _ in same}) >= REPEAT_STEPS and len(drives) >= REPEAT_STEPS
                and _coherent([b.size for _, b in same]) >= REPEAT_STEPS)

    repeated = {(i, id(a)) for i, a in lines if steady(i, a)}
    decays = [(a.freq_Hz, a.decay_per_s) for _, q in quality for a in q.artefacts
              if _vibration_Hz(a) and a.decay_per_s > 0]
    modes = [(key, a.freq_Hz) for key, q in quality for a in q.artefacts if _vibration_Hz(a)]
    modes += [("", float(fr)) for fr in resonances_Hz]        # "": the measured response's resonance
    vib: list[list[float]] = [[a.freq_Hz for a in q.artefacts if _vibration_Hz(a)] for _, q in quality]
    interference: set[int] = set()
    out: list[tuple[str, StepQuality, list[Artefact], bool]] = []
    for i, (key, q) in enumerate(quality):
        arts, changed = [], False
        for a in q.artefacts:
            if a.kind != "line_interference" or id(a) in parent:
                arts.append(a)
                continue
            if id(a) in hidden:
                F = hidden[id(a)]
                arts.append(replace(a, part_of_Hz=F, evidence=sentences.leakage_of_source(
                    a.evidence, F, HARMONIC_GUARD, round(F / q.freq_Hz))))
                changed = True
                continue
            if is_mains(i, a):
                arts.append(a)
                interference.add(id(a))
                continue
            near = lambda fv: abs(fv / a.freq_Hz - 1) <= MODE_REL          # noqa: E731
            before = [fv for fv in (vib[i - 1] if i else []) if near(fv)]
            mode = [(k, fv) for k, fv in modes if near(fv)]
            if before:
                why = sentences.vibration_of_step_before(quality[i - 1][0], before[0])
            elif mode:
                why = sentences.near_mode(mode[0][0], mode[0][1], len(mode) - 1)
            elif (i, id(a)) in repeated:
                arts.append(a)
                interference.add(id(a))
                continue
            else:
                why = sentences.not_repeated(mains_line(a.freq_Hz) is not None, REPEAT_STEPS)
            arts.append(_as_vibration(a, q, why, decays))
            vib[i].append(a.freq_Hz)
            changed = True
        out.append((key, q, arts, changed))
    result = []
    for key, q, arts, changed in out:
        final = []
        for a in arts:
            b = parent.get(id(a))
            if b is not None and a.kind == "line_interference":
                root = b
                while id(root) in parent:
                    root = parent[id(root)]
                if id(root) in interference:
                    a = replace(a, part_of_Hz=root.freq_Hz, evidence=sentences.component_of(a.evidence, root.freq_Hz))
                elif id(root) in hidden:          # beside the leakage of a hum the step cannot separate
                    F = hidden[id(root)]
                    a = replace(a, part_of_Hz=F, evidence=sentences.beside_leakage(a.evidence, F))
                else:
                    a = _as_vibration(a, q, sentences.beside_stronger(b.freq_Hz), decays)
                changed = True
            final.append(a)
        if not changed:
            result.append((key, q))
            continue
        old = {a.describe() for a in q.artefacts}
        notes = ([a.describe() for a in final] + [n for n in q.notes if n not in old]) if q.notes else []
        result.append((key, replace(q, artefacts=final, notes=notes)))
    return result


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
        advice = sentences.advice_from_transients(sigma, bool(near))
    elif a.decay_bound_per_s > 0:     # no transient to learn from: the record's own bound, so at least this many
        sigma = a.decay_bound_per_s
        z = a.snr / max(1.0, sigma * q.record_s / 2)
        cycles = int(math.ceil(q.freq_Hz * math.log(z) / sigma)) if z > 1 else 0
        advice = sentences.advice_from_bound(sigma)
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
    families: dict[tuple[float, float], list] = {}     # (mains base, 0) or (0, a steady line's first frequency)

    def source_Hz(a: Artefact) -> float:        # a component goes with the line it is a component of
        return a.part_of_Hz if math.isfinite(a.part_of_Hz) else a.freq_Hz

    for it in sorted(lines, key=lambda it: (source_Hz(it[2]), math.isfinite(it[2].part_of_Hz))):
        f_src = source_Hz(it[2])
        src = mains_line(f_src)
        fam = (src[0], 0.0) if src is not None else None
        if fam is None:               # a steady line of another source: its frequency cluster
            fam = next((k for k, g in families.items() if not k[0]
                        and _same_line(source_Hz(g[-1][2]), f_src)), (0.0, f_src))
        families.setdefault(fam, []).append(it)
    for (base, _), items in families.items():
        out.append(_line_cause(base, sorted(items, key=lambda it: order[it[0]]), total))
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


def _line_cause(base: float, items, total: int) -> dict:
    """One interference family: the mains of one frequency (any harmonic, any channel) or
    one other steady line (``base``: the mains frequency, 0 for another source).  Its parameters are those of its main line (the channel and
    harmonic in most steps), which a twin can rebuild; the others are in the sentence and
    the evidence."""
    def line_of(a: Artefact) -> tuple[str, int]:
        return a.channel, (round(a.freq_Hz / base) if base else 1)

    parts = [(k, a) for k, _, a in items if math.isfinite(a.part_of_Hz)]
    count: dict[tuple[str, int], set] = {}
    for k, _, a in items:
        if not math.isfinite(a.part_of_Hz):
            count.setdefault(line_of(a), set()).add(k)
    main = max(count, key=lambda c: len(count[c]))
    ch = main[0]
    # the line's own figures: its components (leakage and sidebands at other frequencies, which can
    # round to the same harmonic) are counted in the sentence, not in its frequency and amplitude
    f = [a.freq_Hz for _, _, a in items if line_of(a) == main and not math.isfinite(a.part_of_Hz)]
    amp = [a.size for _, _, a in items if line_of(a) == main and not math.isfinite(a.part_of_Hz)]
    n = len({k for k, _, a in items if not math.isfinite(a.part_of_Hz)})
    others = [(c, m * base, len(count[(c, m)])) for c, m in sorted(set(count) - {main})]
    sentence = sentences.line_cause(float(np.median(f)), float(np.median(amp)), ch, n, total, base, others,
                                    len(parts), len({k for k, _ in parts}))
    return _entry("line_interference", ch, items, total,
                  dict(frequency=_param(f, "Hz"), amplitude=_param(amp, UNIT[ch])), sentence)


def _other_cause(kind: str, ch: str, items, total: int) -> dict:
    qs = list({id(q): q for _, q, _ in items}.values())
    n = len(qs)
    arts = [a for _, _, a in items]
    rej = sum(q.status == "rejected" for q in qs)
    where = _where(qs)
    if kind == "unsettled_transient":
        chans = sorted({a.channel for a in arts})
        worst = max(arts, key=lambda a: a.settle_cycles)
        cyc = worst.settle_cycles
        tau = [1e3 / a.decay_per_s for a in arts if a.decay_per_s > 0]
        ft = [a.freq_Hz for a in arts if math.isfinite(a.freq_Hz)]
        sentence = sentences.transient_cause(where, float(np.median(ft)) if ft else math.nan,
                                             _span(tau, "ms") if tau else "", chans, n, total, cyc,
                                             worst.settle_at_least, rej)
        rates = [a.decay_per_s for a in arts if a.decay_per_s > 0]
        params = dict(settle_cycles_needed=_param([a.settle_cycles for a in arts], "cycles"))
        if rates:
            params["decay_rate"] = _param(rates, "1/s")
        if ft:
            params["frequency"] = _param(ft, "Hz")
        return _entry(kind, ",".join(chans), items, total, params, sentence)
    size = [abs(a.size) for a in arts]
    if kind == "clipping":
        sentence = sentences.clipping_cause(ch, n, total, where, max(size), rej)
        params = dict(level=_param(size, UNIT[ch]), time_at_limit=_param([a.duration_s for a in arts], "s"))
    elif kind == "dropout":
        sentence = sentences.dropout_cause(ch, n, total, where, max(a.duration_s for a in arts), rej)
        params = dict(duration=_param([a.duration_s for a in arts], "s"))
    else:
        sentence = sentences.drift_cause(ch, n, total, max(size))
        params = dict(change=_param(size, UNIT[ch]))
    return _entry(kind, ch, items, total, params, sentence)
