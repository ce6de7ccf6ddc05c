"""The terminal's words of a plan's and a rig's own rules (decision 0067): what a plan or rig
file breaks across its keys, by code.

``RULE``: a plan's rules across keys and a stored plan's problems
(:class:`bench.config.ConfigRule`), the rig's (:class:`bench.rig_config.RigRule`) and what
``bench paper --rig`` needs of a rig (:class:`bench.rig_model.PaperRule`); a
key's rule has the fields source (the file), table and key where it names one.
:data:`bench.words.terminal.CONFIG` holds them beside the problems of a single key, so a
ConfigError that collects a file's problems says them in order.

``SEQUENCE``: a sequence file's or directory's problems (:class:`bench.sequence.SequenceProblem`,
refusals: :data:`bench.words.terminal.REFUSAL` holds them); ``SEQUENCE_LOG``: what a
sequence logs (:class:`bench.sequence.SequenceLine`).

``PLANNED_STEP``: what chooses a step of ``bench dry-run --steps`` online
(:class:`bench.plan_time.Online`), said after the step (:func:`planned_step` makes the line).

``API``: the Python API's and the pytest plugin's refusals (:class:`bench.api.ApiRefusal`,
:class:`bench.testing.PluginRefusal`, ``bench._Missing``); ``LOG``: what the API logs and the
phase-resonance lock's progress note (:class:`bench.api.ApiLine`,
:class:`bench.backbone.BackboneLine`); ``PLUGIN``: the pytest plugin's options' help
(:class:`bench.testing.PluginOption`); ``NUMBER``: a number that is not a measurement, named
(:class:`bench.numbers.Shown`).

``STUDY``: what ``bench study`` and the batch mode of ``bench analyze`` refuse of their
arguments (:class:`bench.studies.cli.StudyArgs`; :data:`bench.words.terminal.REFUSAL` holds
them); ``STUDY_OUT``: what they print and their progress lines' labels
(:class:`bench.studies.cli.StudyOut`).  (The study modules' own words are
``bench.words.terminal_data.STUDIES``'s.)

``NOTE``: what a range's bounds are (:class:`bench.config.RangeNote`), said after the
bounds of a value out of range (``terminal.CONFIG["out_of_range"]``, its field ``note``: a
:class:`bench.words.Said`).

:func:`where`: a key's place in a plan or rig file (the file, the table and the key), the
start of every line that names a key.
"""

from __future__ import annotations

import math

from . import Said, Words, say

__all__ = ["NOTE", "RULE", "SEQUENCE", "SEQUENCE_LOG", "PLANNED_STEP", "API", "LOG", "PLUGIN", "NUMBER", "STUDY",
           "STUDY_OUT", "line", "option", "planned_step", "range_note", "sequence_line", "shown", "study_out",
           "where"]


def where(source: str, table: str, key: str) -> str:
    """Where in a plan or rig file a key is: the file, the table and the key."""
    return f"{source}: [{table}] {key}"


def range_note(said: Said | None) -> str:
    """A range's note (a :class:`bench.words.Said` of a RangeNote; none: no words)."""
    return say(NOTE, said.code, said.fields) if said else ""


# why a value's range is what it is (bench.config.RangeNote), after its bounds
NOTE: Words = {
    "force_range": lambda low, high: f" (the bench's force range, {low:g}-{high:g} N)",
    "frequency_range": lambda low, high: f" (the bench's frequency range, {low:g}-{high:g} Hz)",
    "phase": lambda response: f" (response = \"{response}\": the phase against the force, degrees)",
    "slope_estimated": lambda: " (0 = estimated; the phase falls with frequency through a resonance)",
    "max_step_default": lambda: " (0 = 5 % of start_Hz)",
    "min_Hz_default": lambda: " (0 = start_Hz / 2, at least 20 Hz)",
    "max_Hz_default": lambda: " (0 = 2 x start_Hz, at most 1000 Hz)",
    "response_level": lambda unit: f" ({unit}, the response fundamental's amplitude)",
}

