"""The analysis page: one self-contained HTML file from an analysis dict alone.

Figures are PNGs embedded as base64 ``data:`` URIs and the style sheet is inline, so the
page has no external resource and opens offline, by mail or from a USB stick; it has no
script.  Order: the verdict first (what a technician reads), one figure of measured, base
and extended compliance, the causes table (kind, formula, size with 95 % intervals, held-out
gain, a sentence), the restoring-force plot (the force the base model leaves out against
displacement and velocity); then, collapsed in a ``<details>`` section, the parameters,
the figures per force level (FRFs, loops, residuals), the candidates, the diagnostics as
tables and the steps rejected.  Every part but the
verdict may be missing; the page then says so in place.
"""

from __future__ import annotations

import base64
import logging
import math
from html import escape
from pathlib import Path

from sim.discrepancy.rounding import round_to_interval

from . import _figures as figures
from . import _figures_analysis as analysis_figures
from ._analysis import FRICTION_HEAD, AnalysisData, Interval, analysis_data, friction_rows

log = logging.getLogger(__name__)

# display units of the known parameters: SI key -> (label, unit, scale from SI)
PARAM_DISPLAY = {"F_s_N": ("F_s", "N", 1.0), "x_s_m": ("x_s", "um", 1e6), "n": ("n", "", 1.0),
                 "mass_kg": ("m", "kg", 1.0)}

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #1a1a1a;
       max-width: 62rem; margin: 1.5rem auto; padding: 0 1rem; line-height: 1.45; }
