"""The run report in Markdown: ``<run>/report/report.md`` and its PNG plots.

    <run>/report/report.md                what ran, on what, and what came out
    <run>/report/compliance.png           |X1/F1|, compliance_pp (x_max - x_min)/(2 F1) and phase vs frequency
    <run>/report/accelerance.png          |A1/F1| vs frequency
    <run>/report/quality.png              THD of displacement, force error, residual
    <run>/report/modes.png                each mode's resonance and damping ratio vs force
    <run>/report/model_vs_measurement.png simulated rigs only: the sim/ engine's prediction
    <run>/report/identification.png       online estimates of F_s, x_s, n, m vs steps completed

Works on partial runs (interrupted, aborted): whatever steps are stored are shown.  When
``bench analyze`` has written ``<run>/analysis/analysis.json``, an analysis section gives
its verdict and causes and links to ``analysis.html``.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from procedures.kind import ProcedureKind
from sim.discrepancy.rounding import round_to_interval

from ..words import report as words
from ..words.numbers import number, percent
from . import _figures as figures
from . import _figures_modes as mode_figures
from ._analysis import FRICTION_HEAD, analysis_data, friction_rows
from ._damping import DAMPING_HEADS, DAMPING_KINDS, damping_notes, damping_row
from ._identification import ID_PARAMS, IdentificationData, determined_from, finite, steps_of
from ._overall import overall
from ._refinement import refinement_lines
from ._run import ANALYSIS_HTML, RunData, load_run
from ._steps import UNSETTLED_RESIDUAL, control_error, pp_source

log = logging.getLogger(__name__)


def _num(v, scale: float = 1.0) -> str:
    """The one number formatter (bench.words.numbers): never an overflowed or absurd number."""
    return number(v, scale)


def identification_md(ident: IdentificationData, plotted: bool) -> list[str]:
    md = ["## Identification of F_s, x_s, n and m", ""]
    est = ident.latest
    if ident.failed:
        md += [f"**The final fit failed**: {ident.failed}. No number of it is shown.", ""]
    elif ident.unknown is not None:
        md += [f"run.json holds an identification entry this report cannot read: `{ident.unknown!r}`", ""]
    if est is None:
        md += ["No identification data: this run has no `identification.jsonl` and no `identification` in "
               "`run.json` (run without online identification, or before it existed). "
               "`bench identify <run>` fits the stored steps offline.", ""]
    else:
        md += ["After every step the friction (Masing, F_s, x_s, n) and the moving mass m are refitted to the "
               "harmonics of all steps so far (procedures.online_id, warm-started), with the modes the rig file "
               "declares; at the end a full fit over all steps is stored in run.json; once `bench analyze` has "
               "run, its fit (with the causes it named) is the run's parameter set. One set is shown: the latest "
               "of these." + (" identification.png shows the online estimates." if plotted else ""), ""]
        md += [f"Estimate: {ident.source_of(est)}.", ""]
        effects = (est.get("model") or {}).get("effects") or []
        if effects:
            md += [f"Model: Masing friction and the moving mass with {', '.join(effects)}.", ""]
        if est.get("misfit"):
            md += ["**The model does not fit the data beyond what the noise explains** (reduced chi^2 "
                   f"{_num(est.get('reduced_chi2'))}): the values below are biased by something the model lacks; "
                   "their intervals are widened by sqrt(reduced chi^2) but may miss the truth.", ""]
        head = ["parameter", "unit", "estimate", "95 % low", "95 % high", "rel. std. error"]
        if ident.truth:
            head += ["truth (rig model)", "error", "truth in interval"]
        rows = []
        for p in ID_PARAMS:
            get = {k: (est.get(k) or {}).get(p.key) for k in ("values", "low", "high", "rel_std")}
            row = [p.label, p.unit or "-", number(get["values"], p.scale, ".6g"), number(get["low"], p.scale, ".6g"),
                   number(get["high"], p.scale, ".6g"), _pct(finite(get["rel_std"])).lstrip("+")]
            if ident.truth:
                t, v = ident.truth[p.key], finite(get["values"])
                lo, hi = finite(get["low"]), finite(get["high"])
                row += [number(t, p.scale, ".6g"), _pct(v / t - 1.0),
                        "n/a" if math.isnan(lo) or math.isnan(hi) else ("yes" if lo <= t <= hi else "**no**")]
            rows.append(row)
        md += _table(head, rows) + [""]
        times = [finite(h.get("update_s")) * 1e3 for h in ident.history]
        times = [t for t in times if math.isfinite(t)]
        med = finite((ident.final or {}).get("update_ms_median"))
        mx = finite((ident.final or {}).get("update_ms_max"))
        if math.isnan(med) and times:
            med, mx = float(np.median(times)), float(np.max(times))
        md.append(f"- online update time per step: median {med:.3g} ms, max {mx:.3g} ms"
                  if math.isfinite(med) else "- online update time: n/a (no online updates stored)")
        md.append(f"- reduced chi^2: {_num(est.get('reduced_chi2'))} (about 1 when the residual is the "
                  "measurement noise the fit assumes; intervals are never scaled below it)")
        first = determined_from(ident.history)
        if ident.history:
            md.append(f"- every parameter's relative standard error below 10 % from step {first} of "
                      f"{int(steps_of(ident.history)[-1])} on" if first is not None else
                      "- the last online estimate still has a parameter with a relative standard error of 10 % "
                      "or more")
        warnings = est.get("warnings") or []
        md.append("- fit warnings: " + ("none" if not warnings else ""))
        md += [f"  - {w}" for w in warnings]
    md.append("- identifiability warnings (from the plan and the rig's expected parameters, before the run): "
              + ("none" if not ident.identifiability else ""))
    md += [f"  - {w}" for w in ident.identifiability]
    return md + [""]


# ---------------------------------------------------------------------------- analysis


def analysis_md(run: RunData) -> list[str]:
    """The analysis section, when ``bench analyze`` has written ``<run>/analysis/analysis.json``."""
    if run.analysis is None and run.analysis_error is None:
        return []
    md = ["## Analysis: what the model gets wrong", ""]
    if run.analysis is None:
        return md + [f"The analysis cannot be shown: {run.analysis_error}", ""]
    a = analysis_data(run.analysis)
    page = run.path / ANALYSIS_HTML
    link = f"[analysis.html](../{ANALYSIS_HTML.as_posix()})"
    md += ["> " + (a.verdict or "The analysis gives no verdict."), ""]
    if a.unexplained:
        md += ["**Unexplained:** structure remains in the residuals that no candidate cause explains.", ""]
    if a.causes:
        md += _table(["cause", "parameters (95 %)", "held-out error before", "after", "delta BIC"],
                     [[f"{c.label} (`{c.id}`)",
                       "; ".join(_param_md(k, p) for k, p in c.parameters.items()) or "-",
                       _pct_abs(c.heldout_error_before), _pct_abs(c.heldout_error_after), _num(c.delta_bic)]
                      for c in a.causes])
    else:
        md.append("No cause named.")
    if a.friction_table:
        md += ["", f"Friction model the data prefer: `{a.friction_model}`.", ""]
        md += _table(FRICTION_HEAD, friction_rows(a))
    md += ["", f"- steps used: {len(a.steps_used)}, rejected: {len(a.steps_rejected)}; candidates tried: "
           f"{len(a.candidates)}"]
    md.append(f"- figures, candidate scores and rejected steps: {link}" if page.is_file() else
              f"- the analysis page `{ANALYSIS_HTML}` is missing: `bench analyze {run.path}` writes it")
    md += [f"- could not be read: {p}" for p in a.problems]
    return md + [""]


def _param_md(key: str, p) -> str:
    """'c = 41 N s/m [37, 45]': each figure to the digit its interval supports."""
    v, lo, hi = round_to_interval(p.value, p.low, p.high)
    return f"{key} = {v} {p.unit}".rstrip() + (f" [{lo}, {hi}]" if math.isfinite(p.low) and p.low != p.high else "")


def _pct_abs(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{100 * x:.3g} %"


# ---------------------------------------------------------------------------- markdown


def _pct(x: float) -> str:
    return percent(x)


def _table(header: list[str], rows: list[list]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    out += ["| " + " | ".join(str(c).replace("|", "\\|").replace("\n", " ") for c in row) + " |" for row in rows]
    return out


def _level_starts(history: list[dict], results: list[dict]) -> list[tuple[float, float]]:
    """(steps completed, level N) where the online history first meets each new force level."""
    level_of = {r["key"]: r["target_force_N"] for r in results}
    out, last = [], None
    for x, h in zip(steps_of(history), history):
        level = level_of.get(h.get("step"))
        if level is not None and level != last:
            out.append((float(x), float(level)))
            last = level
    return out


def write_report(run_dir: Path, with_runs=()) -> Path:
    """Write ``<run>/report/`` (plots and report.md); returns the path of report.md.
    ``with_runs``: stepped-sine runs of the same rig whose modes a phase-resonance run's
    backbone figure overlays (``bench report RUN --with OTHER``)."""
    run = load_run(Path(run_dir))
    others = []
    if with_runs:
        from ._modes import run_modes
        others = [run_modes(Path(p), model=False) for p in with_runs]
    out = run.path / "report"
    out.mkdir(exist_ok=True)
    md = _header_md(run)
    if not run.results:
        md += ["## Results", "", "No step was completed, so there is nothing to plot.", ""]
        md += analysis_md(run)
        md += identification_md(run.ident, plotted=False)
    else:
        files = _write_figures(run, out, others)
        md += _results_md(run, out, files)
    path = out / "report.md"
    path.write_text("\n".join(md) + "\n")
    log.info("report written to %s", path)
    return path


def _header_md(run: RunData) -> list[str]:
    meta, plan, rig, levels_N = run.meta, run.plan, run.rig, run.levels_N

    from ._imported import header_md, imported
    if (origin := imported(run)) is not None:
        return header_md(run, origin, _table)
    kind = run.kind
    md = [f"# {kind.label[:1].upper() + kind.label[1:]} report: {plan.get('name', '?')}", ""]
    md += accounting_md(run)
    acc = run.accounting
    recorded = f"{meta.get('steps_done', '?')}/{meta.get('steps_total', '?')}"
    readable = (f"{len(acc.intact)} readable / {acc.planned} planned" if acc and acc.planned is not None
                else f"{len(run.results)} readable / {meta.get('steps_total', '?')} planned")
    md += _table(["", ""], [
        ["run directory", f"`{run.path}`"],
        ["plan", plan.get("name", "?")],
        ["rig", f"{rig.get('name', '?')}{' (simulated)' if rig.get('simulated') else ''}"],
        ["status", f"**{meta.get('status', '?')}**"],
        ["steps", f"{readable} (the run recorded {recorded} done when it ended)"],
        ["started / ended (UTC)", f"{meta.get('started', '?')} / {meta.get('ended', '?')}"],
        ["procedure", _procedure_row(run)],
        [f"levels ({run.level_quantity.name}, {run.level_quantity.unit})", ", ".join(f"{v:g}" for v in levels_N)],
        _frequency_row(run),
    ])
    md += ["", "## Instruments", ""]
    ids = meta.get("identities") or {}
    md += _table(["instrument", "identity"], [[k, ", ".join(f"{a}: {b}" for a, b in v.items())
                                               if isinstance(v, dict) else v] for k, v in ids.items()]) \
        if ids else ["(no identities stored: the instruments were never opened)"]
    md += ["", "## Software", ""]
    md += _table(["package", "version"], [[k, v] for k, v in (meta.get("versions") or {}).items()])
    md += ["", "## Interruptions and aborts", ""]
    notable = run.notable_events
    if notable:
        md += _table(["time (UTC)", "event", "details"],
                     [[e.get("time", ""), e.get("event", ""),
                       "; ".join(f"{k}={v}" for k, v in e.items() if k not in ("time", "event"))] for e in notable])
    else:
        md.append("none (events.jsonl records only start, sensor checks, output off and end)")
    blocks = sum(1 for e in run.events if e.get("event") == "lock_block")
    if blocks:
        md.append(f"\nThe phase-resonance loop's {blocks} controller blocks are progress, not interruptions "
                  "(`lock_block` events in events.jsonl; the watch page showed them as they ran).")
    md.append("")
    return md


def _procedure_row(run: RunData) -> str:
    """What ran and what its controller held, in the plan's words and units."""
    plan, q = run.plan, run.level_quantity
    tol = plan.get("force_tolerance")
    within = f"within {100 * tol:g} %" if isinstance(tol, (int, float)) else "within tolerance"
    if run.kind is ProcedureKind.PHASE_RESONANCE:
        bb = plan.get("backbone") or {}
        response = {"disp": "displacement", "accel": "acceleration"}.get(bb.get("response", ""), "response")
        return (f"phase resonance: at each force level the frequency moved until the {response} "
                f"fundamental's phase against the force's was {bb.get('phase_deg', math.nan):g} deg "
                f"(band +-{bb.get('phase_band_deg', math.nan):g} deg), then held and measured")
    if run.kind is ProcedureKind.RESPONSE_CONTROLLED:
        return (f"response-controlled stepped sine: at each frequency the {q.name} fundamental |{q.symbol}| held "
                f"{within} of the level ({q.unit}); the force it needed is the measurement")
    return f"stepped sine: at each frequency the force fundamental |F1| held {within} of the level (N)"