# what a key (or a table) not used with a procedure is replaced by (ConfigRule.NOT_USED)
_INSTEAD = {"levels_N": " (give [plan.response] levels, response amplitudes)",
            "plan.frequencies": " (the controller finds the frequency; give [plan.backbone] start_Hz)",
            "refine": " (the loop finds the resonance itself)"}


def _not_used(source: str, table: str, key: str | None, procedure: str) -> str:
    said = f"not used with procedure = \"{procedure}\"{_INSTEAD.get(key or table, '')}"
    return f"{source}: [{table}] is {said}" if key is None else f"{where(source, table, key)}: {said}"


def _quoted(word: str) -> str:
    return f'"{word}"'


def _steps(source: str, levels: int, frequencies: int, both: bool, steps: int, most: int) -> str:
    return (f"{source}: [plan] {levels} levels x {frequencies} frequencies{' x 2 directions' if both else ''} = "
            f"{steps} steps; at most {most} (split the test into several plans)")


def _window(source: str, table: str, min_Hz: float, max_Hz: float, start_Hz: float, probe_step: float, low: float,
            high: float) -> str:
    return (f"{where(source, table, 'min_Hz')} / max_Hz: the window {min_Hz:g}-{max_Hz:g} Hz must hold start_Hz "
            f"{start_Hz:g} Hz and its probe blocks (x (1 -+ probe_step {probe_step:g})) inside the bench's range "
            f"{low:g}-{high:g} Hz")


# a plan's rules across keys, a stored plan's problems (bench.config.ConfigRule), the rig's
# (bench.rig_config.RigRule), what `bench paper --rig` needs of a rig (bench.rig_model.PaperRule)
RULE: Words = {
    "window_outside": _window,
    "band_above_lost": lambda source, table, band, lost: (f"{where(source, table, 'phase_band_deg')}: {band:g} deg "
                                                          f"must be below lost_phase_deg {lost:g} deg"),
    "not_used": _not_used,
    "needs_procedure": lambda source, table, procedure: (f"{source}: [{table}] needs procedure = \"{procedure}\" "
                                                         "in [plan]"),
    "repeated_frequencies": lambda source, table: f"{where(source, table, 'frequencies')}: grid has repeated frequencies",
    "too_many_steps": _steps,
    "not_modes": lambda source, table, key, allowed, value: (f"{where(source, table, key)}: must be a non-empty list "
                                                             f"of {', '.join(map(_quoted, allowed))}, got "
                                                             f"{value!r}"),
    "dwell_needs_refine": lambda source, table: (f"{where(source, table, 'dwell_cycles')}: needs refine = true (the "
                                                 "dwell is at the refined resonance)"),
    "above_nyquist": lambda source, table, most, top_Hz, rate_Hz, value: (
        f"{where(source, table, 'harmonics')}: must be <= {most} (below Nyquist at {top_Hz:g} Hz with "
        f"min_sample_rate_Hz = {rate_Hz:g}), got {value}"),
    "no_stored_plan": lambda source, got: f"{source}: no plan stored ([plan] missing or not a table: {got})",
    "not_ascending": lambda source, table, key: (f"{where(source, table, key)}: not in ascending order (the step "
                                                 "keys number them so)"),
    "not_a_stored_plan": lambda source, error, detail: f"{source}: [plan] not a stored plan ({error}: {detail})",
    "bad_skip": lambda source, table, key, got: (f"{where(source, table, key)}: must be a list of [level index, "
                                                 f"frequency index] pairs within the plan, got {got}"),
    "model_not_simulated": lambda source: f"{source}: [rig.model] is only allowed with simulated = true",
    "friction_not_of_model": lambda source, key, model, owners: (
        f"{where(source, 'rig.model', key)}: a parameter of the friction model {' or '.join(map(_quoted, owners))}, "
        f"not of friction = {_quoted(model)} (decision 0075)"),
    "paper_no_model": lambda source: f"{source}: no [rig.model]: bench paper --rig needs a simulated rig's model",
    "paper_no_pitch": lambda source: (f"{source}: [rig.model] has no pitching mode (pitch_inertia_kg_m2 = 0): Figs. 15 "
                                      "and 17 need one"),
}


def _entry(path, entry: int) -> str:
    return f"{path}: [[sequence.entry]] {entry}"


