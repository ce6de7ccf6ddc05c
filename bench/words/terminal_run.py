"""The terminal's words of a run before and while it runs, and of the modules it runs
through (decision 0067; issue 35 item 1), by code.

``bench`` commands: ``DRY_RUN`` (:class:`bench.commands.run.DryRunLine`), ``RESUME``
(``ResumeLine``: what ``bench resume`` says before it measures), ``WATCH`` (``WatchLine``),
``SEQUENCE`` (``SequenceEndLine``), ``CLI`` (:class:`bench.cli.CliLine`: the program's own lines
about a command's end).

A session: ``ENVELOPE`` (:class:`bench.session.EnvelopeProblem`, the ``problems`` of an
:class:`~bench.session.EnvelopePoint`) and :func:`envelope_table`, the plan's envelope that
``bench dry-run`` prints and a refusal ends with; ``SESSION`` (``SessionLine``: its log lines
and the status line's estimates); ``DOING`` and ``SIGNAL`` (:class:`bench.signals.Doing`,
``SignalLine``: what a held signal lets finish); ``STOP`` (:class:`bench.watch.stop.StopLine`).

A run directory: ``STORE`` (:class:`bench.storage.StoreLine`), ``FILE_KIND``
(:class:`bench.files.FileKind`), ``ACCOUNT`` (:class:`bench.accounting.AccountLine`: what a
resume measures, ``bench check``'s summary); ``WARMUP`` (:class:`bench.warmup.WarmupLine`),
``DEMO`` (:class:`bench.demo.DemoLine`); the watch page's log: ``SNAPSHOT``
(:class:`bench.watch.snapshot.SnapshotLine`), ``SERVER`` (:class:`bench.watch.server.ServerLine`).

``REFUSAL``: the one-line errors (``RunRefusal``, ``EnvelopeRefusal``,
:class:`bench.durable.WriteRefusal`, :class:`bench.files.FileRefusal`,
:class:`bench.accounting.AccountRefusal`), made by :func:`refused` into the exception raised,
which keeps the code and the fields.  The page's own words are :mod:`bench.words.page`'s.
"""

from __future__ import annotations

from typing import TypeVar

from . import Words, say

__all__ = ["ACCOUNT", "CLI", "DEMO", "DOING", "DRY_RUN", "ENVELOPE", "FILE_KIND", "REFUSAL", "RESUME", "SEQUENCE",
           "SERVER", "SESSION", "SIGNAL", "SNAPSHOT", "STOP", "STORE", "WARMUP", "WATCH", "duration", "envelope_table",
           "refused"]

E = TypeVar("E", bound=Exception)


def duration(seconds: float) -> str:
    """A rig time: '1 h 02 min', '3 min 05 s', '12 s'."""
    m, s = divmod(int(round(seconds)), 60)
    h, m = divmod(m, 60)
    return f"{h} h {m:02d} min" if h else f"{m} min {s:02d} s" if m else f"{s} s"


def _simulated(simulated: bool, friction: str = "") -> str:
    """' (simulated)', with the plant's friction model when it is not Masing (decision 0075)."""
    return (f" (simulated, {friction} friction)" if friction else " (simulated)") if simulated else ""


def _measured(measured: int, per_sweep: int | None, refined: int, refine_steps: int, modes: list,
              tolerance: float, dwell_cycles: int) -> str:
    runs = f"{measured} measured (adaptive: {per_sweep} per sweep, chosen online)" if per_sweep else f"{measured} measured"
    if refined:
        runs += (f" + at most {refined} refinement steps ([plan.resonance]: {refine_steps} per mode and level, "
                 f"modes {', '.join(modes)}, tolerance {100 * tolerance:g} %"
                 + (f"; with a dwell of {dwell_cycles} cycles at each mode's resonance per level"
                    if dwell_cycles else "") + ")")
    return runs


def _time(quantity, bound_s, without_extra_s, block_s, blocks, typical_s, refined) -> str:
    return (f"expected rig time: at most {duration(bound_s)} (every step's {quantity} control and extra "
            f"settle blocks to the plan's limits, steps chosen online at the lowest frequency, refinement budget "
            f"used up); without the extra settle blocks at most {duration(without_extra_s)}, "
            f"plus at most {block_s:.3g} s for each extra settle block a "
            f"step needs (at most {blocks} a step); typically about {duration(typical_s)}"
            + (" with the refinement budget used up" if refined else "")
            + " (a simulated rig runs faster or slower than real time)")