def _frequency_row(run: RunData) -> list[str]:
    plan = run.plan
    if run.kind is ProcedureKind.PHASE_RESONANCE:
        bb = plan.get("backbone") or {}
        return ["frequency", f"found by the loop, from {bb.get('start_Hz', math.nan):g} Hz inside the window "
                             f"{bb.get('min_Hz', math.nan):g}-{bb.get('max_Hz', math.nan):g} Hz"]
    return ["frequencies", f"{len(plan.get('freqs_Hz', []))} from {min(plan.get('freqs_Hz', [math.nan])):g} to "
                           f"{max(plan.get('freqs_Hz', [math.nan])):g} Hz, direction {plan.get('direction', '?')}"]


FLAG_REASONS = (("noisy displacement", r"noisy: displacement residual"),
                ("unsettled vibration", r"an unsettled (?:[\d.]+ Hz )?vibration"),
                ("unsettled transient", r"an unsettled (?:[\d.]+ Hz )?transient"),
                ("interference line", r"Hz line of .*not locked to the drive"),
                ("offset drift", r"an offset drift"))


def flagged_reasons(attention: list[tuple[str, str, str]]) -> list[tuple[str, int]]:
    """(reason, steps) of the flagged steps, most frequent first; a step with two reasons
    counts under both, one with none of :data:`FLAG_REASONS` under "other"."""
    import re
    counts: dict[str, int] = {}
    for _, status, why in attention:
        if status != "flagged":
            continue
        hits = [name for name, pattern in FLAG_REASONS if re.search(pattern, why)] or ["other"]
        for name in hits:
            counts[name] = counts.get(name, 0) + 1
    return sorted(counts.items(), key=lambda kv: -kv[1])