# a sequence file's or directory's problems (bench.sequence.SequenceProblem); what a sequence
# logs (bench.sequence.SequenceLine): SEQUENCE_LOG
SEQUENCE: Words = {
    "sequence_not_found": lambda path: f"{path}: no such sequence file",
    "sequence_not_toml": lambda path, detail: f"{path}: not a readable TOML file ({detail})",
    "sequence_no_table": lambda path: f"{path}: no [sequence] table",
    "sequence_unknown_key": lambda path, key, known: f"{path}: [sequence] {key}: unknown key (known: {', '.join(known)})",
    "sequence_unknown_table": lambda path, table, known: f"{path}: {table}: unknown table (known: {', '.join(known)})",
    "sequence_no_entry": lambda path: f"{path}: [[sequence.entry]]: at least one entry is needed",
    "entry_not_table": lambda path, entry: f"{_entry(path, entry)}: not a table",
    "entry_unknown_key": lambda path, entry, key, known: (f"{_entry(path, entry)}: {key}: unknown key (known: "
                                                          f"{', '.join(known)})"),
    "entry_bad_name": lambda path, entry, name: (f"{_entry(path, entry)}: name: expected a directory name (letters, "
                                                 f"digits, '.', '_', '-'), got {name!r}"),
    "entry_name_used": lambda path, entry, name: f"{_entry(path, entry)}: name: {name!r} is used by an earlier entry",
    "entry_bad_labels": lambda path, entry: (f"{_entry(path, entry)}: labels: expected a table of strings, e.g. "
                                             "{ lubricant = \"ISO VG 32\" }"),
    "entry_no_file": lambda path, entry, key: f"{_entry(path, entry)}: {key}: the path of a {key} file is needed",
    "entry_file": lambda path, entry, key, detail: f"{_entry(path, entry)}: {key}: {detail}",
    "entry_envelope": lambda path, entry, detail: f"{_entry(path, entry)}: {detail}",
    "sequence_several": lambda problems: "\n".join(say(SEQUENCE, p.code, p.fields) for p in problems),
    "not_a_sequence_dir": lambda out, file, detail: f"{out}: not a sequence directory ({file}: {detail})",
    "sequence_out_not_empty": lambda out: (f"{out}: exists and is not empty (a sequence starts in a new directory; "
                                           f"bench resume {out} goes on with one)"),
}

SEQUENCE_LOG: Words = {
    "sequence_entry": lambda sequence, entry, entries, name, resumed: (f"sequence {sequence}: entry {entry}/{entries} "
                                                                       f"{name} ({'resumed' if resumed else 'started'})"),
}


def sequence_line(code: str, **fields) -> str:
    """A sequence's line in words (what it logs)."""
    return say(SEQUENCE_LOG, code, fields)


# what chooses a step of `bench dry-run --steps` online (bench.plan_time.Online), with its fields
PLANNED_STEP: Words = {
    "adaptive": lambda chosen, of, low_Hz, high_Hz: (f"{chosen} of these {of} frequencies {low_Hz:.4g}-{high_Hz:.4g} "
                                                     "Hz, chosen online"),
    "refined": lambda mode, steps, tolerance: (f"{mode} mode: up to {steps} refinement steps, tolerance "
                                               f"{100 * tolerance:g} %"),
    "dwell": lambda mode, cycles: (f"{mode} mode: dwell of {cycles} cycles at its refined resonance (none without a "
                                   "peak inside the grid)"),
}


def planned_step(key: str, level_N: float, freq_Hz: float, online: str, detail) -> str:
    """A line of ``bench dry-run --steps`` (bench.plan_time.PlannedStep): the key, the level,
    the frequency or what chooses it online, and its note."""
    f = (f"{freq_Hz:10.4g} Hz" if math.isfinite(freq_Hz) else "   refined, chosen online"
         if online in ("refined", "dwell") else "          chosen online")
    note = say(PLANNED_STEP, online, detail) if online else ""
    return f"{key:24s} {level_N:8g} N {f}" + (f"  ({note})" if note else "")


