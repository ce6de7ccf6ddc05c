"""The terminal's words (decision 0067): what ``bench`` prints and logs, by code.

``PROBLEM``: a run directory's problems (:class:`bench.step_files.Problem`, the fields of a
:class:`~bench.step_files.StepProblem`); ``bench check`` prints them, a damaged step's error
says them.  ``detail`` fields hold the words of a reader below (a file too large, a step's
fields, run.json's own error), made where that reader decides.

``CHECK``: the lines ``bench check`` prints besides each problem's
(:class:`bench.commands.results.CheckLine`).

``REFUSAL``: the one-line errors of a refusal (:class:`bench.runlock.LockRefusal`,
:class:`bench.demo.OutDirRefusal`, :class:`bench.storage.RunDirRefusal`), made by
:func:`refused` into the exception the command raises; the exception keeps the code and
the fields.
"""

from __future__ import annotations

from typing import TypeVar

from . import Words, say
from .terminal_config import API, RULE, SEQUENCE, STUDY, range_note, where

__all__ = ["CHECK", "CONFIG", "MODES", "PROBLEM", "PROMISE", "REFUSAL", "RUN", "Words", "problem", "promised", "refused", "say"]

E = TypeVar("E", bound=Exception)

# which of a step's two files are absent (StepProblem.files)
_PAIR = {(".json", ".npz"): "neither .json nor .npz", (".json",): "no .json (only the .npz)",
         (".npz",): "no .npz (only the .json)"}
_FILE = {".json": "the step's result file", ".npz": "the step's raw block; its result file is there"}


def _owed_refinement(mode: str, force_N: float, done: int, most: int, swept: bool, dwell: bool) -> str:
    return (f"the {mode} refinement at {force_N:g} N has not ended"
            + (f" ({done} of at most {most} steps measured)" if swept else " (after the level's sweep)")
            + (", nor its dwell" if dwell else ""))


PROBLEM: Words = {
    "missing_pair": lambda files: f"missing: {_PAIR[tuple(files)]}",
    "missing_file": lambda file: f"missing ({_FILE[file]})",
    "unreadable": lambda detail: detail,
    "os_error": lambda strerror: f"unreadable ({strerror})",
    "empty": lambda: "empty (truncated to 0 bytes)",
    "not_utf8": lambda byte: f"not text (byte {byte} is not UTF-8)",
    "not_json": lambda cut, msg, line, column, chars: (f"{'truncated: ' if cut else ''}not valid JSON ({msg} at line "
                                                       f"{line} column {column}, file of {chars} characters)"),
    "too_deep": lambda: "not a step result (nested too deeply)",
    "not_object": lambda found: f"not a step result (a JSON object was expected, found {found})",
    "json_checksum": lambda: "checksum mismatch: the content differs from what was written",
    "wrong_key": lambda inside, key: f"the result inside is for step {inside!r}, not {key!r}",
    "bad_fields": lambda detail: detail,
    "not_npz": lambda: "not a readable .npz (truncated or overwritten?)",
    "npz_size": lambda size, written: f"{'truncated: ' if size < written else ''}{size} bytes, {written} were written",
    "npz_checksum": lambda: "checksum mismatch: the raw block differs from what was written",
    "npz_unreadable": lambda error, detail: f"unreadable ({error}: {detail})",
    "run_json": lambda detail: detail,
    "steps_link": lambda: "is a symbolic link; a run's steps are read only inside the run directory",
    "no_steps_dir": lambda: "no steps/ directory",
    "raw_lacks": lambda channels: f"raw block lacks {sorted(channels)}",
    "not_in_plan": lambda: "a step the run's plan does not know",
    "name_not_utf8": lambda: "not a step file (its name is not UTF-8)",
    "not_a_step_file": lambda: "not a step file",
    "skipped": lambda why: f"skipped at run time: {why}",
    "sweep_short": lambda short, planned: (f"missing: {short} of the {planned} steps this sweep measures "
                                           "(adaptive plan: chosen online, so not named by key)"),
    "refinement_open": _owed_refinement,
    "dwell_owed": lambda cycles, mode, force_N, dwell, end: (f"the dwell of {cycles} cycles at the {mode} resonance "
                                                             f"at {force_N:g} N ({dwell}) not measured (the "
                                                             f"refinement ended: {end})"),
}


