"""``bench compare REFERENCE OTHER``: do two measurements show the same rig?

Both sources (run directories or UFF58 files, in any combination) are read into steps by
:func:`bench.sources.load_source`.  Steps are matched by force level (within
``LEVEL_TOL``), frequency (within ``FREQ_TOL``) and sweep direction (when both know it);
for each matched pair the first-harmonic compliance X1/P1 and accelerance A1/P1 are
compared: the relative complex difference |H_o - H_r| / |H_r| (magnitude and phase
together), the magnitude difference in per cent, the phase difference in degrees, and
the difference in units of its noise (both steps' standard errors propagated).

A step is *judged* when the noise of the two measurements alone gives a relative
difference of at most half the tolerance (``JUDGED_NOISE``): a noisier step (a tiny
displacement far above resonance, an unsettled free vibration) cannot tell a difference
of the tolerance from noise, and is reported but not gated.  The overall figure per
quantity is the rms of the relative complex difference over the judged steps (the rms
over all matched steps is reported beside it); ``within_tolerance`` holds when both the
compliance's and the accelerance's are at most the tolerance.

*Coverage*: the share of the reference's usable steps that found a match.  Steps the other
source lacks (never measured, or rejected there, which is said with its reason) cannot
agree or disagree, so ``passed`` (CLI exit 0, else 1) also needs the coverage to reach
``min_coverage`` (default 1: every usable step of the reference matched).  The unmatched
ones are named, and those at the resonance (within the half-power band of their force
level's most compliant step: where a twin that rejects its resonance steps hides its
worst difference) are named as such.  Writes ``compare.json``
(schema in docs/twin.md) and ``compare.html``.  Decision record 0026.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

from sim.errors import ConfigurationError

from .sources import MeasuredStep, Source, SourceProblem, load_source
from .storage import write_json
from .words import terminal_data as words

log = logging.getLogger(__name__)

SCHEMA = "guideway-bench/compare/1"
LEVEL_TOL = 0.05       # relative force-level difference of matched steps
FREQ_TOL = 0.005       # relative frequency difference of matched steps
QUANTITIES = ("compliance", "accelerance")
JUDGED_NOISE = 0.5     # a step is judged when its noise alone gives at most half the tolerance
LEVEL_GROUP = 1.15     # reference levels within 15 % are one force level (as the comparison page)
RESONANCE_BAND = 1 / math.sqrt(2)   # a step within the half-power band of its level's peak compliance


class CompareSaid(StrEnum):
    """``bench compare``'s refusals, what compare.json says of the matching and of each
    unmatched step, and the summary it prints (words: :data:`bench.words.terminal_data.COMPARE`)."""

    BAD_TOLERANCE = "bad_tolerance"         # value
    BAD_MIN_COVERAGE = "bad_min_coverage"   # value
    NO_STEPS = "no_steps_to_compare"        # path
    NO_MATCH = "no_match"                   # reference, other, level_pct, freq_pct
    BY_RESPONSE = "by_response"             # unit: the steps were matched by the response both held
    BY_FORCE = "by_force"                   # ... by the force
    REJECTED_IN_OTHER = "rejected_in_other"  # step, reason: the other's step at its level and frequency
    NOT_IN_OTHER = "not_in_other"           # never measured there
    SUMMARY = "summary"                     # result, quantities, judged_noise


@dataclass(frozen=True)
class Frf:
    """First-harmonic compliance and accelerance of a step, with their standard errors."""

    compliance: complex
    accelerance: complex
    sigma_compliance: float
    sigma_accelerance: float

    @classmethod
    def of(cls, s: MeasuredStep) -> Frf:
        h = s.harmonics
        P, A, X = complex(h.force[0]), complex(h.accel[0]), complex(h.disp[0])
        rel_P = h.sigma_force / abs(P)
        C, Acc = X / P, A / P
        return cls(C, Acc, abs(C) * math.hypot(h.sigma_disp / abs(X), rel_P),
                   abs(Acc) * math.hypot(h.sigma_accel / abs(A), rel_P))


def match_steps(ref: list[MeasuredStep], other: list[MeasuredStep]) -> list[tuple[int, int]]:
    """Pairs (i_ref, i_other): each reference step with the nearest unused other step of the
    same level, frequency and direction (directions are ignored when either is unknown).  The
    level is the force, or, when both steps held a response in the same unit
    (response control), that response's level."""
    pairs, used = [], set()
    for i, r in enumerate(ref):
        best, best_d = None, math.inf
        for j, o in enumerate(other):
            if j in used or (r.direction and o.direction and r.direction != o.direction):
                continue
            both = r.held and o.held and r.held[1] == o.held[1]
            dl = abs(o.held[0] / r.held[0] - 1) if both and r.held and o.held else abs(o.level_N / r.level_N - 1)
            df = abs(o.freq_Hz / r.freq_Hz - 1)
            if dl <= LEVEL_TOL and df <= FREQ_TOL:
                d = dl / LEVEL_TOL + df / FREQ_TOL
                if d < best_d:
                    best, best_d = j, d
        if best is not None:
            used.add(best)
            pairs.append((i, best))
    return pairs


