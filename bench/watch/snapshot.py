"""What the watch page shows, read from the run directory alone.

The run directory is the one source of truth (see bench/storage.py): ``run.json`` (plan,
status), ``steps/<key>.json`` (one per completed step, never rewritten), the append-only
``identification.jsonl`` and ``events.jsonl``, and ``bench.log``.  :class:`RunReader` reads
them incrementally (a step file once, the logs from where it stopped, a torn last line
later) so that polling every fraction of a second costs little, and it works whoever
writes the directory: this process, another one, a resumed run, or nobody any more.

Progress: steps done against the plan's schedule (adaptive plans: the chosen number per
sweep); the ETA is the mean time per step since the first step after the latest start or
resume (set-up is not counted, as on the terminal's progress line) times the steps left.  The "next" step is the first of the schedule not yet done (in adaptive mode the
procedure may skip it).
"""

from __future__ import annotations

import json
import logging
import math
import os
import socket
import threading
from datetime import datetime
from enum import StrEnum
from pathlib import Path

from procedures.kind import ProcedureKind
from procedures.plan import GUESS_KEYS, Plan

from ..config import ConfigError, stored_rig
from ..files import open_regular, read_file
from ..storage import RunDirError, RunStatus, stored_plan
from ..words import page, say, terminal_run
from .stop import STOP_FILE

log = logging.getLogger(__name__)

LOG_LINES_KEPT = 40           # warnings and errors from bench.log shown on the page
QUIET_EVENTS = {"sensor"}     # frequent, routine: counted, not listed
LOCK_EVENT = "lock_block"     # a phase-resonance block (bench/backbone.py): shown in the lock panel, not listed
TAIL_CHUNK = 16 * 2**20       # read of a growing log at a time (a huge file is followed in steps)


class _Tail:
    """Complete lines appended to a file since the last read (a torn last line waits);
    only those ``keep`` accepts, at most ``max_lines`` of the latest."""

    def __init__(self, path: Path, keep=None, max_lines: int | None = None):
        self.path, self.offset, self.lines = path, 0, []
        self.keep, self.max_lines = keep, max_lines

    def read(self) -> list[str]:
        try:
            size = self.path.stat().st_size
        except FileNotFoundError:
            return self.lines
        if size < self.offset:          # replaced (a new run in the same place): start over
            self.offset, self.lines = 0, []
        if size > self.offset:
            try:
                fh = os.fdopen(open_regular(self.path), "rb")
            except (OSError, ValueError) as e:       # a link or a FIFO in its place: not read
                log.warning("%s", e)
                return self.lines
            with fh:
                fh.seek(self.offset)
                chunk = fh.read(min(size - self.offset, TAIL_CHUNK))
            end = chunk.rfind(b"\n") + 1
            self.offset += end
            new = chunk[:end].decode(errors="replace").splitlines()
            self.lines.extend(ln for ln in new if self.keep is None or self.keep(ln))
            if self.max_lines is not None:
                del self.lines[:-self.max_lines]
        return self.lines


def _jsonl(lines: list[str]) -> list[dict]:
    out = []
    for line in lines:
        try:
            out.append(json.loads(line))
        except (json.JSONDecodeError, RecursionError):
            pass
    return out


def _time(s: str | None) -> float | None:
    try:
        return datetime.fromisoformat(s).timestamp()
    except (TypeError, ValueError):
        return None


def plan_of(meta: dict) -> Plan | None:
    """The stored plan, validated as a plan file is (bench.storage.stored_plan); None if
    run.json does not hold a valid one."""
    try:
        return stored_plan(meta, "run.json")
    except RunDirError as e:
        log.debug(_logged(SnapshotLine.NO_PLAN, error=e))
        return None


def steps_total(plan: Plan) -> int:
    """Steps the procedure will measure (adaptive mode: the chosen number per sweep)."""
    sweeps: dict[tuple[int, str], int] = {}
    for s in plan.schedule():
        sweeps[(s.level_index, s.direction)] = sweeps.get((s.level_index, s.direction), 0) + 1
    k = plan.adaptive_per_sweep
    return sum(min(n, k) if k else n for n in sweeps.values())


