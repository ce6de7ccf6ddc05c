"""The words of the data's commands (decision 0067): ``bench twin``, ``bench analyze``,
``bench compare``, ``bench export`` and the readers of measured steps (:mod:`bench.sources`),
by code.

``SOURCE``: what is wrong with a source or one of its steps (:class:`bench.sources.SourceProblem`):
a refusal's one-line error, or a step's rejection reason (analysis.json's ``steps_rejected``,
the report, ``bench analyze``'s log).

``NOT_IN_PLANT``: why a cause the analysis named is not in a twin's plant
(:class:`bench.twin.NotInPlant`); ``TWIN_NOTE``: the defaults a twin used and why
(:class:`bench.twin.TwinNote`); ``TWIN``: ``bench twin``'s refusals and warning and the words
of the files it writes (:class:`bench.twin.TwinSaid`).  twin.json and the TOML files store
these words.

``COMPARE``: ``bench compare``'s refusals, the words compare.json stores and its summary
(:class:`bench.compare.CompareSaid`).

``EXPORT``: ``bench export``'s log lines and the ID lines of the universal files it writes
(:class:`bench.export.ExportSaid`); ``ANALYZE``: ``bench analyze``'s
(:class:`bench.analyze.AnalyzeSaid`).

``TOOLS``: the lines of ``bench paper``, ``frf``, ``warmup``, ``twins`` and ``twin``
(:class:`bench.commands.tools.ToolLine`); ``RESULTS``: the lines of ``bench identify``,
``analyze`` and ``compare`` (:class:`bench.commands.results.ResultLine`).

``STUDIES``: the studies' refusals, log lines and the words they store (:mod:`bench.studies`).

A code's words are found by :func:`said` in whichever mapping of this module has them (the
codes are unique across the module); :func:`refused` makes the exception of a refusal.
"""

from __future__ import annotations

from typing import TypeVar

from . import Words, say

E = TypeVar("E", bound=Exception)

# ---------------------------------------------------------------------------- bench.sources

# a UFF58 record's ordinate specific data type (record 8)
_SDT = {13: "force (type 13)", 12: "acceleration (type 12)", 8: "displacement (type 8)"}

SOURCE: Words = {
    "no_such_source": lambda path: f"{path}: no such run directory or file",
    "run_unreadable": lambda path, detail: f"{path}: cannot read the run's metadata or step results: {detail}",
    "damaged": lambda detail: f"damaged: {detail}",
    "raw_unreadable": lambda error, detail: f"raw block unreadable: {error}: {detail}",
    "raw_lacks": lambda missing: f"raw block lacks {', '.join(missing)}",
    "not_uff": lambda path, error, detail: f"{path}: not a readable universal file ({error}: {detail})",
    "not_a_dataset": lambda found: f"pyuff gave a {found}",
    "record_unreadable": lambda record, error, detail: (f"record {record} of the file (dataset 58) cannot be read: "
                                                        f"{error}: {detail}"),
    "no_dataset_58": lambda path, types: f"{path}: no dataset 58 in the file (dataset types: {types})",
    "not_a_quantity": lambda record, sdt: (f"record {record}: ordinate data type {sdt} is not force (13), "
                                           "acceleration (12) or displacement (8)"),
    "two_records": lambda sdt, first, second: f"two {_SDT[sdt]} records (file records {first} and {second})",
    "missing_records": lambda sdts: f"missing record(s): {', '.join(_SDT[t] for t in sdts)}",
    "uneven_spacing": lambda record: f"record {record}: uneven abscissa spacing (need a constant 1/fs)",
    "complex_record": lambda channel: f"{channel} record holds complex values (need a real time record)",
    "lengths_differ": lambda sizes: f"records of different lengths: {sizes}",
    "no_sample_rate": lambda: "no valid abscissa increment (sample rate) on the force record",
    "rates_differ": lambda rates: f"records at different sample rates: { {k: f'{v:.6g} S/s' for k, v in rates.items()} }",
    "not_finite": lambda channel: f"non-finite values in the {channel} record",
    "no_steps_to_identify": lambda path: f"{path}: no steps with force, acceleration and displacement to identify from",
    "not_time_records": lambda path, count: f"{path}: {count} dataset-58 functions not of type 1 (time response) ignored",
    "step_rejected": lambda path, step, reason: f"{path}: step {step} rejected: {reason}",
    "level_held": lambda level, unit, force_N: f"{level:g} {unit} held, {force_N:.3g} N",
    "level_force": lambda force_N: f"{force_N:.3g} N",
}