def _matched_by(ref: list[MeasuredStep], other: list[MeasuredStep]) -> str:
    """The level the steps were matched by, in words."""
    units = {s.held[1] if s.held else "N" for s in ref + other}
    if len(units) == 1 and units != {"N"}:
        return words.said(CompareSaid.BY_RESPONSE, unit=units.pop())
    return words.said(CompareSaid.BY_FORCE)


def _ri(z: complex) -> list[float]:
    return [float(z.real), float(z.imag)]


def _difference(hr: complex, ho: complex, sr: float, so: float, tolerance: float) -> dict:
    dphi = math.degrees(math.remainder(np.angle(ho) - np.angle(hr), 2 * math.pi))
    sigma = math.hypot(sr, so)
    rel_noise = math.sqrt(2) * sigma / abs(hr)        # rms of rel_diff from the noise alone
    return dict(reference=_ri(hr), other=_ri(ho), rel_diff=abs(ho - hr) / abs(hr),
                mag_diff_pct=100 * (abs(ho) / abs(hr) - 1), phase_diff_deg=dphi,
                noise_units=abs(ho - hr) / sigma if sigma > 0 else None, rel_noise=rel_noise,
                judged=bool(rel_noise <= JUDGED_NOISE * tolerance))


def _rms(x) -> float:
    x = np.asarray(list(x), float)
    return float(np.sqrt(np.mean(x ** 2))) if x.size else math.nan


def _describe(src: Source) -> dict:
    from .twin import source_sha256
    return dict(path=str(src.path), kind=src.kind, sha256=source_sha256(src.path), steps=len(src.steps),
                rejected=[dict(step=r.step, reason=r.reason) for r in src.rejected])


def resonance_keys(steps: list[MeasuredStep]) -> set[str]:
    """Keys of the steps at the resonance: within the half-power band (|X1/P1| at least
    1/sqrt(2) of the peak) of their force level's most compliant step."""
    def level(s: MeasuredStep) -> float:       # the response a step held, else its force
        return s.held[0] if s.held else s.level_N

    levels: list[float] = []
    for lv in sorted(level(s) for s in steps):
        if not levels or lv > LEVEL_GROUP * levels[-1]:
            levels.append(lv)
    out: set[str] = set()
    for lv in levels:
        group = [s for s in steps if max(x for x in levels if x <= level(s) * (1 + 1e-9)) == lv]
        mag = {s.key: abs(Frf.of(s).compliance) for s in group}
        peak = max(mag.values())
        out |= {k for k, m in mag.items() if m >= RESONANCE_BAND * peak}
    return out


def _why_unmatched(r: MeasuredStep, other: Source) -> str:
    """Why reference step ``r`` has no match: rejected in the other (with its reason) when a
    rejected step of the other has its level, frequency and direction, else not measured there."""
    for x in other.rejected:
        q = x.quality
        if q is None or not (math.isfinite(q.freq_Hz) and math.isfinite(q.level_N) and q.level_N > 0):
            continue
        if abs(q.freq_Hz / r.freq_Hz - 1) <= FREQ_TOL and abs(q.level_N / r.level_N - 1) <= LEVEL_TOL:
            return words.said(CompareSaid.REJECTED_IN_OTHER, step=x.step, reason=x.reason)
    return words.said(CompareSaid.NOT_IN_OTHER)


def coverage(ref: Source, oth: Source, pairs: list[tuple[int, int]], min_coverage: float) -> dict:
    """How much of the reference the comparison covers, and what it does not (module doc)."""
    matched = {i for i, _ in pairs}
    res = resonance_keys(ref.steps)
    missing = [dict(step=s.key, level_N=float(s.level_N), level=s.level_text(), freq_Hz=float(s.freq_Hz),
                    direction=s.direction,
                    resonance=s.key in res, why=_why_unmatched(s, oth))
               for k, s in enumerate(ref.steps) if k not in matched]
    frac = len(matched) / len(ref.steps)
    return dict(reference_steps=len(ref.steps), matched=len(matched), fraction=frac, min_coverage=min_coverage,
                covered=bool(frac >= min_coverage - 1e-12), unmatched=missing,
                resonance_unmatched=[m["step"] for m in missing if m["resonance"]],
                reference_rejected=len(ref.rejected))