def _holder(pid: int | None = None, host: str = "", since: str = "", command: str = "bench", run: str = "") -> str:
    if pid is None:
        return "another process (it has not said which yet)"
    return f"process {pid} on {host} since {since} ({command}{', run directory ' + run if run else ''})"


_HELD = {"run_dir": "run directory", "instrument": "instrument"}
_DEMO_HOW = "bench demo --out: choose a new or empty directory, or remove"

REFUSAL: Words = {
    "lock_link": lambda path: f"{path}: is a symbolic link; a lock is never taken through links (remove it)",
    "lock_not_a_file": lambda path, held, name: f"{path}: not a regular file (expected the lock file of {_HELD[held]} {name})",
    "in_use": lambda held, name, holder: (f"{_HELD[held]} {name} is in use by {_holder(**holder)}; one session at a "
                                          "time: wait for it to end or stop it (Ctrl-C in its terminal, or its watch "
                                          "page's stop)"),
    "lock_dir": lambda path, uid: (f"{path}: the instruments' lock directory must be a real directory of user {uid} "
                                   "(set GUIDEWAY_LOCK_DIR to another)"),
    "demo_not_a_dir": lambda out: f"{out}: not a directory; {_DEMO_HOW} it",
    "demo_not_a_demo": lambda out, manifest: (f"{out} is not empty and holds no earlier demo run (no readable "
                                              f"{manifest} listing the files a demo wrote there); the demo deletes "
                                              f"nothing else: {_DEMO_HOW} its contents"),
    "demo_foreign": lambda out, foreign: (f"{out} holds an earlier demo run and files the demo did not write ("
                                          + ", ".join(foreign[:6]) + (f" (+{len(foreign) - 6} more)" if len(foreign) > 6
                                                                      else "")
                                          + f"); the demo deletes nothing it did not write: {_DEMO_HOW} them"),
}


REFUSAL.update({
    "run_dir_not_empty": lambda path: (f"run directory {path} exists and is not empty; "
                                       f"use 'bench resume {path}' or choose another --out"),
    "run_dir_missing": lambda path: f"{path}: no such directory (expected a run directory made by 'bench run')",
    "run_dir_no_run_json": lambda path: (f"{path}: not a run directory (no run.json; expected a directory made by "
                                         "'bench run')"),
    "run_dir_link": lambda path, kind: (f"{path}: is a symbolic link; a run writes nothing through links (replace it "
                                        f"with a real {kind})"),
    "run_dir_not_regular": lambda path, kind, found: (f"{path}: not a {'directory' if kind == 'directory' else 'regular file'} "
                                                      f"({found}); a run writes only regular files (replace or remove it)"),
    "run_json_missing": lambda path: f"{path}: missing (not a run directory?)",
    "run_json_unreadable": lambda detail: f"{detail} (run.json holds the run's plan; nothing can be counted without it)",
    "run_json_not_json": lambda path, json: f"{path}: damaged ({PROBLEM['not_json'](**json)})",
    "run_json_not_utf8": lambda path, byte: f"{path}: damaged (not text: byte {byte} is not UTF-8)",
    "run_json_too_deep": lambda path: f"{path}: damaged (nested too deeply to be a run's metadata)",
    "run_json_not_object": lambda path, found: f"{path}: damaged (a JSON object was expected, found {found})",
    "run_json_newer": lambda path, version, reads: (f"{path}: run format version {version!r}, written by a newer "
                                                    f"guideway-bench (this one reads versions up to {reads}); update "
                                                    "to read it"),
    "steps_gone": lambda path: f"{path}: missing (deleted while the run was using it?); no step can be stored",
})


CHECK: Words = {
    "unmeasured_tail": lambda last, count, run: (f"interrupted after step {last or '(none)'}; {count} not yet measured "
                                                 f"(the plan's steps after it; bench resume {run} measures them)"),
    "no_plan": lambda run, files, problems: (f"{run}: {files} step result files; run.json unreadable or its plan not "
                                             "valid, so the steps cannot be counted against the plan; "
                                             f"{problems} problem{'s' if problems != 1 else ''}"),
    "resume_measures": lambda run: (f" (bench resume {run} measures missing and damaged steps again, keeping damaged "
                                    "files in damaged/)"),
    "resume_owes": lambda run: f" (bench resume {run} measures what the refinement still owes)",
    "promise_short": lambda label, short: f"{label}: {'; '.join(short)}",
    "skipped_allowed": lambda count, strict: (f"{count} step{'s' * (count != 1)} skipped at run time as the plan allows "
                                              '(infeasible = "skip"): '
                                              + ("counted as problems (--strict)" if strict else
                                                 "not a problem (--strict counts them); bench resume "
                                                 "--retry-skipped measures them again")),
}