# ---------------------------------------------------------------------------- bench.twin


def _keys(keys: dict) -> str:
    return ", ".join(f"{k} = {v}" for k, v in keys.items())


# why a cause the analysis named is not in the twin's plant (bench.twin.NotInPlant): twin.json's
# not_in_plant and rig.toml's "NOT IN THE PLANT" lines store these words
NOT_IN_PLANT: Words = {
    "unsettled": lambda: ("the measured rig's own free vibration, not yet settled at the record start: the twin's "
                          "plant rings by itself; settle longer rather than build it in"),
    "free_vibration": lambda freq_Hz, steps: (f"a {freq_Hz:.4g} Hz line in {steps} step(s) only, not mains: the "
                                              "measured rig's own free vibration, not interference (decision 0045); "
                                              "not built into the twin"),
    "no_form": lambda: "no plant or sensor form for this cause (bench.twin.CAUSE_KEYS)",
    "no_parameter": lambda parameter: f"the analysis gives no parameter {parameter!r} for it",
    "not_in_this_plant": lambda absent, keys: f"this version's plant has no {', '.join(absent)} (keys {_keys(keys)})",
    "taken": lambda taken, owners, keys: (f"the plant holds one {', '.join(taken)}, already taken by "
                                          f"{', '.join(owners)} (keys {_keys(keys)})"),
    "not_a_plant": lambda detail: f"its identified values are not a valid plant: {detail}",
    "unexplained": lambda reasons: ("structure the analysis could not name"
                                    + (f": {'; '.join(reasons)}" if reasons else "")),
}

# the defaults a twin used and why (bench.twin.TwinNote): twin.json's notes, rig.toml's "note:" lines
TWIN_NOTE: Words = {
    "levels_out": lambda levels, low, high: f"force levels {levels} N outside the bench's range {low:g}-{high:g} N left out",
    "freqs_out": lambda count, low, high: f"{count} frequencies outside the bench's range {low:g}-{high:g} Hz left out",
    "direction_from_order": lambda direction: f"sweep direction '{direction}' from the order of the steps in the file (no tags)",
    "plan_defaults": lambda: "settle cycles (20) and force control from the plan defaults: a file does not record them",
    "foreign_rig": lambda: ("a foreign file: calibration from bench/defaults/sim_rig.toml (sensitivities lowered so the "
                            "largest reading is at most 5 V), amplifier gain reaching the largest level with 5 V, limits "
                            "twice the plan's envelope and three times the largest measured peaks, drive limit 10 V"),
    "no_drive_voltage": lambda gain: (f"no drive voltage in the source (a file): amp_gain_N_per_V is the calibration's "
                                      f"single gain {gain:g} N/V, an ideal amplifier (no shaker fitted)"),
}


def _header(what: str, p: dict) -> str:
    lines = [f"# {what}, written by `bench twin` (decision record 0026)",
             f"# source: {p['source']} ({p['source_kind']}, {p['steps_used']} steps used, "
             f"{p['steps_rejected']} rejected)",
             f"# source sha256: {p['source_sha256']}",
             f"# analysis: software {p['analysis_software_version'] or 'unknown'}; bench twin: software "
             f"{p['software_version']}" + ("; plain Masing twin (base parameters only)" if p["plain"] else "")]
    return "\n".join(lines) + "\n"


def _rig_comments(parameters: dict, applied: dict, shaker: dict, not_in_plant: list, notes: list) -> str:
    v = parameters
    lines = ["# identified (95 %): " + ", ".join(
        f"{k} {v[k]['value']:.5g} [{v[k]['low']:.5g}, {v[k]['high']:.5g}]" for k in v)]     # the model's own names
    for cid, keys in applied.items():
        lines.append(f"# cause {cid} -> " + ", ".join(f"{k} = {val:.5g}" if isinstance(val, float) else f"{k} = {val}"
                                                       for k, val in keys.items()))
    for name, q in shaker.get("parameters", {}).items() if shaker.get("keys") else ():
        lines.append(f"# shaker {name} {q['value']:.5g} " + (f"[{q['low']:.5g}, {q['high']:.5g}] (95 %)" if q["fitted"]
                                                             else "(fixed at the default)"))
    for item in not_in_plant:
        lines.append(f"# NOT IN THE PLANT: {item['cause']}: {item['reason']}")
    for n in notes:
        lines.append(f"# note: {n}")
    lines.append("# channel noise (force_noise_N, accel_noise_m_s2, disp_noise_m): median per-sample rms of the source")
    return "\n".join(lines) + "\n"