def compare_sources(reference, other, tolerance: float = 0.02, min_coverage: float = 1.0) -> dict:
    """The comparison as a dict (compare.json's schema).  ``reference``, ``other``: paths, or
    sources already read by :func:`bench.sources.load_source`.  ``min_coverage``: the share
    of the reference's usable steps that must be matched for the comparison to pass."""
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise words.refused(ConfigurationError, CompareSaid.BAD_TOLERANCE, value=tolerance)
    if not (math.isfinite(min_coverage) and 0 < min_coverage <= 1):
        raise words.refused(ConfigurationError, CompareSaid.BAD_MIN_COVERAGE, value=min_coverage)
    srcs = []
    for p in (reference, other):
        if isinstance(p, Source):
            srcs.append(p)
            continue
        if not Path(p).exists():
            raise words.refused(ConfigurationError, SourceProblem.NO_SUCH_SOURCE, path=p)
        srcs.append(load_source(Path(p)))
    ref, oth = srcs
    for s in srcs:
        if not s.steps:
            raise words.refused(ConfigurationError, CompareSaid.NO_STEPS, path=s.path)
    pairs = match_steps(ref.steps, oth.steps)
    if not pairs:
        raise words.refused(ConfigurationError, CompareSaid.NO_MATCH, reference=ref.path, other=oth.path,
                            level_pct=100 * LEVEL_TOL, freq_pct=100 * FREQ_TOL)
    steps = []
    for i, j in pairs:
        r, o = ref.steps[i], oth.steps[j]
        fr, fo = Frf.of(r), Frf.of(o)
        steps.append(dict(reference_key=r.key, other_key=o.key, level_N=float(r.level_N),
                          other_level_N=float(o.level_N), freq_Hz=float(r.freq_Hz), direction=r.direction or o.direction,
                          **{q: _difference(getattr(fr, q), getattr(fo, q), getattr(fr, f"sigma_{q}"),
                                            getattr(fo, f"sigma_{q}"), tolerance) for q in QUANTITIES}))
    overall = {}
    for q in QUANTITIES:
        d = [s[q] for s in steps]
        judged = [x["rel_diff"] for x in d if x["judged"]]
        overall[q] = dict(rms_rel_diff=_rms(judged) if judged else None, judged=len(judged),
                          rms_rel_diff_all=_rms(x["rel_diff"] for x in d),
                          max_rel_diff=float(max(judged)) if judged else None,
                          rms_mag_diff_pct=_rms(x["mag_diff_pct"] for x in d),
                          rms_phase_diff_deg=_rms(x["phase_diff_deg"] for x in d),
                          rms_noise_units=_rms(x["noise_units"] for x in d if x["noise_units"] is not None))
    rms = [overall[q]["rms_rel_diff"] for q in QUANTITIES]
    worst = None if None in rms else max(rms)
    matched_r, matched_o = {i for i, _ in pairs}, {j for _, j in pairs}
    cov = coverage(ref, oth, pairs, min_coverage)
    within = worst is not None and worst <= tolerance
    return dict(schema=SCHEMA, reference=_describe(ref), other=_describe(oth), tolerance=tolerance,
                matching=dict(level_rel=LEVEL_TOL, freq_rel=FREQ_TOL, level=_matched_by(ref.steps, oth.steps)),
                matched=len(pairs),
                unmatched_reference=[s.key for k, s in enumerate(ref.steps) if k not in matched_r],
                unmatched_other=[s.key for k, s in enumerate(oth.steps) if k not in matched_o],
                coverage=cov,
                overall=dict(overall, rms_rel_diff=worst, within_tolerance=within, passed=within and cov["covered"]),
                steps=steps)


def summary(result: dict) -> str:
    """The comparison in words (what ``bench compare`` prints)."""
    return words.said(CompareSaid.SUMMARY, result=result, quantities=QUANTITIES, judged_noise=JUDGED_NOISE)


def default_out_dir(other: Path) -> Path:
    """OTHER/compare for a run directory, <stem>_compare next to a file."""
    return other / "compare" if other.is_dir() else other.parent / f"{other.stem}_compare"


def write_compare(reference: Path, other: Path, out: Path | None = None, tolerance: float = 0.02,
                  min_coverage: float = 1.0) -> tuple[dict, Path]:
    """Compare, write compare.json and compare.html to ``out``; (result, out)."""
    from .reports import write_compare_html
    result = compare_sources(reference, other, tolerance, min_coverage)
    out = Path(out) if out else default_out_dir(Path(other))
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "compare.json", result)
    write_compare_html(result, out / "compare.html")
    return result, out
