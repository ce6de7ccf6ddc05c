"""The comparison page: one self-contained HTML file from a compare.json dict alone.

Verdict first (within the tolerance or not, and the rms figures), then the figures
(compliance and accelerance of both sources per force level; the difference per step
against frequency with the tolerance), the per-step table and the unmatched steps.
Figures are embedded PNGs, the style is inline, there is no script (as the analysis page,
:mod:`bench.reports._html`).
"""

from __future__ import annotations

import logging
import math
from html import escape
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ._figures import level_colours
from ._html import CSS, figure, num, table

log = logging.getLogger(__name__)

QUANTITIES = ("compliance", "accelerance")
UNIT = {"compliance": "m/N", "accelerance": "(m/s^2)/N"}


def _z(pair) -> complex:
    return complex(pair[0], pair[1])


def _levels(steps: list[dict]) -> list[float]:
    """One value per force level: reference levels within 15 % share one (as the analysis)."""
    out: list[float] = []
    for lv in sorted(s["level_N"] for s in steps):
        if not out or lv > 1.15 * out[-1]:
            out.append(lv)
    return out


def _level_of(levels: list[float], lv: float) -> float:
    return max(x for x in levels if x <= lv * (1 + 1e-9))


def plot_frf(result: dict, quantity: str) -> Figure:
    """Magnitude and phase of both sources against frequency, one colour per force level:
    reference (open circles), other (lines with dots)."""
    steps = result["steps"]
    levels = _levels(steps)
    colours = level_colours(levels)
    fig = Figure(figsize=(10, 6.5), layout="constrained")
    ax_mag, ax_ph = fig.subplots(2, 1, sharex=True)
    for lv in levels:
        g = sorted((s for s in steps if _level_of(levels, s["level_N"]) == lv), key=lambda s: s["freq_Hz"])
        for direction in sorted({s["direction"] for s in g}):
            run = [s for s in g if s["direction"] == direction]
            f = np.array([s["freq_Hz"] for s in run])
            r = np.array([_z(s[quantity]["reference"]) for s in run])
            o = np.array([_z(s[quantity]["other"]) for s in run])
            ls = "--" if direction == "down" else "-"
            for ax, y in ((ax_mag, np.abs), (ax_ph, lambda z: np.degrees(np.unwrap(np.angle(z))))):
                ax.plot(f, y(r), ls="none", marker="o", mfc="none", mec=colours[lv], ms=7)
                ax.plot(f, y(o), ls=ls, marker=".", color=colours[lv], lw=1.3)
    ax_mag.set(xscale="log", yscale="log", ylabel=f"|{quantity}| ({UNIT[quantity]})")
    ax_ph.set(xscale="log", ylabel="phase (deg)", xlabel="frequency (Hz)")
    for ax in (ax_mag, ax_ph):
        ax.grid(True, which="both", alpha=0.3)
    handles = [Line2D([], [], color=colours[lv], lw=2, label=f"{lv:.3g} N") for lv in levels]
    handles += [Line2D([], [], color="0.3", ls="none", marker="o", mfc="none", label="reference"),
                Line2D([], [], color="0.3", marker=".", label="other")]
    ax_mag.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.suptitle(f"First-harmonic {quantity}: reference and other")
    return fig


def plot_difference(result: dict) -> Figure:
    """Relative complex difference per matched step against frequency, per force level, for
    compliance (filled) and accelerance (open), with the tolerance as a line."""
    steps = result["steps"]
    levels = _levels(steps)
    colours = level_colours(levels)
    fig = Figure(figsize=(10, 4.2), layout="constrained")
    ax = fig.subplots()
    for s in steps:
        c = colours[_level_of(levels, s["level_N"])]
        ax.plot(s["freq_Hz"], 100 * s["compliance"]["rel_diff"], "o", color=c, ms=6)
        ax.plot(s["freq_Hz"], 100 * s["accelerance"]["rel_diff"], "s", mfc="none", mec=c, ms=7)
    tol = 100 * result["tolerance"]
    ax.axhline(tol, color="#b00", ls="--", lw=1.2)
    ax.text(0.005, tol, f" tolerance {tol:g} %", color="#b00", va="bottom", transform=ax.get_yaxis_transform())
    ax.set(xscale="log", yscale="log", xlabel="frequency (Hz)", ylabel="|H_other - H_ref| / |H_ref| (%)")
    ax.grid(True, which="both", alpha=0.3)
    handles = [Line2D([], [], color=colours[lv], lw=2, label=f"{lv:.3g} N") for lv in levels]
    handles += [Line2D([], [], color="0.3", ls="none", marker="o", label="compliance"),
                Line2D([], [], color="0.3", ls="none", marker="s", mfc="none", label="accelerance")]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.suptitle("Difference per matched step")
    return fig