def _phase_deg(phase_rad: float) -> float:
    """Phase in (-270, 90] degrees: a compliance lags by 0 to 180 degrees, so the mass
    line near -180 does not flip between -179 and +179 with the noise."""
    deg = math.degrees(phase_rad)
    return deg - 360.0 if deg > 90.0 else deg


def _step_summary(r: dict) -> dict:
    """The page's summary of a step; ``level_N`` is the level it held in the run's level unit
    (a response-controlled step: its target response, ``control_error`` the response's error)."""
    rc = r.get("response_control") if isinstance(r.get("response_control"), dict) else {}
    return dict(key=r.get("key"), level_N=rc.get("target", r.get("target_force_N")), freq_Hz=r.get("freq_Hz"),
                control_error=rc.get("error", r.get("force_error")),
                direction=r.get("direction"), force_N=r.get("force_N"), force_error=r.get("force_error"),
                control_iterations=r.get("control_iterations"), force_converged=r.get("force_converged"),
                thd_force=r.get("force", {}).get("thd"), thd_accel=r.get("accel", {}).get("thd"),
                thd_disp=r.get("disp", {}).get("thd"), drive_Vpp=r.get("drive_Vpp"),
                drive_V=None if r.get("drive_Vpp") is None else r["drive_Vpp"] / 2)   # amplitude (0029)


class PageWarning(StrEnum):
    """A warning the page makes of the stored steps (its words: :mod:`bench.words.page`)."""

    FORCE_NOT_REACHED = "force_not_reached"     # key, target_N, error (relative), iterations


class PageMessage(StrEnum):
    """The page's message of a run it cannot show yet, and of a fit that failed (its words:
    :data:`bench.words.page.MESSAGE`)."""

    WAITING = "waiting"                         # no run.json yet
    UNREADABLE = "unreadable"                   # error: run.json's
    TOO_DEEP = "too_deep"                       # run.json nested too deeply
    FIT_FAILED = "fit_failed"                   # names: the parameters not finite or absurd
    UNUSABLE = "unusable"                       # the final identification holds neither values nor an error


class SnapshotLine(StrEnum):
    """What reading a run for the page logs (:data:`bench.words.terminal_run.SNAPSHOT`)."""

    NO_PLAN = "no_plan"                         # error
    STEP_UNREADABLE = "step_unreadable"         # path, error
    NO_MODES = "no_modes"                       # error


def _message(code: PageMessage, **fields) -> str:
    return say(page.MESSAGE, code, fields)


def _logged(code: SnapshotLine, **fields) -> str:
    return say(terminal_run.SNAPSHOT, code, fields)