def accounting_md(run: RunData) -> list[str]:
    """The report's first lines: steps used against the plan, what was skipped and why,
    and one overall line (went well / needs attention, and why).  Used = intact and not
    rejected by the step-quality check (the one check ``bench analyze`` applies); steps
    skipped at run time as the plan allows are named, and are no reason for attention."""
    acc = run.accounting
    if acc is None or acc.planned is None:
        return [f"**{len(run.results)} used / ? planned**: run.json holds no plan this version can read, so the "
                "steps cannot be counted against it.", "", words.overall(overall(run, 0, [])), ""]
    intact = set(acc.intact)
    rejected = {k: why for k, status, why in run.attention if status == "rejected" and k in intact}
    used = [k for k in acc.intact if k not in rejected]
    said = lambda p: words.problem(p.code, p.fields)    # noqa: E731
    skipped = ([f"{p.key} ({said(p)})" for p in acc.skipped]
               + [f"{k} (rejected by the step-quality check: {why})" for k, why in rejected.items()]
               + [f"{p.key} ({said(p)})" for p in acc.missing] + [f"{p.key} (damaged: {said(p)})" for p in acc.damaged])
    extra = len(run.results) - len(acc.intact)
    more = f"; and {len(skipped) - 12} more (`bench check` lists them all)" if len(skipped) > 12 else ""
    md = [f"**{len(used)} used / {acc.planned} planned**; skipped: {'; '.join(skipped[:12]) or 'none'}{more}"
          + (f"; also used: {extra} step{'s' * (extra != 1)} the plan does not know" if extra > 0 else ""), ""]
    md += [words.overall(overall(run, len(rejected), flagged_reasons(run.attention))), ""]
    return md