# `bench dry-run`'s lines (bench.commands.run.DryRunLine)
DRY_RUN: Words = {
    "backbone_plan": lambda name, levels, start_Hz, min_Hz, max_Hz, rig, simulated, friction: (
        f"plan '{name}': phase resonance, {levels} force levels (N) from {start_Hz:g} Hz in the window "
        f"{min_Hz:g}-{max_Hz:g} Hz (envelope at both ends); rig '{rig}'{_simulated(simulated, friction)}"),
    "backbone_time": lambda bound_s, max_blocks: (
        f"expected rig time: at most {duration(bound_s)} (every level probing its phase "
        f"slope and spending max_blocks = {max_blocks} controller blocks at the window's lowest frequency, "
        f"then settled, measured and re-measured to the plan's limits; a level that locks takes a few blocks)"),
    "plan": lambda name, procedure, levels, freqs, direction, steps, rig, simulated, friction, **measured: (
        f"plan '{name}': {procedure}, {levels} levels x {freqs} frequencies "
        f"({direction}) = {steps} steps, {_measured(**measured)}; rig '{rig}'{_simulated(simulated, friction)}"),
    "levels": lambda levels, unit, quantity, held: (
        f"levels: {', '.join(f'{v:g} {unit}' for v in levels)} ({quantity} amplitude"
        + (", the response fundamental held at each frequency)" if held else ")")),
    "time": _time,
    "steps": lambda lines: "\n".join(["steps, in the order they run:", *lines]),
    "refused": lambda first: f"REFUSED: {first}",
    "runs_some": lambda run, skipped: f"envelope: {run} steps run, {skipped} skipped (infeasible = \"skip\")",
    "envelope_ok": lambda: "envelope ok: the rig's limits hold every step",
    "identifiability": lambda warning: f"identifiability warning: {warning}",
}


# what `bench resume` says before it measures (bench.commands.run.ResumeLine)
RESUME: Words = {
    "nothing_to_do": lambda skipped, summary: (
        "resume: nothing to do: the run completed and its steps are all there "
        + ("or were skipped at run time as the plan allows (--retry-skipped measures them again) "
           if skipped else "") + f"({summary})"),
    "measures": lambda text: f"resume: {text}",
    "finishing": lambda skipped, status: (f"resume: every planned step is there"
                                          f"{' or was skipped at run time' if skipped else ''}; "
                                          f"finishing the run (it ended '{status}')"),
}


# the watch page's lines (bench.commands.run.WatchLine)
WATCH: Words = {
    "url": lambda url: f"watch: {url}",
    "serving": lambda url: f"watch: {url}  (Ctrl-C ends the page, not the run)",
    "waiting": lambda path: f"waiting for {path} to appear ... (Ctrl-C stops)",
    "no_run_json": lambda path: f"{path} has no run.json yet: the page waits for the run to start",
    "appeared": lambda path: f"{path} appeared: the page follows the run",
}


# `bench sequence`'s and a resumed sequence's lines at its end (bench.commands.run.SequenceEndLine)
SEQUENCE: Words = {
    "entry": lambda name, status, done, total: (f"{name}: {status}"
                                                + (f" ({done}/{total} steps)" if status != "not started" else "")),
    "report": lambda path: f"sequence report: {path}",
}


# the one-line errors of `bench run`, `bench watch` (bench.commands.run.RunRefusal)
REFUSAL: Words = {
    "watch_port": lambda host, port, error: f"cannot serve the watch page on {host}:{port}: {error}",
    "watch_a_file": lambda path: f"{path}: not a run directory (a file)",
    "watch_no_parent": lambda path, parent: (f"{path}: no such run directory, nor its parent {parent} "
                                             f"(bench watch waits for a run directory to appear inside an existing one)"),
    "label": lambda item: f"--label {item!r}: expected KEY=VALUE, e.g. --label lubricant=\"ISO VG 32\"",
}