def _p(x) -> str:
    return "n/a" if x is None else f"{100 * x:.3g} %"


def _coverage(result: dict) -> str:
    cov = result.get("coverage")
    if not cov:
        return ""
    head = (f"<p>Coverage: {cov['matched']} of the reference's {cov['reference_steps']} usable steps matched "
            f"({100 * cov['fraction']:.3g} %; needed {100 * cov['min_coverage']:.3g} %).")
    if cov["resonance_unmatched"]:
        head += (f" <strong>{len(cov['resonance_unmatched'])} of the unmatched steps are at the resonance</strong> "
                 f"(within the half-power band of their level's peak compliance), where the rigs differ most: "
                 f"{escape(', '.join(cov['resonance_unmatched']))}.")
    if not cov["covered"]:
        head += " The comparison does not pass: steps the other source lacks can neither agree nor disagree."
    return head + "</p>"


def _unmatched_table(result: dict) -> str:
    cov = result.get("coverage")
    if not cov or not cov["unmatched"]:
        return ""
    rows = [[escape(m["step"]), num(m["level_N"], ".4g"), num(m["freq_Hz"], ".5g"), escape(m["direction"] or "-"),
             "yes" if m["resonance"] else "no", escape(m["why"])] for m in cov["unmatched"]]
    return ('<section aria-labelledby="unmatched-h"><h2 id="unmatched-h">Steps of the reference not compared</h2>'
            + table(["reference step", "level (N)", "frequency (Hz)", "sweep", "resonance", "why"], rows, {1, 2},
                    "Usable steps of the reference without a matching step in the other source, and why.")
            + "</section>")


def _verdict(result: dict) -> str:
    o = result["overall"]
    ok = o.get("passed", o["within_tolerance"])
    tol = 100 * result["tolerance"]
    if o["rms_rel_diff"] is None:
        head = (f"<p><strong>Outside the tolerance</strong>: no matched step is precise enough to judge a difference of "
                f"{tol:g} % (the noise of the two measurements alone gives more than half of it).</p>")
    else:
        head = (f"<p><strong>{'Within' if o['within_tolerance'] else 'Outside'} the tolerance</strong>: the larger "
                f"rms difference of "
                f"compliance and accelerance is {_p(o['rms_rel_diff'])} over the matched steps precise enough to judge "
                f"(tolerance {tol:g} %; {result['matched']} steps matched).</p>")
    parts = [head, _coverage(result)]
    for q in QUANTITIES:
        x = o[q]
        parts.append(f"<p>{q.capitalize()}: rms difference {_p(x['rms_rel_diff'])} over {x['judged']} judged steps "
                     f"({_p(x['rms_rel_diff_all'])} over all matched steps; magnitude "
                     f"{num(x['rms_mag_diff_pct'], '.3g')} %, phase {num(x['rms_phase_diff_deg'], '.3g')} deg), "
                     f"{num(x['rms_noise_units'], '.3g')} times the measurement noise; largest judged "
                     f"{_p(x['max_rel_diff'])}.</p>")
    parts.append("<p>A step is judged when the noise of the two measurements alone would give a difference of at "
                 "most half the tolerance; the others are shown but not gated.</p>")
    cls = "verdict" if ok else "verdict unexplained"
    return (f'<section aria-labelledby="verdict-h"><h2 id="verdict-h">Verdict</h2><div class="{cls}">'
            + "".join(parts) + "</div></section>")