def _write_figures(run: RunData, out: Path, others=()) -> list[tuple[str, str]]:
    """Save the run's PNG plots into ``out``; returns (file name, what it shows) for each."""
    results, series, title = run.results, run.series, run.title
    colours = figures.level_colours(sorted({s.level_N for s in series}) or [1.0])
    save = figures.save_png
    files: list[tuple[str, str]] = []
    q = run.level_quantity
    save(figures.plot_compliance(series, colours, title, run.legacy, level=q), out / "compliance.png")
    lines = ("each level's locked point, one marker per level (no sweep)" if run.kind is ProcedureKind.PHASE_RESONANCE
             else "solid = up sweep, dashed = down sweep")
    from ._imported import imported
    files.append(("compliance.png", f"compliance vs frequency, log-log, one colour per {q.name} level ({q.unit}), "
                  + (f"{lines}. Top: |X1/F1| from the fundamentals of the harmonic "
                     "fits; middle: compliance_pp = (x_max - x_min)/(2 F1), the seed's Eq. 9 in SI, from "
                     f"{pp_source(results)}" if imported(run) is None else
                     "one line per level. Top: |X1/F1| imported; middle: compliance_pp, here |X1/F1| (the source "
                     "holds fundamentals only)")
                  + "; bottom: phase of X1/F1 in degrees (0 = spring-like, -180 = mass-like)."))
    save(figures.plot_accelerance(series, colours, title, run.rig.get("expected_mass_kg"), level=q),
         out / "accelerance.png")
    files.append(("accelerance.png", "|A1/F1| vs frequency per level; it tends to 1/m above the friction "
                  "resonance (dotted line: the rig file's expected mass)."))
    if imported(run) is None:           # an import has no control error, THD or residual to draw
        save(figures.plot_quality(series, colours, title, run.plan.get("force_tolerance"), level=q), out / "quality.png")
        files.append(("quality.png", f"THD of the displacement (friction nonlinearity), {q.name}-control error "
                      "of the fundamental with the tolerance, and the displacement residual after the harmonic fit "
                      "relative to the fundamental (noise and non-periodic motion such as an unsettled free "
                      f"vibration; steps above {100 * UNSETTLED_RESIDUAL:g} % are flagged)."))

    if run.modes is not None:
        save(mode_figures.plot_fig17([run.modes], f"Modes per {q.name} level: {title}"), out / "modes.png")
        if run.modes.kind == "phase_resonance":
            files.append(("modes.png", "each level's locked point (diamonds): frequency and damping ratio against "
                          "force, no interval."))
        else:
            files.append(("modes.png", "each mode's resonance frequency (feed: the peak of compliance_pp; pitch: the "
                          f"peak of |A1/F1|) and damping ratio against {q.name} ({q.unit}), from a single-mode fit around each peak "
                          "(bars: 95 % intervals; squares: half-power cross-check; triangles: no peak inside the "
                          "grid, the mode lies at or beyond that edge; lines: the rig model's prediction, simulated "
                          "rigs)."))
    if imported(run) is not None and run.modes is not None:     # the backbone of the imported levels
        from ._backbone import plot_backbone
        save(plot_backbone([], {}, title, [run.modes]), out / "backbone.png")
        files.append(("backbone.png", "the imported levels' backbone: each level's resonance and damping ratio "
                      "(single-mode fit, 95 % intervals) against the response amplitude at the fitted peak "
                      "(|X1| = peak compliance x force level; a held displacement as held)."))
    if any("backbone" in r for r in results):
        from ._backbone import plot_backbone
        save(plot_backbone(results, run.rig, title, others), out / "backbone.png")
        files.append(("backbone.png", "phase resonance: natural frequency and damping ratio of each level's "
                      "locked point against its displacement amplitude, over the rig model's backbone (single-"
                      "harmonic balance of the Masing loop, decision 0044; on a rig whose model has a pitching "
                      "mode or other effects, the phase resonance of that full model, decision 0054)"
                      + (f"; squares: the modes of {len(others)} stepped-sine run{'s' * (len(others) != 1)} "
                         "(`--with`) at their peaks' amplitudes, with 95 % intervals." if others else ".")))
    if run.comparison:
        held = run.kind is ProcedureKind.RESPONSE_CONTROLLED
        save(figures.plot_model(series, colours, title, run.comparison, level=q,
                                **({"lines": "model at the held response (the rig's model, every declared "
                                             "effect)"} if held else {})), out / "model_vs_measurement.png")
        files.append(("model_vs_measurement.png", "simulated rig only: the rig model's compliance_pp (its "
                      "file's values and every effect it declares; lines" + (", at each level's held response: "
                                                                            "the force that holds it, found on "
                                                                            "the same model" if held else "")
                      + ") over the measured compliance_pp (markers), and the relative differences from the same "
                      "lines (flagged steps marked)."))
    ident = run.ident
    if ident.history:
        save(figures.plot_identification(ident, title, _level_starts(ident.history, results)),
             out / "identification.png")
        files.append(("identification.png", "online identification: the estimate of F_s, x_s, n and m after "
                      "each step with its 95 % interval (band)"
                      + (", the final fit (star) and the rig model's truth (dashed)" if ident.truth
                         else " and the final fit (star)") + "; dotted: the first step of each force level."))
    return files