def refused(exc: type[E], code: str, **fields) -> E:
    """The exception ``exc`` of a refusal of :data:`REFUSAL` (as :func:`bench.words.terminal.refused`)."""
    e = exc(say(REFUSAL, code, fields))
    e.code, e.fields = code, fields         # type: ignore[attr-defined]
    return e


def _at(level: float, unit: str, margin: float, response: bool) -> str:
    return f"at {level:g} {unit} x {margin:g}{'' if response else ' margin'}"


# what the rig's limits cannot hold at a (level, frequency) (bench.session.EnvelopeProblem)
ENVELOPE: Words = {
    "drive": lambda drive_V, margin, limit_V: (f"drive {drive_V:.3g} V x {margin:g} margin = {drive_V * margin:.3g} V "
                                               f"> drive_V {limit_V:g} V"),
    "force": lambda level_N, margin, limit_N: (f"{level_N:g} N x {margin:g} margin = {level_N * margin:.3g} N "
                                               f"> force_N {limit_N:g} N"),
    "displacement": lambda disp_m, level, unit, margin, response, limit_m: (
        f"displacement {disp_m * 1e3:.3g} mm {_at(level, unit, margin, response)} > disp_m {limit_m * 1e3:g} mm"),
    "acceleration": lambda accel_m_s2, level, unit, margin, response, limit_m_s2: (
        f"acceleration {accel_m_s2:.3g} m/s^2 {_at(level, unit, margin, response)} > accel_m_s2 {limit_m_s2:g} m/s^2"),
}


def _problems(p) -> str:
    return "; ".join(say(ENVELOPE, s.code, s.fields) for s in p.problems)


def envelope_table(points, margin: float) -> str:
    """The plan's envelope (:class:`bench.session.EnvelopePoint` s) by level: the drive, the
    largest displacement and acceleration, and the first problem at the level."""
    unit = points[0].quantity.unit if points else "N"
    lines = [f"{'level ' + unit:>11} {'drive V':>8} {'disp mm (max)':>14} {'accel m/s2':>10}  problems",
             f"(drive: the generator's amplitude, V = Vpp/2, at the level; displacement, acceleration and every "
             f"limit check: at {margin:g} x the level, the control's overshoot margin)"]
    for F in sorted({p.level for p in points}):
        ps = [p for p in points if p.level == F]
        bad = [f"{p.freq_Hz:g} Hz: {_problems(p)}" for p in ps if p.problems]
        lines.append(f"{F:11.3g} {max(p.drive_V for p in ps):8.3g} {max(p.disp_m for p in ps) * 1e3:14.4g} "
                     f"{max(p.accel_m_s2 for p in ps):10.3g}  {bad[0] + (f' (+{len(bad) - 1} more)' if len(bad) > 1 else '') if bad else 'ok'}")
    return "\n".join(lines)


def _first_bad(points) -> str:
    p = next(p for p in points if p.problems)
    return f"{p.level:g} {p.quantity.unit} at {p.freq_Hz:g} Hz: {_problems(p)}"


# the refusals of a plan the rig's limits cannot hold (bench.session.EnvelopeRefusal)
REFUSAL.update({
    "skip_in_window": lambda points, margin: (f"infeasible = \"skip\" cannot skip part of a phase-resonance window: "
                                              f"{_first_bad(points)}\n" + envelope_table(points, margin)),
    "not_held": lambda points, margin: (f"the rig's limits cannot hold {sum(1 for p in points if p.problems)} of "
                                        f"{len(points)} steps of the plan, e.g. {_first_bad(points)}\n"
                                        + envelope_table(points, margin)),
})


# what a session logs and shows while it runs (bench.session.SessionLine)
SESSION: Words = {
    "skipping": lambda skipped, points: f"skipping {skipped} of {points} (level, frequency) points the rig's limits cannot hold",
    "identifiability": lambda warning: f"identifiability: {warning}",
    "off_unconfirmed": lambda error, url: f"output off not confirmed on the open link ({error}); reconnecting to {url}",
    "off_failed": lambda url, error: f"could not switch the output off at {url}: {error}",
    "aborted": lambda error: f"aborted: {error}",
    "interrupted": lambda path: f"interrupted; resume with: bench resume {path}",
    "instrument_error": lambda kind, error: f"instrument error: {kind}: {error}",
    "storage_error": lambda error: (f"storage error: {error}; the output is switched off, the steps stored so far "
                                    "are intact"),
    "failed": lambda: "run failed",
    "end_unrecorded": lambda status, error: f"the run's end ({status}) could not be recorded: {error}",
    "event_unrecorded": lambda kind, error: f"event {kind} not recorded: {error}",
    "estimates": lambda F_s_N, x_s_m, n, mass_kg, at_bound, misfit: (
        f"F_s {F_s_N:.3g} N x_s {x_s_m * 1e6:.3g} um n {n:.3g} m {mass_kg:.3g} kg"
        + (f" ({', '.join(at_bound)} at the search bound: not estimates)" if at_bound else "")
        + (" (the model does not fit: see the report)" if misfit else "")),
}