# bench twin's refusals and warning, and the words of the files it writes (bench.twin.TwinSaid)
TWIN: Words = {
    "no_level_or_freq": lambda path, level_low, level_high, freq_low, freq_high: (
        f"{path}: no force level or frequency within the bench's range ({level_low:g}-{level_high:g} N, "
        f"{freq_low:g}-{freq_high:g} Hz)"),
    "no_analysis": lambda path: f"{path}: no analysis.json (run `bench analyze SOURCE` or leave --analysis out)",
    "analysis_not_json": lambda path, detail: f"{path}: not valid JSON: {detail}",
    "analysis_not_object": lambda path: f"{path}: not an analysis.json (a JSON object was expected)",
    "analysis_schema": lambda path, schema: f"{path}: not an analysis.json (schema {schema!r})",
    "no_steps_for_twin": lambda path: f"{path}: no usable steps to build a twin from",
    "analysis_of_another": lambda analysis, of, source: f"the analysis in {analysis} is of {of}, not of {source}",
    "no_toml_form": lambda name: f"no TOML form for {name}",
    "rig_name": lambda source, plain: f"twin of {source}" + (" (plain Masing)" if plain else ""),
    "rig_notes": lambda source, rig: f"bench twin of {source}" + (f" (rig '{rig}')" if rig is not None
                                                                  else " (foreign file)"),
    "plan_name": lambda name: f"twin of {name}",
    "rig_label": lambda: "twin rig.toml",
    "plan_label": lambda: "twin plan.toml",
    "rig_header": lambda provenance: _header("Simulated twin of a measured rig", provenance),
    "plan_header": lambda provenance: _header("The source's plan, to run on its twin", provenance),
    "rig_comments": _rig_comments,
}

# ---------------------------------------------------------------------------- bench.compare


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * x:.3g} %"


def _coverage(cov: dict) -> list[str]:
    """The coverage in words: how many of the reference's usable steps were compared, which
    were not and why, and whether they are the resonance."""
    lines = [f"coverage: {cov['matched']} of the reference's {cov['reference_steps']} usable steps matched "
             f"({100 * cov['fraction']:.3g} %; needed {100 * cov['min_coverage']:.3g} %)"]
    if cov["unmatched"]:
        res = cov["resonance_unmatched"]
        if res:
            lines.append(f"{len(res)} of the unmatched steps are at the resonance (within the half-power band of "
                         f"their level's peak compliance), where the rig differs most: {', '.join(res)}")
        for m in cov["unmatched"]:
            lines.append(f"  unmatched {m['step']} ({m.get('level') or format(m['level_N'], '.3g') + ' N'}, "
                         f"{m['freq_Hz']:.4g} Hz"
                         f"{', ' + m['direction'] if m['direction'] else ''}"
                         f"{', resonance' if m['resonance'] else ''}): {m['why']}")
    return lines


def _summary(result: dict, quantities: tuple, judged_noise: float) -> str:
    o = result["overall"]
    cov = result["coverage"]
    by = (result.get("matching") or {}).get("level")
    lines = [f"{result['matched']} steps matched{' by ' + by if by else ''} ({len(result['unmatched_reference'])} of "
             f"the reference and {len(result['unmatched_other'])} of the other unmatched)"] + _coverage(cov)
    for q in quantities:
        x = o[q]
        lines.append(f"{q:>11}: rms difference {_pct(x['rms_rel_diff'])} over the {x['judged']} steps precise enough "
                     f"to judge ({_pct(x['rms_rel_diff_all'])} over all; magnitude {x['rms_mag_diff_pct']:.3g} %, "
                     f"phase {x['rms_phase_diff_deg']:.3g} deg; {x['rms_noise_units']:.3g} x noise), "
                     f"largest judged {_pct(x['max_rel_diff'])}")
    if o["rms_rel_diff"] is None:
        lines.append(f"OUTSIDE: no step is precise enough to judge a difference of {100 * result['tolerance']:g} % "
                     f"(its noise alone would give more than {100 * judged_noise * result['tolerance']:g} %)")
    else:
        lines.append(f"{'within' if o['within_tolerance'] else 'OUTSIDE'} the tolerance of "
                     f"{100 * result['tolerance']:g} % (larger rms {_pct(o['rms_rel_diff'])})")
    if not cov["covered"]:
        lines.append(f"NOT PASSED: only {100 * cov['fraction']:.3g} % of the reference's usable steps were compared "
                     f"(--min-coverage {cov['min_coverage']:g})"
                     + (", the resonance among the missing" if cov["resonance_unmatched"] else ""))
    return "\n".join(lines) + "\n"