# the Python API's and the pytest plugin's refusals (bench.api.ApiRefusal, bench.testing.PluginRefusal,
# bench's missing name: bench._Missing)
API: Words = {
    "api_not_a_plan": lambda got: f"plan: expected a bench Plan or the path of a plan file, got {got}",
    "api_not_a_rig": lambda got: f"rig: expected a bench Rig or the path of a rig file, got {got}",
    "api_bad_label": lambda key: f"labels: a key must be a non-empty string, got {key!r}",
    "api_imported_no_rig": lambda run, file: f"{run}: imported from {file} (bench import): measured by other "
                                             f"software, it has no bench rig; steps(), modes() and report() read it",
    "no_attribute": lambda module, name: f"module {module!r} has no attribute {name!r}",
    "plugin_bad_instrument": lambda call, allowed, got: (f"{call}: instrument must be one of {', '.join(allowed)}, "
                                                         f"got {got!r}"),
    "plugin_not_simulated": lambda rig_file: (f"{rig_file}: not a simulated rig (simulated = true is needed for its "
                                              "[rig.model])"),
    "plugin_unknown_limits": lambda limits: f"with_limits: unknown limit(s) {', '.join(limits)}",
}

# what the API logs (bench.api.ApiLine) and what a phase-resonance run says of its lock in the
# progress line (bench.backbone.BackboneLine)
LOG: Words = {
    "kernels_compiling": lambda: "compiling the simulation kernels (first run only; `make setup` does it ahead)",
    "kernels_compiled": lambda seconds: f"kernels compiled in {seconds:.0f} s",
    "locking": lambda level_N, freq_Hz, phase_error_deg, periods: (f"locking {level_N:g} N: {freq_Hz:.3f} Hz, phase "
                                                                   f"error {phase_error_deg:+.2f} deg, {periods} periods "
                                                                   "in band"),
}

# the pytest plugin's options (bench.testing.PluginOption): their help
PLUGIN: Words = {
    "group": lambda: "the simulated rig of guideway-bench",
    "rig_file": lambda: "rig file (simulated = true) for the sim_rig fixture",
}

# how a number that is not a measurement is shown (bench.numbers.Shown, decision 0042)
NUMBER: Words = {
    "nan": lambda: "not a number",
    "absurd": lambda: "absurd (fit failed)",
}


def line(code: str, **fields) -> str:
    """A line the API logs or the progress line says (LOG), in words."""
    return say(LOG, code, fields)


def shown(code: str) -> str:
    """A number that is not a measurement, named (NUMBER)."""
    return say(NUMBER, code, {})


def option(code: str) -> str:
    """A pytest option's help (PLUGIN)."""
    return say(PLUGIN, code, {})



_SIMULATED = "a Monte-Carlo study needs a simulated rig (simulated = true, [rig.model])"

# what `bench study` and the batch mode of `bench analyze` refuse of their arguments
# (bench.studies.cli.StudyArgs)
STUDY: Words = {
    "study_not_numbers": lambda text: f"expected numbers like '0.5,1.5' or 'start:stop:count', got {text!r}",
    "batch_needs_out": lambda: "analysing several sources needs --out DIR (the summary table and one report per source)",
    "study_mc_rig_not_simulated": lambda path: f"{path}: {_SIMULATED}",
}

# what `bench study` and the batch mode of `bench analyze` print, and their progress lines'
# labels (bench.studies.cli.StudyOut)
STUDY_OUT: Words = {
    "study_figure": lambda path: f"figure: {path}",
    "study_outcome": lambda computed, skipped, failed, seconds, workers, table: (
        f"{computed} tasks computed, {skipped} already done, {failed} failed in {seconds:.1f} s on {workers} "
        f"workers; table: {table}"),
    "study_failed": lambda task, shown, error: f"FAILED {task} {shown}: {error}",
    "batch_summary": lambda parquet, csv, reports: f"summary: {parquet}, {csv}; reports under {reports}/",
    "study_map_label": lambda rows: f"map {rows} rows",
    "study_mc_label": lambda samples: f"identification MC {samples} rigs",
    "batch_label": lambda: "batch analysis",
}


def study_out(code: str, **fields) -> str:
    """A line ``bench study`` prints or a progress line's label (STUDY_OUT), in words."""
    return say(STUDY_OUT, code, fields)