# what a held signal lets finish (bench.signals.Doing), and the log line of a signal meanwhile
# (bench.signals.SignalLine)
DOING: Words = {
    "report": lambda: "the report is written (the output is off)",
    "ramp_down": lambda: "ramping down",
    "switch_off": lambda: "switching the output off",
}
SIGNAL: Words = {
    "held": lambda reason, doing: f"{reason} while {say(DOING, doing, {})}: finishing it first",
    "uninterruptible": lambda signum, doing: f"signal {signum} while {say(DOING, doing, {})}: finishing that first",
}


# the refusals of a run directory's files as they are written (bench.durable.WriteRefusal)
REFUSAL.update({
    "dir_missing": lambda path: f"{path}: missing (expected a directory)",
    "dir_link": lambda path: (f"{path}: is a symbolic link; a run writes nothing through links "
                              "(replace it with a real directory)"),
    "not_a_dir": lambda path: f"{path}: not a directory",
    "append_link": lambda path: f"{path}: is a symbolic link; a run writes nothing through links (remove it)",
    "fifo": lambda path: f"{path}: not a regular file (a FIFO)",
    "not_regular": lambda path: f"{path}: not a regular file",
    "cannot_write": lambda path, error: f"{path}: cannot write: {error}",
    "not_serialisable": lambda kind: f"not JSON serialisable: {kind}",
})


# what reading a run directory logs and fills in (bench.storage.StoreLine)
STORE: Words = {
    "events_unreadable": lambda error: f"{error}; its events are not used",
    "event_line_damaged": lambda path, line: f"{path}: line {line} damaged (torn or not JSON); skipped",
    "event_line_not_object": lambda path, line: f"{path}: line {line} is not an event object; skipped",
    "history_unreadable": lambda error: f"{error}; the identification history is not shown",
    "skipping_step": lambda key, error: f"skipping step {key}: {error}",
    "damaged_moved": lambda key, problem, dest: (f"step {key} damaged ({problem}): files moved to {dest}; it will be "
                                                 "measured again"),
    "no_reason": lambda: "no reason recorded",
}


# what is at a path (bench.files.FileKind)
FILE_KIND: Words = {
    "fifo": lambda: "a FIFO",
    "char_device": lambda: "a character device",
    "block_device": lambda: "a block device",
    "socket": lambda: "a socket",
    "directory": lambda: "a directory",
    "regular": lambda: "a regular file",
    "other": lambda: "not a regular file",
}

# the refusals of a run directory's files as they are read (bench.files.FileRefusal)
REFUSAL.update({
    "too_large": lambda path, size, limit: (f"{path}: {f'{size} bytes' if size is not None else 'grew while read'}, "
                                            f"more than the {limit} bytes a file of this kind may have; not read"),
    "read_link": lambda path: (f"{path}: is a symbolic link; a run's files are read only as regular files inside "
                               "the run directory"),
    "not_regular_read": lambda path, kind: f"{path}: not a regular file ({say(FILE_KIND, kind, {})}); not read",
})


def _keys(keys: list[str], limit: int = 8) -> str:
    return ", ".join(keys[:limit]) + (f" and {len(keys) - limit} more" if len(keys) > limit else "")


def _missing(missing) -> list[str]:
    """A step's key, or an adaptive sweep with the number of steps it lacks: 'L01-up (2)'."""
    return [f"{key} ({short})" if short is not None else key for key, short in missing]


def _damaged(damaged) -> list[str]:
    return [f"{key} ({kind})" for key, kind in damaged]