# bench compare's refusals, the words compare.json stores (the level steps were matched by, why
# a step is unmatched) and its summary (bench.compare.CompareSaid)
COMPARE: Words = {
    "bad_tolerance": lambda value: f"--tolerance must be a positive fraction (0.02 = 2 %), got {value!r}",
    "bad_min_coverage": lambda value: (f"--min-coverage must be a fraction in (0, 1] (1 = every usable step of the "
                                       f"reference matched), got {value!r}"),
    "no_steps_to_compare": lambda path: f"{path}: no usable steps to compare",
    "no_match": lambda reference, other, level_pct, freq_pct: (
        f"no step of {reference} matches one of {other} in level (the force, or the response both held; within "
        f"{level_pct:g} %), frequency (within {freq_pct:g} %) and direction"),
    "by_response": lambda unit: f"the response both held ({unit})",
    "by_force": lambda: "the force (N)",
    "rejected_in_other": lambda step, reason: f"rejected in the other ({step}): {reason}",
    "not_in_other": lambda: "not in the other",
    "summary": _summary,
}

# ---------------------------------------------------------------------------- bench.export, bench.export_modes


def _labels(labels: dict) -> str:
    return "labels: " + (", ".join(f"{k}={v}" for k, v in labels.items()) if labels else "none")


_FRF = {"X": ("compliance X/F", "X1/F1, probe"), "A": ("accelerance A/F", "A1/F1, drive point")}

# bench export's log lines and the words of the ID lines of the universal files it writes
# (bench.export.ExportSaid)
EXPORT: Words = {
    "one_step": lambda level, direction, key: (f"export: level {level} {direction} has one readable step ({key}): "
                                               "no FRF record in frf.uff; it is in steps.csv"),
    "phase_resonance": lambda run: (f"{run}: phase resonance: one locked point per level, no FRF along frequency, so "
                                    "no frf.uff; the points are in steps.csv and modes.uff"),
    "no_frf": lambda run: f"{run}: no level has two readable steps, so no frf.uff",
    "no_steps_to_export": lambda run: f"{run}: no completed steps; only the CSV header was written",
    "id_too_long": lambda line: f"UFF ID line longer than 80 characters: {line!r}",
    "frf_id1": lambda kind, level, direction: f"{_FRF[kind][0]}, {level}, {direction} sweep",
    "frf_id2": lambda plan, rig, origin="": f"imported from {origin}" if origin else f"{plan} on {rig}",
    "frf_id5": lambda kind, quantity, labels: f"{_FRF[kind][1]}, {quantity} amplitude held at the level; {_labels(labels)}",
    "time_id1": lambda channel, unit, key: f"{channel} ({unit}), step {key}",
    "mode_id1": lambda mode, level_N, status, resonance_Hz, curve: (
        f"{mode} mode {level_N:g} N ({status}): resonance {resonance_Hz:.6g} Hz, peak of {curve}"),
    "mode_id2": lambda fit: f"freq = fit's undamped natural frequency (Hz); zeta fit %: {fit}",
    "mode_id3": lambda balance, half_power: f"zeta % energy balance {balance} half-power {half_power}",
    "mode_id5": lambda run, mass: f"run {run}; modal mass kg: {mass or 'unknown'}",
}

# ---------------------------------------------------------------------------- bench.analyze