def _sources(result: dict) -> str:
    rows = []
    for role in ("reference", "other"):
        s = result[role]
        rows.append([role, f"<code>{escape(s['path'])}</code>", escape(s["kind"]), str(s["steps"]),
                     str(len(s["rejected"])), f"<code>{escape(s['sha256'][:16])}</code>..."])
    return ('<section aria-labelledby="src-h"><h2 id="src-h">Sources</h2>'
            + table(["role", "path", "kind", "steps", "rejected", "sha256"], rows, {3, 4})
            + f"<p>Steps match when their force levels differ by at most {100 * result['matching']['level_rel']:g} %, "
              f"their frequencies by at most {100 * result['matching']['freq_rel']:g} % and their sweep directions "
              f"agree (when both are known).</p></section>")


def _steps_table(result: dict) -> str:
    rows = []
    for s in sorted(result["steps"], key=lambda s: (s["level_N"], s["direction"], s["freq_Hz"])):
        c, a = s["compliance"], s["accelerance"]
        rows.append([escape(s["reference_key"]), escape(s["other_key"]), num(s["level_N"], ".4g"),
                     num(s["freq_Hz"], ".5g"), escape(s["direction"] or "-"),
                     num(100 * c["rel_diff"], ".3g"), num(c["mag_diff_pct"], "+.3g"), num(c["phase_diff_deg"], "+.3g"),
                     num(c["noise_units"] if c["noise_units"] is not None else math.nan, ".3g"),
                     "yes" if c["judged"] else "no (noisy)",
                     num(100 * a["rel_diff"], ".3g"), num(a["mag_diff_pct"], "+.3g"), num(a["phase_diff_deg"], "+.3g")])
    head = ["reference step", "other step", "level (N)", "frequency (Hz)", "sweep", "compliance diff (%)",
            "magnitude (%)", "phase (deg)", "x noise", "judged", "accelerance diff (%)", "magnitude (%)", "phase (deg)"]
    out = ['<section aria-labelledby="steps-h"><h2 id="steps-h">Matched steps</h2>',
           table(head, rows, set(range(2, 13)) - {4, 9},
                  "Per matched step: relative complex difference, magnitude difference, phase difference "
                  "(other minus reference) and, for the compliance, the difference in units of its noise and whether "
                  "the step is precise enough to be judged at the tolerance.")]
    for role in ("reference", "other"):
        keys = result[f"unmatched_{role}"]
        if keys:
            out.append(f"<p>{len(keys)} steps of the {role} have no match: "
                       f"{escape(', '.join(keys[:20]))}{' ...' if len(keys) > 20 else ''}</p>")
    return "".join(out) + "</section>"


def render_compare_html(result: dict) -> str:
    title = "Comparison of two measurements"
    meta = f"reference: {result['reference']['path']}; other: {result['other']['path']}"
    figs = ['<section aria-labelledby="figs-h"><h2 id="figs-h">Figures</h2>']
    for q in QUANTITIES:
        figs.append(figure(plot_frf(result, q),
                            f"{q.capitalize()} magnitude and phase against frequency for each force level: reference "
                            f"as open circles, other as lines.",
                            f"First-harmonic {q}: the reference (open circles) and the other source (lines), one colour "
                            f"per force level; dashed: down sweeps."))
    figs.append(figure(plot_difference(result),
                        "Relative difference of compliance and accelerance per matched step against frequency, "
                        "with the tolerance line.",
                        "Relative complex difference |H_other - H_ref| / |H_ref| per matched step: compliance (filled), "
                        "accelerance (open); the dashed line is the tolerance."))
    figs.append("</section>")
    body = (f"<header><h1>{escape(title)}</h1><p class=\"meta\">{escape(meta)}</p></header><main>"
            + _verdict(result) + _sources(result) + "".join(figs) + _steps_table(result) + _unmatched_table(result)
            + "</main>")
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{escape(title)}</title><style>{CSS}</style></head>\n<body>{body}</body></html>\n")


def write_compare_html(result: dict, out_path: Path) -> Path:
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_name(out_path.name + ".tmp")
    tmp.write_text(render_compare_html(result), encoding="utf-8")
    tmp.replace(out_path)
    log.info("comparison page written to %s", out_path)
    return out_path