h1 { font-size: 1.6rem; margin-bottom: 0.2rem; }
h2 { font-size: 1.25rem; border-bottom: 1px solid #ccc; padding-bottom: 0.2rem; margin-top: 2rem; }
h3 { font-size: 1.05rem; margin-bottom: 0.3rem; }
.meta { color: #555; font-size: 0.9rem; }
.verdict { border-left: 6px solid #2b7a3d; background: #eef7f0; padding: 0.8rem 1rem; font-size: 1.1rem; }
.verdict.unexplained { border-left-color: #b35c00; background: #fff4e5; }
.verdict p { margin: 0.3rem 0; }
.flag { font-weight: bold; }
table { border-collapse: collapse; margin: 0.5rem 0 1rem; font-size: 0.92rem; }
th, td { border: 1px solid #bbb; padding: 0.25rem 0.55rem; text-align: left; vertical-align: top; }
th { background: #f0f0f0; }
caption { text-align: left; caption-side: top; font-size: 0.9rem; color: #333; padding-bottom: 0.2rem; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
figure { margin: 1rem 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 0.9rem; color: #333; }
details { margin-top: 2rem; }
summary { cursor: pointer; font-weight: bold; font-size: 1.1rem; }
.problems { border: 1px solid #b00; padding: 0.5rem 1rem; background: #fff0f0; }
@media print {
  body { max-width: none; margin: 0; font-size: 10pt; }
  figure, table, .verdict { break-inside: avoid; page-break-inside: avoid; }
  h2 { break-after: avoid; page-break-after: avoid; }
}
"""


def num(v: float, fmt: str = ".4g") -> str:
    return "n/a" if not math.isfinite(v) else format(v, fmt)


def _pct(v: float) -> str:
    return "n/a" if not math.isfinite(v) else f"{100 * v:.3g} %"


def table(head: list[str], rows: list[list[str]], numeric: set[int] = frozenset(), caption: str = "") -> str:
    cap = f"<caption>{escape(caption)}</caption>" if caption else ""
    th = "".join(f'<th scope="col">{escape(h)}</th>' for h in head)
    body = "".join("<tr>" + "".join(f'<td class="num">{c}</td>' if i in numeric else f"<td>{c}</td>"
                                    for i, c in enumerate(row)) + "</tr>" for row in rows)
    return f"<table>{cap}<thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"


def figure(fig, alt: str, caption: str) -> str:
    data = base64.b64encode(figures.png_bytes(fig)).decode("ascii")
    return (f'<figure><img src="data:image/png;base64,{data}" alt="{escape(alt, quote=True)}">'
            f"<figcaption>{escape(caption)}</figcaption></figure>")


def _param_row(key: str, p: Interval) -> list[str]:
    """label, unit, value, low, high: each figure to the digit its interval supports."""
    label, unit, scale = PARAM_DISPLAY.get(key, (key, p.unit, 1.0))
    return [escape(label), escape(unit or p.unit or "-"), *round_to_interval(p.value * scale, p.low * scale,
                                                                              p.high * scale)]


def _verdict(a: AnalysisData) -> str:
    cls = "verdict unexplained" if a.unexplained else "verdict"
    text = escape(a.verdict) if a.verdict else "The analysis gives no verdict."
    lines = [f"<p>{text}</p>"]
    if a.unexplained:
        lines.append('<p class="flag">Unexplained: structure remains in the residuals that no candidate cause '
                     "explains.</p>")
    names = ", ".join(escape(c.label) for c in a.causes)
    lines.append(f"<p>Causes named: {names}.</p>" if a.causes else "<p>No cause named.</p>")
    return f'<section aria-labelledby="verdict-h"><h2 id="verdict-h">Verdict</h2><div class="{cls}">' \
           + "".join(lines) + "</div></section>"


KIND_TEXT = {"catalog": "catalog effect", "discovered": "discovered (not in the catalog)",
             "artefact": "measurement artefact"}


def _friction(a: AnalysisData) -> str:
    """Every friction model fitted to the same data (decision 0078)."""
    if not a.friction_table:
        return ""
    rows = [[escape(c) for c in r] for r in friction_rows(a)]
    return ('<section aria-labelledby="friction-h"><h2 id="friction-h">Friction models</h2>'
            f"<p>The data prefer <code>{escape(a.friction_model)}</code>.</p>"
            + table(FRICTION_HEAD, rows) + _friction_loops(a) + "</section>")


def _friction_loops(a: AnalysisData) -> str:
    """Every fitted model's loop at every level against the measured one, and the rms gap."""
    loops = {n: ls for n, ls in a.friction_loops.items() if ls}
    if not loops:
        return ""
    labels = {str(r.get("model")): str(r.get("label") or r.get("model")) for r in a.friction_table}
    ref = loops.get(a.friction_model) or next(iter(loops.values()))
    head = ["friction model"] + [f"{lp.key} ({lp.level_N:.3g} N)" for lp in ref]
    rows = []
    for name, ls in loops.items():
        by_key = {lp.key: lp for lp in ls}
        rows.append([escape(f"{labels.get(name, name)} ({name})" + (" - preferred" if name == a.friction_model else ""))]
                    + [num(by_key[lp.key].rms_difference_N, ".3g") if lp.key in by_key else "-" for lp in ref])
    return ("<h3>Hysteresis loops of each friction model</h3>"
            + figure(analysis_figures.plot_friction_model_loops(loops, a.friction_model, labels),
                     f"Friction force against displacement over one period at {len(ref)} force levels: measured and "
                     f"each fitted friction model ({', '.join(loops)}); the preferred model "
                     f"({a.friction_model}) thick.",
                     "Measured friction P - m a (black, with the preferred model's mass m) and each fitted model's "
                     "prediction of it (its steady periodic friction along the measured displacement, plus the "
                     "inertia by which its own mass differs), at the most compliant step of every force level.")
            + table(head, rows, caption="RMS difference between the measured loop (P - m a with the model's own "
                                        "mass) and the model's friction over one period (N), per force level."))


def _causes(a: AnalysisData) -> str:
    out = ['<section aria-labelledby="causes-h"><h2 id="causes-h">Causes named</h2>']
    if not a.causes:
        out.append("<p>None: " + ("no candidate explains what remains (see the verdict)."
                                  if a.unexplained else "the base model explains the data within the noise.")
                   + "</p>")
        return "".join(out) + "</section>"
    rows = []
    for i, c in enumerate(a.causes, 1):
        size = "<br>".join(_size(k, p) for k, p in c.parameters.items()) or "-"
        gain = (f"{_pct(c.heldout_error_before)} &rarr; {_pct(c.heldout_error_after)}"
                + f"<br>&Delta;BIC = {num(c.delta_bic, '.3g')}")
        rows.append([str(i), escape(KIND_TEXT.get(c.kind, c.kind)),
                     f"{escape(c.label)}<br><code>{escape(c.id)}</code>", escape(c.formula or "-"), size, gain,
                     escape(c.sentence or "")])
    out.append(table(["#", "kind", "cause", "formula", "size (SI units, 95 % interval)",
                       "held-out error before \u2192 after", "in words"], rows,
                      caption="Every cause named, in the order the selection took them; the held-out error is "
                              "the prediction error on force levels left out of the fit."))
    return "".join(out) + "</section>"


def _size(name: str, p: Interval) -> str:
    """'c = 41 N s/m (95 %: 37 to 45)', each figure to the digit its interval supports."""
    unit = "" if p.unit in ("", "1") else f" {p.unit}"
    value, low, high = round_to_interval(p.value, p.low, p.high)
    return escape(f"{name} = {value}{unit}" + (f" (95 %: {low} to {high})" if math.isfinite(p.low) else ""))


def _overview(a: AnalysisData) -> str:
    if not a.steps:
        return ""
    final = "the extended model (solid)" if a.causes else "no cause named: the base model is the final model"
    return figure(analysis_figures.plot_analysis_overview(a.steps),
                   f"Compliance magnitude against frequency for every force level on one axis ({len(a.steps)} "
                   f"steps): measured circles, base Masing model dashed, extended model solid.",
                   f"Measured compliance (circles) against the base Masing model (dashed) and {final}, colour "
                   f"by force level.")


def _restoring(a: AnalysisData) -> str:
    out = ['<section aria-labelledby="rf-h"><h2 id="rf-h">The missing force</h2>']
    rf = a.restoring_force
    if rf is None or rf.x_m.size == 0:
        out.append("<p>No restoring-force samples in the analysis.</p>")
    else:
        out.append(figure(analysis_figures.plot_restoring_force(rf),
                           "Force the base model leaves out (N) against displacement and against velocity, "
                           "points coloured by force level.",
                           "What the base model leaves out, P - m a - F_Masing(x), against displacement (left) "
                           "and velocity (right). A curve in x alone is a stiffness (an S-shape: cubic), a curve "
                           "in v alone is a damping (straight: viscous, parabola-like: quadratic), a shift between "
                           "the two directions is an asymmetry; a cloud around zero is noise."))
    return "".join(out) + "</section>"


def _parameters(a: AnalysisData) -> str:
    out = ['<section aria-labelledby="params-h"><h2 id="params-h">Friction and mass parameters</h2>']
    head = ["parameter", "unit", "value", "95 % low", "95 % high"]
    same = not a.causes and a.parameters == a.base_parameters
    if a.parameters and not same:
        out.append(table(head, [_param_row(k, p) for k, p in a.parameters.items()], {2, 3, 4},
                          "final model" + ("" if a.causes else " (the base model: no cause named)")))
    if a.base_parameters:
        out.append(table(head, [_param_row(k, p) for k, p in a.base_parameters.items()], {2, 3, 4},
                          "base model (Masing friction and mass only)"
                          + (", which is the final model: no cause named" if same else "")))
    if not (a.parameters or a.base_parameters):
        out.append("<p>No parameters in the analysis.</p>")
    fit = [f"base model {num(a.base_reduced_chi2, '.4g')}"]
    if math.isfinite(a.final_reduced_chi2) and a.causes:
        fit.append(f"final model {num(a.final_reduced_chi2, '.4g')}")
    out.append(f"<p>Reduced chi-square: {', '.join(fit)} (about 1 when the residual is the measurement noise)."
               + (f" Held-out error of the base model: {_pct(a.base_heldout_error)}."
                  if math.isfinite(a.base_heldout_error) else "") + "</p>")
    if a.base_diagnostics:
        out.append(_diagnostics(a.base_diagnostics))
    return "".join(out) + "</section>"


def _diagnostics(diag: dict) -> str:
    """Diagnostics as tables: scalars in one table, number lists as rows, lists of records
    as tables, texts as lists."""
    scalars, parts = [], []
    for k, v in diag.items():
        name = escape(str(k).replace("_", " "))
        if isinstance(v, dict):
            sub = {kk: vv for kk, vv in v.items() if not isinstance(vv, dict)}
            rows = [[escape(str(kk).replace("_", " ")), _cell(vv)] for kk, vv in sub.items()]
            parts.append(table(["quantity", "values"], rows, caption=name))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            head = list(dict.fromkeys(kk for x in v for kk in x))
            parts.append(table(head, [[_cell(x.get(h)) for h in head] for x in v], caption=name))
        elif isinstance(v, list) and v and all(isinstance(x, str) for x in v):
            parts.append(f"<p>{name}:</p><ul>" + "".join(f"<li>{escape(x)}</li>" for x in v) + "</ul>")
        else:
            scalars.append([name, _cell(v)])
    if scalars:
        parts.insert(0, table(["quantity", "value"], scalars, caption="diagnostics of the fit"))
    return "".join(parts)


def _cell(v) -> str:
    if isinstance(v, bool) or v is None:
        return escape(str(v))
    if isinstance(v, (int, float)):
        return num(float(v))
    if isinstance(v, (list, tuple)):
        return escape(", ".join(_cell(x) if not isinstance(x, (list, tuple)) else
                                "[" + ", ".join(_cell(y) for y in x) + "]" for x in v)) if v else "none"
    return escape(str(v))


def _nested(v) -> str:
    """Diagnostics of any shape: objects and lists of texts as nested lists, numbers inline."""
    if isinstance(v, dict):
        return "<ul>" + "".join(f"<li><code>{escape(str(k))}</code>: {_nested(x)}</li>" for k, x in v.items()) \
            + "</ul>"
    if isinstance(v, (list, tuple)):
        if not v:
            return "none"
        if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            return escape(", ".join(num(float(x)) for x in v))
        return "<ul>" + "".join(f"<li>{_nested(x)}</li>" for x in v) + "</ul>"
    if isinstance(v, float):
        return num(v)
    return escape(str(v))


def _figures(a: AnalysisData) -> str:
    out = ['<section aria-labelledby="figs-h"><h2 id="figs-h">Model against measurement</h2>']
    final = ("the final model, which adds the causes named (solid)" if a.causes else
             "no cause is named, so the final model is the base model")
    if not a.steps:
        out.append("<p>No per-step data in the analysis: no frequency response or residual figures.</p>")
    else:
        levels = sorted({round(s.level_N, 3) for s in a.steps})
        span = f"{len(a.steps)} steps, force levels {levels[0]:g} to {levels[-1]:g} N" if levels else ""
        for q, what in (("compliance", "displacement over force, x/P"), ("accelerance", "acceleration over "
                                                                                         "force, a/P")):
            out.append(f"<h3>{q.capitalize()}</h3>")
            out.append(figure(analysis_figures.plot_analysis_frf(a.steps, q),
                               f"{q.capitalize()} ({what}) magnitude and phase against frequency for each force "
                               f"level ({span}): measured points, base model dashed, final model solid.",
                               f"First-harmonic {q} ({what}), one row per force level: measured (circles), "
                               f"simulated with the base Masing model (dashed); {final}."))
    if a.loops:
        out.append("<h3>Hysteresis loops</h3>")
        out.append(figure(analysis_figures.plot_analysis_loops(a.loops),
                           f"Friction force against displacement over one period at {len(a.loops)} chosen steps "
                           f"({', '.join(lp.key for lp in a.loops)}): measured, base model and final model.",
                           "Friction force P - m a against displacement over one period: measured (black), base "
                           f"model (dashed); {final}. The loop area is the energy dissipated per cycle."))
    else:
        out.append("<p>No hysteresis loops in the analysis.</p>")
    if a.steps:
        out.append("<h3>Residuals of the base model</h3>")
        out.append(figure(analysis_figures.plot_analysis_residuals(a.steps),
                           "Relative error of the base model's compliance and accelerance against frequency and "
                           "against force level, and the base model's residual per harmonic.",
                           "Where the base model misses: relative error of the first harmonic against frequency "
                           "and force level (filled: compliance, open: accelerance), and the residual per "
                           "harmonic. Structure here (a trend, a band, one harmonic) is what a cause must explain."))
    return "".join(out) + "</section>"


def _candidates(a: AnalysisData) -> str:
    out = ['<section aria-labelledby="cand-h"><h2 id="cand-h">Candidates tried</h2>']
    if not a.candidates:
        out.append("<p>No candidate scores in the analysis.</p>")
    else:
        rounds = any(c.round is not None for c in a.candidates)
        ordered = sorted(a.candidates, key=lambda c: (c.round if c.round is not None else 0, not c.named,
                                                      _sort_key(c.delta_bic)))
        rows = [([str(c.round) if c.round is not None else "-"] if rounds else [])
                + [f"<code>{escape(c.id)}</code>", num(c.delta_bic),
                   _pct(c.heldout_error) if math.isfinite(c.heldout_error) else "not computed",
                   "<strong>yes</strong>" if c.named else "no"] for c in ordered]
        head = (["round"] if rounds else []) + ["candidate", "\u0394BIC", "held-out error", "named"]
        out.append(table(head, rows, {int(rounds) + 1, int(rounds) + 2},
                          "Every candidate extension fitted"
                          + (", round by round of the forward selection (each round against the model so far)"
                             if rounds else "") + "; \u0394BIC against the model without it (negative favours "
                          "the candidate), held-out error of compliance and accelerance on steps left out of the "
                          "fit."))
    return "".join(out) + "</section>"


def _sort_key(v: float) -> float:
    return v if math.isfinite(v) else math.inf


def _steps(a: AnalysisData) -> str:
    out = ['<section aria-labelledby="steps-h"><h2 id="steps-h">Steps</h2>',
           f"<p>{len(a.steps_used)} steps used, {len(a.steps_rejected)} rejected"
           + (f"; {len(a.steps_flagged)} of the used steps flagged" if a.steps_flagged else "") + ".</p>"]
    if a.steps_rejected:
        out.append(table(["step", "reason"], [[escape(s), escape(r)] for s, r in a.steps_rejected],
                          caption="steps rejected, with the reason"))
    if a.steps_flagged:
        out.append(table(["step", "why"], [[escape(s), escape(r)] for s, r in a.steps_flagged],
                          caption="steps used but flagged (artefacts removed, or noisy), with the reason"))
    return "".join(out) + "</section>"


def render_analysis_html(analysis: dict) -> str:
    """The page as a string (see :func:`write_analysis_html`)."""
    a = analysis_data(analysis)
    title = "Model against measurement: analysis" + (f" of {a.source}" if a.source else "")
    meta = ", ".join(x for x in (f"source: {a.source}" if a.source else "",
                                 f"software {a.software_version}" if a.software_version else "") if x)
    problems = ""
    if a.problems:
        items = "".join(f"<li>{escape(p)}</li>" for p in a.problems)
        problems = (f'<section class="problems" aria-labelledby="prob-h"><h2 id="prob-h">Parts of the analysis that '
                    f"could not be shown</h2><ul>{items}</ul></section>")
    body = (f"<header><h1>{escape(title)}</h1>" + (f'<p class="meta">{escape(meta)}</p>' if meta else "")
            + "</header><main>" + _verdict(a) + problems + _overview(a) + _causes(a) + _friction(a) + _restoring(a)
            + '<details id="details"><summary>Details: parameters, figures per level, candidates, diagnostics, '
              "steps</summary>" + _parameters(a) + _figures(a) + _candidates(a) + _steps(a) + "</details></main>")
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{escape(title)}</title><style>{CSS}</style></head>\n<body>{body}</body></html>\n")


def write_analysis_html(analysis: dict, out_path: Path) -> Path:
    """Render the analysis dict (analysis.json's schema) into one self-contained HTML page
    at ``out_path``; returns the path."""
    out_path = Path(out_path)
    text = render_analysis_html(analysis)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_name(out_path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(out_path)
    log.info("analysis page written to %s", out_path)
    return out_path