# bench analyze's refusal and log lines (bench.analyze.AnalyzeSaid)
ANALYZE: Words = {
    "no_steps_to_analyse": lambda path, rejected: (f"{path}: no usable steps ({len(rejected)} rejected"
                                                   + (f", first: {rejected[0]['step']}: {rejected[0]['reason']}"
                                                      if rejected else "") + ")"),
    "analysing": lambda steps, path, rejected: f"analysing {steps} steps of {path} ({rejected} rejected)",
    "artefact": lambda sentence: f"artefact: {sentence}",
    "verdict": lambda verdict: f"verdict: {verdict}",
    "imported_fundamentals": lambda run, path: (f"{run}: imported from {path}: the run holds fundamentals only, no "
                                                "time records to identify from (bench analyze fits the friction to "
                                                "the fundamentals; bench modes and bench report read it)"),
    "analysing_fundamentals": lambda levels, points, path: (f"fitting the friction models to the fundamentals of {path} "
                                                            f"({levels} levels, {points} points)"),
}

# ---------------------------------------------------------------------------- bench.fundamentals

# the parameters' names and display units (the terminal's and the analysis page's)
FUNDAMENTAL_PARAMETERS = {"F_s_N": ("F_s", "N", 1.0), "x_s_m": ("x_s", "um", 1e6), "n": ("n", "", 1.0),
                          "mass_kg": ("m", "kg", 1.0), "F_c_N": ("F_c", "N", 1.0),
                          "sigma_N_per_m": ("sigma", "N/um", 1e-6), "exponent": ("exponent", "", 1.0),
                          "mode_mass_kg": ("m_r", "kg", 1.0), "mode_frequency_Hz": ("f_r", "Hz", 1.0),
                          "mode_damping_ratio": ("zeta_r", "", 1.0), "spring_N_per_m": ("k", "N/m", 1.0),
                          "dashpot_N_s_per_m": ("c", "N s/m", 1.0)}


def _estimate_words(name: str, p: dict) -> str:
    label, unit, scale = FUNDAMENTAL_PARAMETERS.get(name, (name, p.get("unit", ""), 1.0))
    lo, hi = p.get("low"), p.get("high")
    span = (f" [{lo * scale:.4g}, {hi * scale:.4g}]" if lo is not None and hi is not None else " [unbounded]")
    return f"{label} {p['value'] * scale:.4g}{' ' + unit if unit else ''}{span} {said(p['status'])}"


def _interval(name: str, p: dict) -> str:
    """'F_c 10 N [9.99, 10.01]': a parameter of analysis.json with its 95 % interval."""
    label, unit, scale = FUNDAMENTAL_PARAMETERS.get(name, (name, p.get("unit", ""), 1.0))
    unit = "" if unit in ("", "1") else " " + unit
    lo, hi = p.get("low"), p.get("high")
    span = f" [{lo * scale:.4g}, {hi * scale:.4g}]" if lo is not None and hi is not None else " [unbounded]"
    return f"{label} {p['value'] * scale:.4g}{unit}{span}"


# the codes of the fit to fundamentals (sim.describing_fit.ParameterStatus, Separation) and the lines of its
# verdict (bench.fundamentals.FundamentalLine)
FUNDAMENTALS: Words = {
    "identified": lambda: "identified",
    "degenerate": lambda: "degenerate",
    "fixed": lambda: "fixed",
    "harmonics": lambda: ("the upper harmonics of time records (the loop's shape, which the fundamental does not see: "
                          "record time histories, bench run or UFF58 time records, and bench analyze them)"),
    "level_at_saturation": lambda: "a level at or above the friction level (a loop that saturates)",
    "frequencies_across_resonance": lambda: "frequencies across and above the friction resonance (the mass)",
    "frequencies_at_mode": lambda: "frequencies around the structure's mode",
    "fundamentals_model": lambda model, structure, reduced_chi2, bic, parameters: (
        f"{model} (structure: {structure}): " + ", ".join(_estimate_words(k, p) for k, p in parameters.items())
        + f"; reduced chi^2 {reduced_chi2:.3g}, BIC {bic:.4g}"),
    "fundamentals_failed": lambda model, error: f"{model}: the fit failed ({error}); not compared",
    "fundamentals_preferred": lambda model, gap: (f"preferred by BIC: {model}" +
                                                  (f" (the next model's BIC {gap:.4g} higher)" if gap is not None
                                                   else "")),
    "fundamentals_open": lambda degenerate, separations: (
        ("identified: every parameter (95 % intervals within a factor 2)" if not degenerate else
         "not identified by the fundamentals: " + ", ".join(FUNDAMENTAL_PARAMETERS.get(d, (d,))[0] for d in degenerate))
        + ("; what would separate what is open: " + "; ".join(said(c) for c in separations) if separations else "")),
    "fundamentals_noise": lambda rule, sigma: (
        f"noise: {100 * sigma:.3g} % of |X/F| per real and imaginary part, "
        + ("the mapping's noise" if rule == "mapping" else
           "from the residuals of the Masing fit without a structure (the FRF file gives none)")),
}