def _within(tolerance: float | None) -> str:
    return f"within {100 * tolerance:g} %" if tolerance is not None else "within tolerance"


def _refined(refined: dict | None) -> str:
    if refined is None:
        return ""
    c, more = refined["converged"], refined["no_peak"]
    return (f", the refinement converged for {c} peak{'s' * (c != 1)}"
            + (f" ({more} more had no peak inside the grid to refine)" if more else ""))


def _lost(level: str, why: str | None, measured: bool) -> str:
    return f"{level}: {why or 'not locked'}" if measured else f"{level}: not measured"


# what a run's procedure kept of its promise and where it fell short (bench.verdict.Kept,
# Short); `bench check`, `bench run` and the report's overall line say them
PROMISE: Words = {
    "levels_locked": lambda locked, levels: (f"{locked} of {levels} levels locked (the phase held in its band), each "
                                             "a point of the backbone; phase resonance identifies no model"),
    "level_held": lambda name, symbol, tolerance, refined: (f"the {name} ({symbol}) held {_within(tolerance)} of its "
                                                            f"level at every step{_refined(refined)}"),
    "force_held": lambda tolerance, refined: f"the force {_within(tolerance)} at every step{_refined(refined)}",
    "not_locked": lambda locked, levels, lost: (f"{locked} of {levels} levels locked; not locked: "
                                                + "; ".join(_lost(*x) for x in lost)),
    "out_of_tolerance": lambda name, symbol, steps: (f"{name}{f' ({symbol})' if symbol else ''} out of tolerance at "
                                                     f"{steps} step{'s' * (steps != 1)}"),
    "budget_spent": lambda mode, level, tolerance, steps: (f"refinement: the {mode} peak at {level} not within "
                                                           f"{100 * tolerance:g} % after {steps} steps (budget spent; "
                                                           "[plan.resonance] max_steps)"),
}


def promised(said) -> str:
    """What a procedure kept, or one of its shortfalls (a :class:`bench.words.Said`), in words."""
    return say(PROMISE, said.code, said.fields)


# the lines `bench run` and `bench resume` print at the end of a run (bench.commands.run.RunLine)
RUN: Words = {
    "ended": lambda status, done, total, out: f"run {status}: {done}/{total} steps in {out}/",
    "no_report": lambda reason, out: f"report not written: {reason} before it began; `bench report {out}` writes it",
    "report": lambda path, then: f"report: {path}" + (f" (complete; then {then})" if then else ""),
    "promise_broken": lambda label, short: f"the {label} did not measure what it promised: {'; '.join(short)}",
    "output_never_on": lambda: "output not switched on by this session (stopped before the generator was set up)",
    "output_off": lambda: "output off, confirmed by the generator",
    "output_off_unconfirmed": lambda: ("WARNING: output off NOT confirmed by the generator: switch the amplifier off "
                                       "by hand and check the generator"),
}


def _fitted(run, mode, level, f_Hz, zeta, balance) -> str:
    (f, f_lo, f_hi), (z, z_lo, z_hi) = f_Hz, zeta
    return (f"{run}: {mode} at {level}: {f:.5g} Hz [{f_lo:.5g}, {f_hi:.5g}], damping ratio (single-mode fit) "
            f"{100 * z:.3g} % [{100 * z_lo:.3g}, {100 * z_hi:.3g}]"
            + (f", (energy balance at resonance) {100 * balance[0]:.3g} % [{100 * balance[1]:.3g}, "
               f"{100 * balance[2]:.3g}]" if balance is not None else ""))


# the lines `bench modes` prints (bench.commands.results.ModeLine)
MODES: Words = {
    "locked": lambda run, mode, level, f_Hz, zeta: (f"{run}: {mode} at {level}: {f_Hz:.5g} Hz (phase resonance, "
                                                    "locked), damping ratio (energy balance at the locked point) "
                                                    f"{100 * zeta:.3g} %"),
    "fitted": _fitted,
    "not_estimated": lambda run, mode, level, status, note: (f"{run}: {mode} at {level}: {status}"
                                                             + (f" ({note})" if note else "")),
    "wrote": lambda files: "wrote " + ", ".join(files),
}


def _hint(near: str | None, allowed: list) -> str:
    return f"did you mean {near}?" if near else f"allowed: {allowed}"