class RunReader:
    """Incremental, thread-safe reader of one run directory."""

    def __init__(self, run_dir: Path):
        self.path = Path(run_dir)
        self._lock = threading.Lock()
        self._steps: dict[str, dict] = {}         # file name -> result (step files never change)
        self._step_mtime: dict[str, float] = {}
        self._cached: dict = {}
        self._cached_sig: tuple | None = None
        self._process: dict | None = None
        self._events = _Tail(self.path / "events.jsonl")
        self._ident = _Tail(self.path / "identification.jsonl")
        self._log = _Tail(self.path / "bench.log", keep=lambda ln: " WARNING " in ln or " ERROR " in ln,
                          max_lines=LOG_LINES_KEPT)

    def signature(self) -> tuple:
        """Changes whenever anything the page shows may have changed (cheap: stats only)."""
        sig = []
        for name in ("run.json", "events.jsonl", "identification.jsonl", "bench.log", STOP_FILE):
            try:
                st = (self.path / name).stat()
                sig.append((st.st_mtime_ns, st.st_size))
            except FileNotFoundError:
                sig.append(None)
        try:
            sig.append(sum(1 for e in os.scandir(self.path / "steps") if e.name.endswith(".json")))
        except FileNotFoundError:
            sig.append(0)
        return tuple(sig)

    def _process_gone(self) -> bool:
        """True if run.json names a process on this host that no longer exists (kill -9, a
        crash): the run says "running" but nobody runs it.  Unknown (another host, no
        record): False."""
        process = self._process
        if not isinstance(process, dict) or process.get("host") != socket.gethostname():
            return False
        try:
            os.kill(int(process["pid"]), 0)
        except ProcessLookupError:
            return True
        except (PermissionError, KeyError, TypeError, ValueError):
            return False
        return False

    def _read_steps(self) -> list[dict]:
        steps_dir = self.path / "steps"
        try:
            entries = [e for e in os.scandir(steps_dir) if e.name.endswith(".json") and not e.name.startswith(".")]
        except FileNotFoundError:
            return []
        for e in entries:
            if e.name not in self._steps:
                try:
                    self._steps[e.name] = json.loads(read_file(Path(e.path)))
                    self._step_mtime[e.name] = e.stat().st_mtime
                except (OSError, ValueError, RecursionError) as exc:     # renamed into place: only if damaged
                    log.warning(_logged(SnapshotLine.STEP_UNREADABLE, path=e.path, error=exc))
        return [self._steps[k] for k in sorted(self._steps)]

    def snapshot(self) -> dict:
        """The state; recomputed only when :meth:`signature` changed (several pages, one read)."""
        with self._lock:
            sig = self.signature()
            if sig != self._cached_sig:
                self._cached, self._cached_sig = self._snapshot(), sig
            state = dict(self._cached)
        if state.get("status") == RunStatus.RUNNING:     # a process can die without touching a file
            state["process_gone"] = self._process_gone()
        return state

    def _snapshot(self) -> dict:
        try:
            meta = json.loads(read_file(self.path / "run.json"))
        except FileNotFoundError:
            return {"run_dir": str(self.path), "status": "waiting", "message": _message(PageMessage.WAITING)}
        except ValueError as e:
            return {"run_dir": str(self.path), "status": "unreadable", "message": _message(PageMessage.UNREADABLE, error=e)}
        except RecursionError:
            return {"run_dir": str(self.path), "status": "unreadable", "message": _message(PageMessage.TOO_DEEP)}
        results = self._read_steps()
        events = _jsonl(self._events.read())
        ident = _jsonl(self._ident.read())
        plan = plan_of(meta)
        status = meta.get("status", "unknown")
        self._process = meta.get("process")
        return {
            "run_dir": str(self.path),
            "name": meta.get("plan", {}).get("name", ""),
            "rig": meta.get("rig", {}).get("name", ""),
            "simulated": bool(meta.get("rig", {}).get("simulated")),
            "status": status,
            "levels_N": list(plan.levels_N) if plan else [],       # in level_unit
            "procedure": plan.procedure.label if plan else "",
            "level_quantity": plan.level_quantity.name if plan else "force",
            "level_unit": plan.level_quantity.unit if plan else "N",
            "started": meta.get("started"),
            "ended": meta.get("ended") if status != RunStatus.RUNNING else None,
            "stop_pending": (self.path / STOP_FILE).exists(),
            "process_gone": False,       # filled in by snapshot()
            "progress": self._progress(plan, results, events, status),
            "last_step": _step_summary(results[-1]) if results else None,
            "next_step": self._next(plan, results) if status == RunStatus.RUNNING else None,
            "compliance": self._compliance(plan, results),
            "modes": self._modes(plan, results, meta),
            "identification": self._identification(ident, results, meta, self._analysis()),
            "lock": self._lock_state(plan, results, events),
            "events": [e for e in events if e.get("event") not in QUIET_EVENTS and e.get("event") != LOCK_EVENT],
            "quiet_events": sum(1 for e in events if e.get("event") in QUIET_EVENTS),
            "warnings": self._warnings(meta, results),
        }

    def _progress(self, plan: Plan | None, results: list[dict], events: list[dict], status: str) -> dict:
        done = len(results)
        total = steps_total(plan) if plan else None
        if total is not None and plan is not None and plan.refine:   # refinement steps: counted as they come
            total += sum(1 for r in results if plan.refined_key_ok(str(r.get("key", ""))))
        starts = [_time(e.get("time")) for e in events if e.get("event") in ("start", "resume")]
        t_start = starts[-1] if starts and starts[-1] else None
        since = sorted(self._step_mtime[n] for n in self._steps if t_start and self._step_mtime[n] >= t_start)
        eta_s = per_step_s = None
        if len(since) >= 2:              # from the first step on: set-up is not a step
            per_step_s = (since[-1] - since[0]) / (len(since) - 1)
        elif since and t_start:
            per_step_s = since[0] - t_start
        if per_step_s is not None:
            if total is not None and status == RunStatus.RUNNING:
                eta_s = max(0.0, per_step_s * (total - done))
        return dict(done=done, total=total, fraction=(done / total if total else None),
                    started_s=t_start, per_step_s=per_step_s, eta_s=eta_s)

    @staticmethod
    def _next(plan: Plan | None, results: list[dict]) -> dict | None:
        if plan is None:
            return None
        done = {r.get("key") for r in results}
        for s in plan.schedule():
            if s.key not in done:
                return dict(key=s.key, level_N=s.force_N, freq_Hz=s.freq_Hz, direction=s.direction)
        return None

    @staticmethod
    def _compliance(plan: Plan | None, results: list[dict]) -> list[dict]:
        """One series per (force level, direction), sorted by frequency."""
        groups: dict[tuple[int, str], list[dict]] = {}
        for r in results:
            if "compliance_abs_m_per_N" in r:
                groups.setdefault((r.get("level_index", 0), r.get("direction", "")), []).append(r)
        out = []
        for (li, d), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] != "up")):
            rs.sort(key=lambda r: r["freq_Hz"])
            level = plan.levels_N[li] if plan and li < len(plan.levels_N) else rs[0].get("target_force_N")
            out.append(dict(level_index=li, level_N=level, direction=d, key=[r.get("key") for r in rs],
                            freq_Hz=[r["freq_Hz"] for r in rs],
                            abs_m_per_N=[r["compliance_abs_m_per_N"] for r in rs],
                            phase_deg=[_phase_deg(r["compliance_phase_rad"]) for r in rs],
                            accel_abs_per_kg=[r.get("accelerance_abs_kg_inv") for r in rs],
                            converged=[bool(r.get("force_converged", True)) for r in rs]))
        return out

    def _analysis(self) -> dict | None:
        """analysis/analysis.json's parameters as an estimate, once `bench analyze` has run."""
        path = self.path / "analysis" / "analysis.json"
        if not path.is_file():
            return None
        from ..reports import analysis_estimate  # (matplotlib: only when there is one)
        try:
            return analysis_estimate(json.loads(path.read_text()))
        except (OSError, ValueError):
            return None

    @staticmethod
    def _lock_state(plan: Plan | None, results: list[dict], events: list[dict]) -> dict | None:
        """A phase-resonance run's lock (decision records 0044, 0046): the latest block's
        frequency, phase error and response amplitude (its ``lock_block`` event) and each
        stored point; None for other procedures."""
        if plan is None or plan.procedure is not ProcedureKind.PHASE_RESONANCE:
            return None
        blocks = [e for e in events if e.get("event") == LOCK_EVENT]
        points = [dict(level_N=r.get("target_force_N"), **{k: r["backbone"].get(k) for k in (
            "frequency_Hz", "amplitude_m", "phase_error_deg", "damping_ratio", "locked", "why", "periods")})
            for r in sorted(results, key=lambda r: r.get("index", 0)) if isinstance(r.get("backbone"), dict)]
        return {"response": plan.backbone.response, "phase_target_deg": plan.backbone.phase_deg,
                "phase_band_deg": plan.backbone.phase_band_deg, "settle_periods": plan.backbone.settle_periods,
                "latest": blocks[-1] if blocks else None, "blocks": len(blocks), "points": points}

    @staticmethod
    def _modes(plan: Plan | None, results: list[dict], meta: dict) -> list[dict]:
        """Each mode per level as found so far (sim.modal, decision 0043; no model prediction:
        the page stays fast): a level needs at least 3 steps."""
        from sim.modal import LevelData, pitch_band_Hz, track_modes
        by_level: dict[int, list[dict]] = {}
        for r in results:
            if "compliance_m_per_N" in r and "accelerance_phase_rad" in r:
                by_level.setdefault(r.get("level_index", 0), []).append(r)
        try:
            data = [LevelData.from_steps(plan.levels_N[li] if plan and li < len(plan.levels_N)
                                         else rs[0].get("target_force_N"), rs)
                    for li, rs in sorted(by_level.items()) if len(rs) >= 3]
            from procedures.plan import stored_model
            model = stored_model(meta.get("rig"))
            band = pitch_band_Hz(model) if model else None
            # a rig model without a pitching mode: no pitch rows (decision 0056)
            modes = track_modes(data, pitch=not (model is not None and band is None),
                                pitch_band_Hz=band)
        except Exception as e:  # noqa: BLE001 - the page must come out; the rest of it is unaffected
            log.warning(_logged(SnapshotLine.NO_MODES, error=e))
            return []
        if band is None and not any(e.mode == "pitch" and e.ok for e in modes):
            modes = [e for e in modes if e.mode != "pitch"]
        keys = ("mode", "level_N", "status", "resonance_Hz", "resonance_low_Hz", "resonance_high_Hz", "damping_ratio",
                "damping_ratio_low", "damping_ratio_high", "edge_Hz", "n_points")
        return [{k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                 for k, v in ((k, getattr(e, k)) for k in keys)} for e in modes]

    @staticmethod
    def _identification(ident: list[dict], results: list[dict], meta: dict, analysis: dict | None = None) -> dict:
        """The online history and the final fit (the analysis' parameters once `bench analyze`
        has run: one parameter set per run, with its source); an estimate whose numbers
        overflowed or are absurd is shown as a failed fit with its reason, never as numbers
        (decision 0042)."""
        from ..numbers import insane, sane
        order = {r.get("key"): i + 1 for i, r in enumerate(sorted(results, key=lambda r: r.get("key", "")))}

        def ok(h: dict) -> bool:
            return all(sane(v) for v in (h.get("values") or {}).values())
        history = [dict(step=h.get("step"), steps_done=order.get(h.get("step"), h.get("steps_used")),
                        values=h.get("values"), low=h.get("low"), high=h.get("high"),
                        reduced_chi2=h.get("reduced_chi2"), misfit=bool(h.get("misfit")))
                   for h in ident if isinstance(h.get("values"), dict) and ok(h)]
        latest_warnings = ident[-1].get("warnings", []) if ident else []
        final = meta.get("identification")
        if isinstance(final, dict) and isinstance(final.get("values"), dict) and not ok(final):
            final = {"error": _message(PageMessage.FIT_FAILED, names=list(insane(final["values"])))}
        elif not (isinstance(final, dict) and isinstance(final.get("values"), dict)):
            final = None if not isinstance(final, dict) else {"error": final.get("error", _message(PageMessage.UNUSABLE))}
        if analysis is not None and ok(analysis):
            final = analysis
        try:
            expected: dict = stored_rig(meta["rig"], "run.json").guess()
        except (KeyError, TypeError, ConfigError):    # a damaged rig entry: the page shows none
            expected = dict.fromkeys(GUESS_KEYS)
        return dict(history=history, latest_warnings=latest_warnings, final=final, expected=expected)

    def _warnings(self, meta: dict, results: list[dict]) -> list[dict]:
        out = [dict(source="plan", text=w) for w in meta.get("identifiability_warnings", [])]
        for r in results:
            if r.get("force_converged") is False:
                out.append(dict(source="step", text=page.warning(PageWarning.FORCE_NOT_REACHED, dict(
                    key=r.get("key"), target_N=r.get("target_force_N"), error=r.get("force_error") or 0,
                    iterations=r.get("control_iterations")))))
        out += [dict(source="log", text=ln) for ln in self._log.read()]
        return out