def fundamentals_verdict(section: dict) -> str:
    """The verdict's lines of a fit to fundamentals (analysis.json's ``fundamentals``): one per
    model, the preferred model, what is open and what would separate it, the noise used."""
    models = section["models"]
    best = section["preferred"]
    lines = [said("fundamentals_model", model=m, structure=d["structure"], reduced_chi2=d["reduced_chi2"],
                  bic=d["bic"], parameters=d["parameters"]) for m, d in models.items()]
    lines += [said("fundamentals_failed", model=m, error=e) for m, e in (section.get("failed") or {}).items()]
    others = [d["bic"] for m, d in models.items() if m != best]
    lines.append(said("fundamentals_preferred", model=best, gap=min(others) - models[best]["bic"] if others else None))
    lines.append(said("fundamentals_open", degenerate=models[best]["degenerate"], separations=section["separations"]))
    lines.append(said("fundamentals_noise", rule=section["noise"]["rule"], sigma=section["noise"]["relative_sigma"]))
    return "\n".join(lines)


# ---------------------------------------------------------------------------- bench.commands.tools


def _twin_applied(cause: str, keys: dict) -> str:
    return f"cause {cause} -> " + ", ".join(f"{k} = {x:.4g}" if isinstance(x, float) else f"{k} = {x}"
                                            for k, x in keys.items())


# the lines of `bench paper`, `frf`, `warmup`, `twins` and `twin` (bench.commands.tools.ToolLine)
TOOLS: Words = {
    "paper_progress": lambda: "paper figures",
    "paper_wrote": lambda count, out: f"wrote {count} files to {out}/ (start with {out}/README.md)",
    "bad_points": lambda points: f"--points must be >= 1, got {points}",
    "frf_progress": lambda gamma0, n, engine: f"FRF gamma0={gamma0} n={n} ({engine})",
    "frf_peak": lambda kind, beta, G: f"# {kind} resonance: beta={beta:.4f} G={G:.4f}",
    "compiling": lambda: "compiling the simulation kernels (once per machine and change of sim/) ...",
    "compiled": lambda seconds: f"kernels compiled and cached in {seconds:.0f} s",
    "not_simulated": lambda rig: f"{rig}: not a simulated rig (simulated = true is needed)",
    "stopping_twins": lambda: "stopping twins",
    "twin_parameters": lambda parameters: "twin: " + ", ".join(f"{k} {parameters[k]['value']:.4g}"
                                                              for k in parameters),
    "twin_applied": _twin_applied,
    "twin_not_in_plant": lambda cause, reason: f"not in the plant: {cause}: {reason}",
    "twin_wrote": lambda rig, plan, twin: f"wrote {rig}, {plan} and {twin}",
    "twin_run_it": lambda rig, plan: f"run it: bench run --plan {plan} --rig {rig} --out RUN",
}

# ---------------------------------------------------------------------------- bench.commands.results

# the lines of `bench identify`, `analyze` and `compare` (bench.commands.results.ResultLine)
RESULTS: Words = {
    "no_source": lambda: "no such file or directory (expected a run directory or a UFF58 file)",
    "step_rejected_here": lambda step, reason: f"step {step} rejected: {reason}",
    "analysis_unreadable": lambda path, detail: (f"warning: {path} cannot be read ({detail}); the analysis' causes "
                                                 "are not in the model"),
    "model": lambda effects, source, named: (f"model: Masing friction and the moving mass"
                                             f"{' with ' + ', '.join(effects) if effects else ''} "
                                             f"({source if named else 'final fit'})"),
    "table_head": lambda: f"{'parameter':>10} {'estimate':>12} {'95 % interval':>28}",
    "fit": lambda steps, rejected, chi2: f"{steps} steps ({rejected} rejected), reduced chi^2 {chi2}",
    "warning": lambda text: f"warning: {text}",
    "analyzed": lambda causes, unexplained, friction_model, out: (
        f"friction model: {friction_model}; causes: {', '.join(causes) or 'none'}; "
        f"unexplained: {'yes' if unexplained else 'no'}; written to {out}"),
    "friction_preferred": lambda model, label, parameters, analysis: (
        f"friction model the data prefer: {label} ({model}), by `bench analyze` ({analysis})"
        + (": " + "; ".join(_interval(k, p) for k, p in parameters.items()) if model != "masing" and parameters
           else "")
        + ("; the estimate below is the Masing model's" if model != "masing" else "")),
    "friction_not_compared": lambda source: (f"friction model: Masing, not compared with the rival models "
                                             f"(`bench analyze {source}` fits them and names the one the data prefer)"),
    "compared": lambda out: f"written to {out}/compare.json and compare.html",
    "fundamentals_written": lambda out: f"the fit to fundamentals written to {out}/analysis.json and analysis.html",
}