_UTF8 = "TOML files are UTF-8 (save it again as UTF-8)"


def _unit(unit: str) -> str:
    return f" (unit: {unit})" if unit else ""

# a plan's or rig's problems (bench.toml_tables.ConfigProblem); a key's with source, table, key
CONFIG: Words = {
    "not_a_table": lambda source, table: f"{source}: [{table}] must be a table",
    "unknown_table": lambda source, table, near, allowed: (f"{source}: [{table}]: unknown table; "
                                                          + _hint(f"[{near}]" if near else None, allowed)),
    "unknown_key": lambda source, table, key, near, allowed: (f"{source}: {'[' + table + '] ' if table else ''}{key}: "
                                                              f"unknown key; {_hint(near, allowed)}"),
    "unknown_keys": lambda source, table, keys, allowed: f"{source}: [{table}] unknown key(s) {keys}; allowed: {allowed}",
    "missing": lambda source, table, key: f"{where(source, table, key)}: missing (required)",
    "not_a_number": lambda source, table, key, integer, value, unit: (
        f"{where(source, table, key)}: must be {'an integer' if integer else 'a number'}, got {value!r}{_unit(unit)}"),
    "out_of_range": lambda source, table, key, value, low, low_open, high, note, unit: (
        f"{where(source, table, key)}: must be {'>' if low_open else '>='} {low:g} and <= {high:g}{range_note(note)}, got "
        f"{value!r}{_unit(unit)}"),
    "not_a_list": lambda source, table, key, got: f"{where(source, table, key)}: must be a non-empty list of numbers, got {got}",
    "too_many": lambda source, table, key, count, most: f"{where(source, table, key)}: {count} values; at most {most}",
    "not_one_of": lambda source, table, key, allowed, value: f"{where(source, table, key)}: must be one of {allowed}, got {value!r}",
    "not_a_string": lambda source, table, key, value: f"{where(source, table, key)}: must be a string, got {value!r}",
    "not_a_bool": lambda source, table, key, value: f"{where(source, table, key)}: must be true or false, got {value!r}",
    "file_not_found": lambda path: f"{path}: file not found",
    "file_too_large": lambda path, size, most: f"{path}: {size} bytes; a plan or rig file is at most {most} bytes",
    "file_unreadable": lambda detail: detail,
    "file_is_dir": lambda path: f"{path}: a directory, not a TOML file",
    "utf16": lambda path: f"{path}: saved as UTF-16; {_UTF8}",
    "nul_bytes": lambda path, offset: (f"{path}: NUL bytes at offset {offset}: the file seems saved as UTF-16 without a "
                                       f"byte-order mark; {_UTF8}"),
    "not_utf8": lambda path, byte, line, offset: (f"{path}: not UTF-8: byte 0x{byte:02x} at line {line} (offset "
                                                  f"{offset}); the file seems saved in another encoding (Latin-1, "
                                                  f"Windows-1252, ...); {_UTF8}"),
    "not_toml": lambda path, detail: f"{path}: not valid TOML: {detail}",
    "too_deep": lambda path: f"{path}: not a plan or rig: tables or arrays nested too deeply",
    "several": lambda problems: "\n".join(say(CONFIG, p.code, p.fields) if p.code else p.fields["text"]
                                          for p in problems),
}
CONFIG.update(RULE)         # a plan's and a rig's rules across keys (bench.words.terminal_config)
REFUSAL.update(CONFIG)
REFUSAL.update(SEQUENCE)    # a sequence file's problems (bench.words.terminal_config)
REFUSAL.update(API)         # the API's and the pytest plugin's (bench.words.terminal_config)
REFUSAL.update(STUDY)       # the studies' (bench.words.terminal_config)


def config(code: str, **fields) -> str:
    """A plan's or rig's problem in words (a line of the ConfigError that collects them)."""
    return say(CONFIG, code, fields)


def refused(exc: type[E], code: str, **fields) -> E:
    """The exception ``exc`` of a refusal: its message the words of ``code`` with ``fields``,
    and ``code`` and ``fields`` kept on it (what a caller decides by)."""
    e = exc(say(REFUSAL, code, fields))
    e.code, e.fields = code, fields         # type: ignore[attr-defined]
    return e


def problem(code: str, fields) -> str:
    """A run directory's problem in words (no file name: the caller shows it)."""
    return say(PROBLEM, code, fields)
