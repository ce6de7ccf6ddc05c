"""The analysis page of an imported run (``bench analyze RUN`` on fundamentals, decision 0084):
the verdict's lines, each model's parameters with 95 % intervals and status, the structures'
BIC, what would separate what is open, and per level the measured receptance against each
model's fitted one (magnitude and phase)."""

from __future__ import annotations

import logging
from html import escape
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..words.terminal_data import FUNDAMENTAL_PARAMETERS, said
from ._html import CSS, figure, table
from ._steps import phase_deg

log = logging.getLogger(__name__)

MODEL_STYLE = {"masing": dict(ls="-", lw=1.6, color="C0"), "dahl": dict(ls="--", lw=1.3, color="C1")}


def _complex(pairs) -> np.ndarray:
    return np.array([complex(re, im) for re, im in pairs]) if pairs else np.zeros(0, complex)


def plot_fundamentals(section: dict) -> Figure:
    """Per level (one row): |X/F| and its phase against frequency, measured (markers) and
    each model's fit (lines)."""
    levels = section.get("levels") or []
    unit = {"force": "N", "disp": "m", "accel": "m/s^2"}.get(section.get("level_kind", "force"), "")
    fig = Figure(figsize=(10, 1.0 + 2.4 * max(len(levels), 1)), layout="constrained")
    axes = fig.subplots(max(len(levels), 1), 2, sharex=True, squeeze=False)
    for (ax_mag, ax_ph), lv in zip(axes, levels):
        f = np.asarray(lv["freq_Hz"], float)
        H = _complex(lv["measured"])
        ax_mag.semilogy(f, np.abs(H), ls="none", marker="o", mfc="none", mec="k", ms=6, label="measured")
        ax_ph.plot(f, phase_deg(np.angle(H)), ls="none", marker="o", mfc="none", mec="k", ms=6)
        for name, fit in (lv.get("fitted") or {}).items():
            ff, Hf = np.asarray(fit["freq_Hz"], float), _complex(fit["receptance"])
            style = MODEL_STYLE.get(name, dict(ls=":", lw=1.2))
            ax_mag.semilogy(ff, np.abs(Hf), label=f"{name} fit", **style)
            ax_ph.plot(ff, phase_deg(np.angle(Hf)), **style)
        ax_mag.set_ylabel("|X/F|  (m/N)")
        ax_ph.set_ylabel("phase of X/F  (deg)")
        ax_mag.set_title(f"level {lv['level']:.4g} {unit}", fontsize=10)
        ax_mag.grid(True, alpha=0.3)
        ax_ph.grid(True, alpha=0.3)
    axes[0][0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("frequency  (Hz)")
    return fig


def _parameters(name: str, d: dict) -> str:
    rows = []
    for k, p in d["parameters"].items():
        label, unit, scale = FUNDAMENTAL_PARAMETERS.get(k, (k, p.get("unit", ""), 1.0))
        lo, hi = p.get("low"), p.get("high")
        rows.append([escape(label), escape(unit or "-"), f"{p['value'] * scale:.5g}",
                     f"{lo * scale:.5g}" if lo is not None else "unbounded",
                     f"{hi * scale:.5g}" if hi is not None else "unbounded", escape(said(p["status"]))])
    bic = ", ".join(f"{s} {b:.5g}" for s, b in d["bic_by_structure"].items())
    return table(["parameter", "unit", "value", "95 % low", "95 % high", "status"], rows, numeric={2, 3, 4},
                 caption=(f"{name}: structure {d['structure']}, reduced chi^2 {d['reduced_chi2']:.3g}, "
                          f"BIC {d['bic']:.5g} (by structure: {bic}), loop reach {d['loop_reach']:.2f}"))


def render_fundamentals_html(analysis: dict) -> str:
    section = analysis["fundamentals"]
    title = f"Friction fitted to fundamentals: {analysis.get('source', '')}"
    verdict = "".join(f"<p>{escape(line)}</p>" for line in str(analysis.get("verdict", "")).splitlines())
    seps = section.get("separations") or []
    open_ = ("<ul>" + "".join(f"<li>{escape(said(c))}</li>" for c in seps) + "</ul>") if seps else \
        "<p>Nothing: every parameter of the preferred model is identified and its loops saturate.</p>"
    body = (f"<header><h1>{escape(title)}</h1><p class=\"meta\">software {escape(str(analysis.get('software_version', '')))}"
            f"; imported frequency responses, not a bench measurement</p></header><main>"
            f'<section class="verdict">{verdict}</section>'
            "<h2>Parameters</h2>" + "".join(_parameters(m, d) for m, d in section["models"].items())
            + "<h2>What would separate what is open</h2>" + open_
            + "<h2>Measured and fitted receptance per level</h2>"
            + figure(plot_fundamentals(section), "measured and fitted X/F per level",
                     "markers: the imported fundamentals; lines: each model's harmonic balance at the fitted values")
            + "</main>")
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{escape(title)}</title><style>{CSS}</style></head>\n<body>{body}</body></html>\n")


def write_fundamentals_html(analysis: dict, out_path: Path) -> Path:
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_name(out_path.name + ".tmp")
    tmp.write_text(render_fundamentals_html(analysis), encoding="utf-8")
    tmp.replace(out_path)
    log.info("analysis page written to %s", out_path)
    return out_path