# ---------------------------------------------------------------------------- bench.studies

# the studies' refusals, log lines and words they store (bench.studies: StudiesSaid, engine.StudySaid,
# maps.MapRefusal, montecarlo.McRefusal, batch.BatchSaid)
STUDIES: Words = {
    "no_attribute": lambda module, name: f"module {module!r} has no attribute {name!r}",
    "version": lambda version: f"guideway-bench {version}",
    "not_installed": lambda: "guideway-bench (not installed)",
    "no_scheduler": lambda scheduler, detail: f"cannot reach the dask scheduler at {scheduler}: {detail}",
    "same_inputs": lambda kind: f"{kind} study: two tasks have the same inputs",
    "different_study": lambda path, kind, seed, spec: (f"{path} holds a different study ({kind}, seed {seed}, "
                                                       f"spec {spec}); use a new directory or the same inputs to "
                                                       "resume it"),
    "already_done": lambda path, done, total, todo: f"{path}: {done} of {total} tasks already done, {todo} to compute",
    "resumed": lambda: "(resumed)",
    "failed_so_far": lambda count: f"{count} failed",
    "task_failed": lambda key, inputs, error: f"task {key} failed with inputs {inputs}: {error}",
    "cancelling": lambda path, count: f"{path}: cancelling {count} pending tasks",
    "no_n_or_gamma0": lambda: "a map needs at least one n and one gamma0",
    "bad_n": lambda n: f"n must be > 0 and != 1, got {n!r}",
    "bad_gamma0": lambda gamma0: f"gamma0 must lie in (0, 1) (above 1 the carriage rolls away), got {gamma0!r}",
    "bad_beta_range": lambda low, high: f"need 0 < beta_min < beta_max, got {low!r}, {high!r}",
    "bad_beta_points": lambda points: f"beta_points must be >= 3, got {points!r}",
    "bad_engine": lambda engine: f"engine must be 'shooting' or 'rk4', got {engine!r}",
    "no_peaks": lambda n, gamma0, detail: f"n={n:g} gamma0={gamma0:g}: no peaks ({detail})",
    "bad_samples": lambda samples: f"samples must be >= 1, got {samples!r}",
    "bad_spread": lambda spread: f"spread is a factor >= 1, got {spread!r}",
    "negative_spread": lambda: "n_spread and noise_scale must be >= 0",
    "not_simulated_rig": lambda: "a Monte-Carlo study needs a simulated rig (simulated = true, [rig.model])",
    "no_n_drawn": lambda n, spread: f"expected n {n} +- {spread} leaves no n > 0.2 away from 1",
    "no_such_path": lambda path: f"{path}: no such file or directory",
    "no_sources_in": lambda path: f"{path}: no run directories (run.json) or UFF58 files (.uff, .unv) in it",
    "no_modes": lambda path, detail: f"{path}: modes could not be estimated: {detail}",
}


# ---------------------------------------------------------------------------- bench.frf_import, bench.frf_run


def _where(where) -> str:
    what, value = where
    return f"{what} {value:g}" if isinstance(value, float) else f"{what} {value}"


_LEVEL_KIND = {"force": "force amplitude held (N)", "disp": "displacement amplitude held (m)",
               "accel": "acceleration amplitude held (m/s^2)"}
_RESPONSE = {"disp": "compliance X/F", "vel": "mobility V/F", "accel": "accelerance A/F"}