def _step_level(r: dict) -> float:
    """The level a step held, in its quantity's unit (a response-controlled step's target
    response; otherwise the force level)."""
    rc = r.get("response_control")
    return float(rc["target"]) if isinstance(rc, dict) and "target" in rc else float(r["target_force_N"])


def _interval(v: float, lo: float, hi: float, scale: float = 1.0) -> str:
    if not math.isfinite(v):
        return "-"
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return f"{v * scale:.4g}"
    a, b, c = round_to_interval(v * scale, lo * scale, hi * scale)     # the digits the interval supports
    return f"{a} [{b}, {c}]"


def modes_md(run: RunData) -> list[str]:
    """The modes per level (sim.modal, decision 0043): each mode's resonance, damping
    ratio and peak with 95 % intervals; a mode at the grid's edge said to be there."""
    md = ["## Modes per level", "",
          f"Each mode's resonance at each {run.level_quantity.name} level ({run.level_quantity.unit}): the feed mode's is the peak of compliance_pp "
          "(x_max - x_min)/(2 F1) (the seed's Eq. 9 and Fig. 13), the pitching mode's the peak of the accelerance "
          "|A1/F1|; both, and the damping ratio, from a single-mode fit (rational fraction with a constant "
          "residual) to the complex FRF around the peak, with 95 % intervals from the fit's covariance; the "
          "half-power damping ratio is the cross-check. A peak at the first or last frequency measured is not a "
          "peak: the mode lies at or beyond it and gets no value. `bench modes` writes the same as CSV, with "
          "other runs beside it."]
    if run.modes is not None and run.modes.kind == "phase_resonance":
        md = ["## Modes per level", "",
              "Phase resonance: each level's point (the backbone section above), the locked frequency as the "
              "resonance and the energy balance's damping ratio; no interval (one point held at one frequency has "
              "no fit whose spread would give one). `bench modes` draws them beside stepped-sine runs."]
    if run.legacy:
        md += ["", f"compliance_pp of this run is from {pp_source(run.results)}."]
    if run.modes is None:
        return md + ["", "No modes: no steps, or the estimate failed (see bench.log).", ""]
    rows = []
    for e, row in zip(run.modes.modes, run.modes.rows()):
        status = e.status if e.ok or e.status == "coarse" else (f"{e.status}: at or {'below' if e.status == 'below grid' else 'above'} "
                                        f"{e.edge_Hz:.4g} Hz" if math.isfinite(e.edge_Hz) else e.status)
        peak = (f"{_interval(e.peak, e.peak_low, e.peak_high)} {'m/N' if e.mode == 'feed' else '1/kg'}"
                if e.ok else "-")
        model = (f"{row['model_resonance_Hz']:.4g}" if math.isfinite(row["model_resonance_Hz"])
                 else row["model_note"] or "-")
        z = damping_row(e)
        rows.append([e.mode, f"{e.level_N:g}", status, _interval(e.resonance_Hz, e.resonance_low_Hz,
                     e.resonance_high_Hz), *(_interval(z[f"damping_{d}_fraction"], z[f"damping_{d}_low_fraction"],
                                                       z[f"damping_{d}_high_fraction"], 100) for d in DAMPING_KINDS),
                     peak, str(e.n_points), model])
    md += [""] + _table(["mode", run.level_quantity.heading, "status", "resonance (Hz) [95 %]",
                         *(f"damping: {DAMPING_HEADS[d]} (%) [95 %]" for d in DAMPING_KINDS),
                         "peak [95 %]", "points", "model resonance (Hz)"], rows) + [""]
    md += damping_notes(run.modes.modes)
    md += [*refinement_lines(run.modes.refinement), ""] if refinement_lines(run.modes.refinement) else []
    for mode in ("feed", "pitch"):
        ms = [e for e in run.modes.modes if e.mode == mode]
        ok = [e for e in ms if e.ok]
        if len(ok) >= 2 and len(ok) == len(ms):
            falls = all(b.resonance_Hz < a.resonance_Hz for a, b in zip(ok, ok[1:]))
            md.append(f"The {mode} mode's resonance {'falls' if falls else 'does not fall monotonically'} as the "
                      f"{run.level_quantity.name} rises ({ok[0].resonance_Hz:.4g} Hz at {run.level(ok[0].level_N)} "
                      f"to {ok[-1].resonance_Hz:.4g} Hz at {run.level(ok[-1].level_N)}; the seed: it falls).")
        elif len(ok) >= 2:
            md.append(f"The {mode} mode lies inside the grid at {len(ok)} of {len(ms)} levels; no trend is drawn "
                      "across the levels where it does not.")
    md.append("")
    return md