def _owed(owed) -> list[str]:
    """'L00-feed dwell' or 'L01-pitch refinement'."""
    return [f"{key} {'dwell' if dwell else 'refinement'}" for key, dwell in owed]


def _planned(planned: int | None) -> str:
    return "?" if planned is None else str(planned)


def _resume(measures, retry, planned, missing, damaged, owed, skipped) -> str:
    parts = [f"measures again {measures} of {_planned(planned)} planned step{'s' * (planned != 1)}"]
    if missing:
        parts.append("missing: " + _keys(_missing(missing), 12))
    if damaged:
        parts.append("damaged: " + _keys(_damaged(damaged), 12))
    if owed:
        parts.append("owed: " + _keys(_owed(owed), 12))
    if skipped:
        parts.append(("skipped at run time, retried: " if retry else
                      "skipped at run time, not retried (--retry-skipped retries them): ") + _keys(skipped, 12))
    return "; ".join(parts)


def _summary(intact, orphan, planned, missing, damaged, owed, skipped) -> str:
    skip = f"skipped at run time: {_keys(skipped)}; " if skipped else ""
    return (f"{intact} intact / {_planned(planned)} planned; {skip}"
            f"missing: {_keys(_missing(missing)) or 'none'}; "
            f"damaged: {_keys(_damaged(damaged)) or 'none'}; "
            f"orphan: {_keys(orphan) or 'none'}"
            + (f"; owed: {_keys(_owed(owed))}" if owed else ""))


# a run's account (bench.accounting.AccountLine): what a resume measures, bench check's summary
ACCOUNT: Words = {
    "resume": _resume,
    "summary": _summary,
}
REFUSAL.update({"stored_plan": lambda error: f"{error} (the plan stored in run.json; nothing is counted against it)"})


# the warm-up's words (bench.warmup.WarmupLine)
WARMUP: Words = {
    "source": lambda: "warm-up plan",
    "ended": lambda status: f"warm-up run ended {status!r}",
    "stamp_unwritten": lambda path, error: f"could not write the warm-up stamp {path}: {error}",
}

# the demo's words (bench.demo.DemoLine)
DEMO: Words = {
    "link": lambda name: f"{name} (a link)",
    "changed": lambda name: f"{name} (changed since the demo wrote it)",
    "deleted": lambda out, files: f"deleted the earlier demo in {out} ({files} files)",
}


# the program's own lines about a command's end (bench.cli.CliLine)
CLI: Words = {
    "interrupted": lambda: "interrupted",
    "internal": lambda: "internal error",
    "problems": lambda count: f"{count} problems:",
    "late": lambda reason: f"bench: {reason} after the work was done: nothing left to stop",
    "failed": lambda command: f"bench {command} failed",
    "error": lambda: "error: ",
    "hint_internal": lambda: ", rerun with --debug for the traceback",
    "hint_debug": lambda: " (--debug shows the traceback)",
}


# what reading a run for the watch page logs (bench.watch.snapshot.SnapshotLine)
SNAPSHOT: Words = {
    "no_plan": lambda error: f"no usable plan in run.json: {error}",
    "step_unreadable": lambda path, error: f"cannot read step {path}: {error}",
    "no_modes": lambda error: f"modes could not be estimated: {error}",
}


# a stop request's words (bench.watch.stop.StopLine): its log line, the interruption's reason
STOP: Words = {
    "requested": lambda path, by: f"stop requested for {path} by {by}",
    "stopped": lambda by: f"stop requested by {by}",
    "by_page": lambda client: f"the watch page ({client})",
}


# what the watch page's server logs (bench.watch.server.ServerLine)
SERVER: Words = {
    "off_loopback": lambda host: (f"the watch page is served on {host}, off loopback: anyone who can reach this "
                                  "address can read the run (the stop token is still needed to stop it)"),
    "full": lambda connections, client: f"watch: {connections} connections already; closed one from {client}",
    "late": lambda: "watch: request not complete within its deadline; connection closed",
    "went_away": lambda client, error: f"watch: {client} went away: {error}",
    "error": lambda client, kind, error: f"watch: error serving {client}: {kind}: {error}",
    "stop_refused": lambda client, given: f"refused a stop request from {client}: {'wrong' if given else 'no'} token",
    "stop_unwritten": lambda path, error: f"could not write the stop request into {path}: {error}",
}