# bench import's problems, one line each (bench.frf_import.ImportProblem), and its lines (bench.frf_run.ImportLine)
IMPORT: Words = {
    "import_unknown_format": lambda path, suffix: (f"{path}: not a format bench import reads ({suffix or 'no suffix'}; "
                                                   "it reads .uff/.unv (UFF58 FRF records), .csv and .mat)"),
    "import_mat_not_numbers": lambda path, where, cls: (f"{path}: {where} is a MATLAB {cls} value, where bench import "
                                                        "reads numbers, strings, structs and cells"),
    "import_unreadable": lambda path, error, detail: f"{path}: cannot be read ({error}: {detail})",
    "import_mapping_key": lambda path, key: f"{path}: [{key}] is not a key of the mapping (docs/howto/measured-frfs.md)",
    "import_mapping_value": lambda path, key, got, allowed: f"{path}: {key} = {got!r}; allowed: {allowed}",
    "import_field_missing": lambda path, field: (f"{path}: {field}: not in the file and not in the mapping "
                                                 f"(give it in --mapping, [import.fields] / [import.units] / [import])"),
    "import_column_absent": lambda path, field, name: f"{path}: {field}: the mapping names {name!r}, which the file lacks",
    "import_unit_unknown": lambda path, field, unit, allowed: (f"{path}: {field}: unit {unit!r} is not one bench import "
                                                               f"knows ({', '.join(allowed)})"),
    "import_unit_kind": lambda path, field, unit, kind, expected: (f"{path}: {field}: unit {unit!r} is of a "
                                                                   f"{_RESPONSE.get(kind, kind)}, not of the "
                                                                   f"{_RESPONSE.get(expected, expected)} declared"),
    "import_not_a_number": lambda path, where, field, got: f"{path}: {_where(where)}, {field}: {got!r} is not a number",
    "import_not_finite": lambda path, where, field, count: f"{path}: {_where(where)}: {count} {field} value(s) NaN or infinite",
    "import_not_increasing": lambda path, where, at_Hz, after_Hz: (f"{path}: {_where(where)}: frequencies not increasing "
                                                                   f"({at_Hz:.6g} Hz after {after_Hz:.6g} Hz)"),
    "import_too_few": lambda path, where, points, need: (f"{path}: {_where(where)}: {points} frequencies; a mode fit "
                                                         f"needs at least {need}"),
    "import_no_level": lambda path, where: (f"{path}: {_where(where)}: no level (no bench tag; give level_from and "
                                            "[import.levels] or level_pattern in --mapping)"),
    "import_no_frf": lambda path: f"{path}: no frequency response in the file",
    "import_record_kind": lambda path, where, sdt: (f"{path}: {_where(where)}: an FRF of ordinate data type {sdt}, not "
                                                    "displacement (8), velocity (11) or acceleration (12)"),
    "import_record_unreadable": lambda path, where, detail: f"{path}: {_where(where)}: {detail}",
    "import_points": lambda path, where, nodes: (f"{path}: {_where(where)}: FRFs at nodes {nodes} and none at the "
                                                 "reference (drive point); choose one with point = NODE in --mapping"),
    "import_force_grid": lambda path, where: f"{path}: {_where(where)}: force spectrum on other frequencies than its FRF",
    "import_plan_range": lambda path, detail: f"{path}: outside what a run directory holds: {detail}",
    "import_out_not_new": lambda path: f"{path}: exists and is not empty (bench import writes a new run directory)",
    "imported": lambda path, out, levels, points, kind, response: (
        f"imported from {path}: {levels} levels ({_LEVEL_KIND.get(kind, kind)}), {points} frequencies, "
        f"{_RESPONSE.get(response, response)}; written to {out} (bench modes / report / export read it)"),
}


# the mappings :func:`said` and :func:`refused` look a code up in (by name: a reworded mapping is found)
_MAPPINGS = ("SOURCE", "NOT_IN_PLANT", "TWIN_NOTE", "TWIN", "COMPARE", "EXPORT", "ANALYZE", "TOOLS", "RESULTS", "STUDIES", "IMPORT",
             "FUNDAMENTALS")


def said(code: str, **fields) -> str:
    """The words of ``code`` (a code of this module's mappings) with ``fields``."""
    words = next((w for w in (globals()[n] for n in _MAPPINGS) if str(code) in w), {})
    return say(words, code, fields)


def refused(exc: type[E], code: str, **fields) -> E:
    """The exception ``exc`` of a refusal: its message the words of ``code`` with ``fields``,
    ``code`` and ``fields`` kept on it (what a caller decides by)."""
    e = exc(said(code, **fields))
    e.code, e.fields = code, fields         # type: ignore[attr-defined]
    return e