def _results_md(run: RunData, out: Path, files: list[tuple[str, str]]) -> list[str]:
    results, legacy, cmp = run.results, run.legacy, run.comparison
    md = [f"Model comparison failed: {run.comparison_error}", ""] if run.comparison_error else []
    md += ["## Files", "", f"All in `{out}/` (raw data: `{run.path}/steps/`; "
           f"CSV and UFF: `bench export {run.path}`).", ""]
    md += _table(["file", "what it shows"], [[f"[{n}]({n})", d] for n, d in files])
    md += [""]
    if any("backbone" in r for r in results):
        from ._backbone import backbone_md
        md += backbone_md(results)

    md += modes_md(run)
    if cmp:
        p = cmp.model
        if p.friction == "masing":
            truth = f"F_s = {p.F_s_N:g} N, x_s = {p.x_s_m:g} m, n = {p.n:g}"
        else:                 # a rival friction model in the plant (decision 0075), its parameters by their keys
            from sim.friction import MODELS
            truth = (f"{MODELS[p.friction].label} friction (friction = \"{p.friction}\"), "
                     + ", ".join(f"{k} = {v:g}" for k, v in p.friction_parameters))
        md += ["## Model vs measurement (simulated rig)", "",
               f"Rig model (true parameters, defaults filled in): {truth}, m = {p.mass_kg:g} kg.", ""]
        md += [f"- {n}" for n in cmp.engine_notes]
        md += ["- relative difference = measured / model - 1 of the stored compliance_pp (from "
               f"{pp_source(results)}), over all steps; max = the value of largest magnitude.",
               f"- flagged: steps whose displacement residual is above {100 * UNSETTLED_RESIDUAL:g} % of the "
               "fundamental (see quality.png and the steps needing attention).", ""]
        md += _table([run.level_quantity.heading, "gamma0", "steps (flagged)", "median", "max", "max, unflagged steps",
                      "notes"],
                     [[f"{c.level_N:g}", f"{c.gamma0:.3g}" if math.isfinite(c.gamma0) else "-", f"{c.n_steps} ({c.n_flagged})", _pct(c.median),
                       _pct(c.max), _pct(c.max_unflagged), "; ".join(c.notes) or "ok"] for c in cmp.levels])
        md.append("")

    from ._imported import imported, steps_md
    if imported(run) is not None:       # fundamentals: bench analyze's fit to them, no identification
        return md + steps_md(run.analysis)
    md += analysis_md(run)
    md += identification_md(run.ident, plotted=bool(run.ident.history))

    md += ["## Steps needing attention", ""]
    failed = [r for r in results if not r.get("force_converged", True)]
    q = run.level_quantity
    if failed:
        md.append(f"{q.name.capitalize()} control did not reach the tolerance:")
        md.append("")
        md += _table(["step", q.heading, "freq (Hz)", f"{q.name} error", "iterations"],
                     [[r["key"], f"{_step_level(r):g}", f"{r['freq_Hz']:g}", _pct(control_error(r)),
                       r["control_iterations"]] for r in failed])
    else:
        md.append(f"{q.name.capitalize()} control reached the tolerance at every step.")
    md += ["", "Step quality, from the time records (`sim.artefacts`: interference lines and offset drift "
           "removed, unsettled transients removed or their first periods dropped, clipping and drop-outs "
           "rejected, periodicity gate, displacement residual above "
           f"{100 * UNSETTLED_RESIDUAL:g} % of the fundamental flagged as noisy). `bench analyze` uses the "
           "same check: it leaves out the rejected steps and uses the flagged ones.", ""]
    if run.attention_error:
        md.append(f"The step quality could not be computed: {run.attention_error}")
    elif run.attention:
        md += _table(["step", "status", "why"],
                     [[k, status, why + (f"; {run.probe.sentence(k)}" if run.probe and k in run.below_resolution
                                         else "")] for k, status, why in run.attention])
    else:
        md.append("Every step is usable: no artefact found and no step flagged.")
    if legacy:
        md += ["", "This run stored compliance_pp from the raw record: at flagged steps (noise or non-periodic "
               "motion) compliance_pp of these steps, from the raw record, is biased high; |X1/F1| much less "
               "affected."]
    md.append("")
    return md
