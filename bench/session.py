"""Run a plan on a rig: open the instruments, check the envelope, run, store, clean up.

Exit paths all end with the generator's output off: normal end, exception, Ctrl-C,
SIGTERM, SIGHUP, SIGQUIT, instrument error, lost connection, a storage error, safety
limit.  (kill -9 cannot be caught: on the real rig the generator then keeps its last
output; stored data stays intact.)  One session at a time holds a run directory and a
real rig's instruments (bench.runlock)."""

from __future__ import annotations

import logging
import math
import os
import platform
import socket
import sys
from contextlib import ExitStack
from dataclasses import dataclass, replace
from enum import StrEnum
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import numpy as np

from drivers import (
    CanFdDaq,
    Channel,
    ChannelSpec,
    InstrumentError,
    ModbusEddySensor,
    ScpiFunctionGenerator,
    open_can_bus,
    start_twins,
)
from procedures.factory import procedure_for
from procedures.kind import FORCE, ProcedureKind, Quantity
from procedures.online_id import OnlineIdentification, identifiability
from procedures.plan import StepSpec
from procedures.safety import LimitExceeded, SupervisedDaq, SupervisedGenerator, Supervisor, check_gap, tightest
from procedures.stepped_sine import StepResult
from sim.errors import EnvelopeError, StorageError

from . import runlock
from .config import Plan, Rig
from .signals import Doing, SignalLatch, uninterruptible
from .storage import RunStatus, RunStore, open_append, planned_count
from .watch import stop as stop_request
from .words import Said, say, terminal_run

log = logging.getLogger(__name__)

FORCE_MARGIN = 1.25      # control overshoot allowance: the envelope is checked at 1.25 x each level


class EnvelopeProblem(StrEnum):
    """A limit of the rig a (level, frequency) exceeds at FORCE_MARGIN x the level (its
    words: :data:`bench.words.terminal_run.ENVELOPE`)."""

    DRIVE = "drive"                         # drive_V (at the level), margin, limit_V
    FORCE = "force"                         # level_N, margin, limit_N
    DISPLACEMENT = "displacement"           # disp_m, level, unit, margin, response (a response's level), limit_m
    ACCELERATION = "acceleration"           # accel_m_s2, level, unit, margin, response, limit_m_s2


class EnvelopeRefusal(StrEnum):
    """Why a plan is refused before anything is opened (fields: points, margin)."""

    SKIP_IN_WINDOW = "skip_in_window"       # infeasible = "skip" inside a phase-resonance window
    NOT_HELD = "not_held"                   # steps the rig's limits cannot hold


class SessionLine(StrEnum):
    """What a session logs and shows while it runs (:data:`bench.words.terminal_run.SESSION`)."""

    SKIPPING = "skipping"                   # skipped, points
    IDENTIFIABILITY = "identifiability"     # warning
    OFF_UNCONFIRMED = "off_unconfirmed"     # error, url
    OFF_FAILED = "off_failed"               # url, error
    ABORTED = "aborted"                     # error
    INTERRUPTED = "interrupted"             # path
    INSTRUMENT_ERROR = "instrument_error"   # kind, error
    STORAGE_ERROR = "storage_error"         # error
    FAILED = "failed"
    END_UNRECORDED = "end_unrecorded"       # status, error
    EVENT_UNRECORDED = "event_unrecorded"   # kind, error
    ESTIMATES = "estimates"                 # F_s_N, x_s_m, n, mass_kg, at_bound, misfit (the status line's)


def said(code: SessionLine, **fields) -> str:
    return say(terminal_run.SESSION, code, fields)


@dataclass(frozen=True)
class EnvelopePoint:
    level: float             # in the plan's level unit (Plan.level_quantity: N, m or m/s^2)
    freq_Hz: float
    drive_V: float           # generator output amplitude (= Vpp/2) at the level, without the margin
    disp_m: float            # bounds at FORCE_MARGIN x the level
    accel_m_s2: float
    problems: tuple[Said, ...]   # EnvelopeProblem codes and their fields
    quantity: Quantity = FORCE   # what ``level`` is an amplitude of


def envelope(plan: Plan, rig: Rig) -> list[EnvelopePoint]:
    """Expected drive, peak displacement and acceleration of every (level, frequency).

    Drive: the generator's amplitude (V, = Vpp/2: the unit of ``drive_V`` and of the
    amplifier gain) at the level.  The limits are checked at FORCE_MARGIN x the level (the
    force control may overshoot), and a problem says so.  Displacement: free mass
    P/(m w^2) plus a pre-rolling allowance of 3 x_s; acceleration P/m (the free-mass bound,
    reached above the friction resonance); both at the margin."""
    lim = tightest(rig.limits, plan.limits)
    out = []
    # phase resonance: its frequency window's ends bound what the loop can drive
    window = (plan.backbone.min_Hz, plan.backbone.max_Hz) if plan.backbone else ()
    if plan.procedure is ProcedureKind.RESPONSE_CONTROLLED:
        return _response_envelope(plan, rig, lim)
    for F in plan.levels_N:
        for f in window or plan.freqs_Hz:
            Fp = F * FORCE_MARGIN
            w = 2 * math.pi * f
            drive = F / rig.amp_gain_N_per_V
            disp = Fp / (rig.expected_mass_kg * w * w) + 3 * rig.expected_x_s_m
            acc = Fp / rig.expected_mass_kg
            at = dict(level=F, unit=FORCE.unit, margin=FORCE_MARGIN, response=False)
            problems = tuple(p for p, bad in (
                (Said(EnvelopeProblem.DRIVE, dict(drive_V=drive, margin=FORCE_MARGIN, limit_V=lim.drive_V)),
                 drive * FORCE_MARGIN > lim.drive_V),
                (Said(EnvelopeProblem.FORCE, dict(level_N=F, margin=FORCE_MARGIN, limit_N=lim.force_N)),
                 Fp > lim.force_N),
                (Said(EnvelopeProblem.DISPLACEMENT, dict(disp_m=disp, limit_m=lim.disp_m, **at)), disp > lim.disp_m),
                (Said(EnvelopeProblem.ACCELERATION, dict(accel_m_s2=acc, limit_m_s2=lim.accel_m_s2, **at)),
                 acc > lim.accel_m_s2)) if bad)
            out.append(EnvelopePoint(F, f, drive, disp, acc, problems))
    return out


def _response_envelope(plan: Plan, rig: Rig, lim) -> list[EnvelopePoint]:
    """Response-controlled levels (decision 0044): the displacement and acceleration the
    level sets, at FORCE_MARGIN; the force and drive it needs are found by the control
    (given here as the free mass's, m w^2 X) and held by the supervisor's limits."""
    out = []
    q = plan.level_quantity
    for level in plan.levels_N:
        for f in plan.freqs_Hz:
            w2 = (2 * math.pi * f) ** 2
            X = (level if plan.response == "disp" else level / w2) * FORCE_MARGIN
            force = rig.expected_mass_kg * w2 * X / FORCE_MARGIN
            at = dict(level=level, unit=q.unit, margin=FORCE_MARGIN, response=True)
            problems = tuple(p for p, bad in (
                (Said(EnvelopeProblem.DISPLACEMENT, dict(disp_m=X, limit_m=lim.disp_m, **at)), X > lim.disp_m),
                (Said(EnvelopeProblem.ACCELERATION, dict(accel_m_s2=X * w2, limit_m_s2=lim.accel_m_s2, **at)),
                 X * w2 > lim.accel_m_s2)) if bad)
            out.append(EnvelopePoint(level, f, force / rig.amp_gain_N_per_V, X, X * w2, problems, q))
    return out


def envelope_report(points: list[EnvelopePoint]) -> str:
    """The plan's envelope as ``bench dry-run`` prints it (:func:`bench.words.terminal_run.envelope_table`)."""
    return terminal_run.envelope_table(points, FORCE_MARGIN)


def check_envelope(plan: Plan, rig: Rig) -> Plan:
    """The plan the rig can run: unchanged, or with infeasible steps skipped if the plan
    says ``infeasible = "skip"``; otherwise a plan with any infeasible step is refused."""
    points = envelope(plan, rig)
    bad = [p for p in points if p.problems]
    if bad and plan.infeasible == "skip":
        if plan.backbone:
            raise terminal_run.refused(EnvelopeError, EnvelopeRefusal.SKIP_IN_WINDOW, points=points,
                                       margin=FORCE_MARGIN)
        li = {F: i for i, F in enumerate(plan.levels_N)}
        fi = {f: i for i, f in enumerate(plan.freqs_Hz)}
        skip = tuple(sorted({(li[p.level], fi[p.freq_Hz]) for p in bad}))
        log.warning(said(SessionLine.SKIPPING, skipped=len(skip), points=len(points)))
        return replace(plan, skip=skip)
    if bad:
        raise terminal_run.refused(EnvelopeError, EnvelopeRefusal.NOT_HELD, points=points, margin=FORCE_MARGIN)
    return plan


CONTROL_ITERATIONS_EXPECTED = 3    # force-control iterations a step typically takes (rig time estimate)


def step_seconds(plan: Plan, f: float, *, from_rest: bool) -> float:
    """Rig time of one step at ``f``: force control (CONTROL_ITERATIONS_EXPECTED iterations of
    settle + acquire ``control_cycles``), settle, the measured block; from rest (a new sweep,
    a refinement step) also the ramp up and down (at least 40 periods or ``ramp_s`` each).
    Extra settle blocks are not counted (an estimate, not a bound)."""
    t = CONTROL_ITERATIONS_EXPECTED * 2 * plan.control_cycles / f
    t += max(plan.settle_cycles / f, plan.min_settle_s) + max(plan.measure_cycles / f, plan.min_measure_s)
    if from_rest:
        t += 2 * max(40 / f, plan.ramp_s)
    return t


def planned_steps(plan: Plan) -> tuple[int, int, float]:
    """(steps of the grid as they will run, refinement steps at most, expected rig time in s
    with the refinement budget used up): an adaptive plan counts its chosen number per
    sweep (at the sweep's median frequency each), a refined plan adds at most
    ``refine_steps`` per mode and level, each from rest, at the grid's geometric middle, and
    with ``dwell_cycles`` one dwell step per mode and level (counted with the refinement steps)."""
    from .storage import _sweeps
    steps = plan.schedule()
    by_key = {s.key: s for s in steps}
    n, t = 0, 0.0
    for keys in _sweeps(plan).values():
        sw = [by_key[k] for k in keys]
        k = min(len(sw), plan.adaptive_per_sweep) if plan.adaptive_per_sweep else len(sw)
        chosen = sw if k == len(sw) else [sorted(sw, key=lambda s: s.freq_Hz)[len(sw) // 2]] * k
        n += k
        t += sum(step_seconds(plan, s.freq_Hz, from_rest=i == 0) for i, s in enumerate(chosen))
    refined = plan.refine_steps * len(plan.refine_modes) * len(plan.levels_N) if plan.refine else 0
    if refined:
        fm = math.sqrt(min(plan.freqs_Hz) * max(plan.freqs_Hz))
        t += refined * step_seconds(plan, fm, from_rest=True)
        if plan.dwell_cycles:
            dwells = len(plan.refine_modes) * len(plan.levels_N)
            refined += dwells
            t += dwells * step_seconds(replace(plan, measure_cycles=max(plan.measure_cycles, plan.dwell_cycles)), fm,
                                       from_rest=True)
    return n, refined, t


def versions() -> dict:
    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for pkg in ("guideway-bench", "numpy", "scipy", "numba", "pyserial", "python-can", "cantools", "pymodbus"):
        try:
            out[pkg] = importlib_metadata.version(pkg)
        except importlib_metadata.PackageNotFoundError:
            out[pkg] = None
    return out


@dataclass
class Instruments:
    generator: ScpiFunctionGenerator
    daq: CanFdDaq
    sensor: ModbusEddySensor
    identities: dict
    sim_rig: object | None = None


def switch_off(gen: ScpiFunctionGenerator, url: str) -> bool:
    """Output off, confirmed by the instrument; over a new connection if the link is gone
    (a dropped connection, a rebooted LAN module).  True if confirmed.  Never raises: this
    runs on every exit path."""
    gen.safe_off()
    try:
        if not gen.output_enabled():
            return True
    except Exception as exc:  # noqa: BLE001 - try the new connection below
        log.warning(said(SessionLine.OFF_UNCONFIRMED, error=exc, url=url))
    try:
        with ScpiFunctionGenerator(url, timeout_s=gen.timeout_s) as again:
            again.set_output(False)
        return True
    except Exception as exc:  # noqa: BLE001
        log.error(said(SessionLine.OFF_FAILED, url=url, error=exc))
        return False


def open_instruments(rig: Rig, stack: ExitStack, *, sim_seed: int | None = None,
                     on_output_off=None) -> Instruments:
    """Open the three drivers (starting the twins first for a simulated rig).

    On closing ``stack`` the output is switched off first; ``on_output_off(confirmed)``
    is told whether the instrument confirmed it."""
    g_url, s_url, d_url = rig.generator_url, rig.sensor_url, rig.daq_url
    sim = None
    if rig.simulated:
        from sim.rig import RigModel, SimulatedRig
        model = rig.model or RigModel()
        sim = SimulatedRig(model if sim_seed is None else replace(model, seed=sim_seed))
        twins = stack.enter_context(start_twins(sim))
        g_url, s_url, d_url = twins.generator_url, twins.sensor_url, twins.daq_url
    gen = ScpiFunctionGenerator(g_url, drive_limit_V=rig.limits.drive_V)
    stack.callback(gen.close)

    def output_off() -> None:             # runs before close: output off on every exit path
        confirmed = switch_off(gen, g_url)
        if on_output_off:
            on_output_off(confirmed)
    stack.callback(output_off)
    gen.set_output(False)
    gen.configure_sine(drive_limit_V=rig.limits.drive_V)
    channels = (ChannelSpec(Channel.FORCE, rig.force_V_per_N, "N"),
                ChannelSpec(Channel.ACCELERATION, rig.accel_V_per_m_s2, "m/s^2"),
                ChannelSpec(Channel.DISPLACEMENT, rig.disp_V_per_m, "m"))
    daq = CanFdDaq(open_can_bus(d_url), channels)
    stack.callback(daq.close)
    sensor = ModbusEddySensor(s_url)
    stack.callback(sensor.close)
    ids = {"generator": gen.identify().__dict__, "sensor": sensor.identify().__dict__,
           "daq": {"url": d_url}}
    return Instruments(gen, daq, sensor, ids, sim)


def run_plan(plan: Plan, rig: Rig, out: Path, *, resume: bool = False, progress=None,
             sim_seed: int | None = None, identify: bool = True, retry_skipped: bool = False,
             labels: dict[str, str] | None = None, latch: SignalLatch | None = None) -> RunStore:
    """Run (or resume) ``plan`` on ``rig`` into the run directory ``out``.

    The plan is checked against the rig's limits before anything is opened; the run's
    status and the output-off confirmation are recorded whatever happens.  A resume does
    not measure again the steps skipped at run time (force unreachable, ``infeasible =
    "skip"``) unless ``retry_skipped`` (after raising a limit, say).  ``latch``: the
    program's (marked finished when the measuring is over: a signal during the switch-off
    or later is kept for the caller to decide, decision 0051); by default the run's own."""
    plan = check_envelope(plan, rig)
    warnings = identifiability(plan, rig) if plan.procedure is ProcedureKind.STEPPED_SINE else []
    latch = latch or SignalLatch()
    out = Path(out)
    if not resume:
        RunStore.check_new(out)            # before anything, the lock file included, is written
        out.mkdir(parents=True, exist_ok=True)
    else:
        RunStore.open(out)                 # a run directory (else a one-line error), before its lock
    with ExitStack() as held, latch.installed():
        held.enter_context(runlock.run_dir(out))          # one session at a time on a run directory ...
        if not rig.simulated:                             # ... and on an instrument (a simulated rig's are its own)
            for url in (rig.generator_url, rig.daq_url, rig.sensor_url):
                held.enter_context(runlock.instrument(url, out))
        latch.hold()          # a signal while the directory is set up acts once it says "running"
        store = _open_store(plan, rig, out, resume=resume, sim_seed=sim_seed, warnings=warnings)
        if labels:
            store.update(labels=labels)
        log_handler = _log_to(store.path / "bench.log")
        try:
            for w in warnings:              # judged before the run, said once its log is open
                log.warning(said(SessionLine.IDENTIFIABILITY, warning=w))
            _supervised(plan, rig, store, latch, progress=progress, sim_seed=sim_seed, identify=identify,
                        retry_skipped=retry_skipped)
        finally:
            if log_handler:
                logging.getLogger().removeHandler(log_handler)
                log_handler.close()
    return store


def _open_store(plan: Plan, rig: Rig, out: Path, *, resume: bool, sim_seed: int | None,
                warnings: list[str]) -> RunStore:
    """The run directory, new or resumed (damaged steps set aside to be measured again)."""
    if resume:
        store = RunStore.open(out)
        store.refuse_links(writing=True)    # a FIFO where the session appends would hold it
        store.set_aside_damaged()        # damaged steps are measured again, their files kept
        store.event("resume", done=len(store.done_keys()))
        store.update(status=RunStatus.RUNNING)
    else:
        store = RunStore.create(out, {"plan": plan.to_dict(), "procedure": plan.describe(), "rig": rig.to_dict(),
                                      "versions": versions(),
                                      "sim_seed": sim_seed, "identifiability_warnings": warnings})
    stop_request.clear(store.path)      # a request left from an earlier session is not for this one
    store.update(process={"pid": os.getpid(), "host": socket.gethostname()})   # watch: is it still alive?
    return store


def _supervised(plan: Plan, rig: Rig, store: RunStore, latch: SignalLatch, *, progress, sim_seed: int | None,
                identify: bool, retry_skipped: bool = False) -> None:
    """The safety path: open the instruments, measure, and on every way out ramp down,
    switch the output off (confirmed), close everything and record how the run ended.
    ``latch`` is installed and held: released here, inside the path that records the end."""
    status = RunStatus.FAILED
    sup: Supervisor | None = None
    unrecorded: StorageError | None = None
    with ExitStack() as stack:
        try:
            latch.release()            # a signal latched while the directory was set up acts now
            store.check_writable()     # a step can be stored, before the output goes on
            ins = open_instruments(rig, stack, sim_seed=sim_seed,
                                   on_output_off=lambda ok: _note(store, "output_off", confirmed=ok))
            store.update(identities=ins.identities)
            sup = Supervisor(tightest(rig.limits, plan.limits), ins.generator)
            _measure(plan, rig, store, ins, sup, latch, progress=progress, identify=identify,
                     retry_skipped=retry_skipped)
            status = RunStatus.COMPLETED
        except LimitExceeded as e:
            status = RunStatus.ABORTED
            _note(store, "abort", reason=str(e))
            log.error(said(SessionLine.ABORTED, error=e))
        except KeyboardInterrupt as e:
            status = RunStatus.INTERRUPTED
            _note(store, "interrupted", reason=str(e) or "Ctrl-C")
            if sup is not None:
                with uninterruptible(Doing.RAMP_DOWN, latch):
                    sup.shutdown()       # ramp down; the output is switched off below
            stop_request.clear(store.path)
            log.warning(said(SessionLine.INTERRUPTED, path=store.path))
            raise
        except InstrumentError as e:
            status = RunStatus.INSTRUMENT_ERROR
            _note(store, "instrument_error", error=f"{type(e).__name__}: {e}")
            log.error(said(SessionLine.INSTRUMENT_ERROR, kind=type(e).__name__, error=e))
        except StorageError as e:          # named, no traceback: the output goes off below
            _note(store, "storage_error", error=str(e))
            log.error(said(SessionLine.STORAGE_ERROR, error=e))
            raise
        except Exception as e:
            _note(store, "error", error=f"{type(e).__name__}: {e}")
            log.exception(said(SessionLine.FAILED))
            raise
        finally:
            latch.finish()   # the measuring is over: a signal now stops nothing (the switch-off runs on, 0051)
            with uninterruptible(Doing.SWITCH_OFF, latch):
                stack.close()    # output off, then close links and twins
                try:
                    done = store.done_keys()
                    refined = sum(1 for k in done if plan.refined_key_ok(k))   # refinement steps: counted as run
                    store.finish(status, steps_done=len(done), steps_total=planned_count(plan) + refined)
                except StorageError as e:
                    log.error(said(SessionLine.END_UNRECORDED, status=status, error=e))
                    unrecorded = e
    if unrecorded is not None:          # only when nothing else is on its way out
        raise unrecorded


def _note(store: RunStore, kind: str, **fields) -> None:
    """An event on an exit path: one that cannot be stored (a full disk) is logged, and
    the path goes on (the ramp-down, the switch-off)."""
    try:
        store.event(kind, **fields)
    except StorageError as e:
        log.error(said(SessionLine.EVENT_UNRECORDED, kind=kind, error=e))


def _measure(plan: Plan, rig: Rig, store: RunStore, ins: Instruments, sup: Supervisor, latch: SignalLatch,
             *, progress, identify: bool, retry_skipped: bool = False) -> None:
    """The stepped-sine test on supervised instruments, each step stored (and fed to the
    online identification) as it completes."""
    skipped = set() if retry_skipped or plan.infeasible != "skip" else set(store.skipped_at_run_time())
    gen = SupervisedGenerator(ins.generator, sup)
    daq = stop_request.StopOnRequest(SupervisedDaq(ins.daq, sup), store.path, also=latch.check)

    def sensor_check() -> dict:
        reading = check_gap(ins.sensor)
        store.event("sensor", gap_mm=reading.gap_mm, status=int(reading.status),
                    temperature_C=reading.temperature_C)
        return reading.__dict__

    # reference position with the output off
    rest = ins.daq.acquire_periods(100.0, 10).disp_m
    sup.x_ref_m = float(np.mean(rest))
    if plan.procedure is ProcedureKind.PHASE_RESONANCE:
        from .backbone import run_backbone
        run_backbone(plan, rig, store, gen, daq, sensor_check, marker=ins.generator, drive_limit_V=sup.limits.drive_V,
                     noise_floor_m=float(np.std(rest)), progress=progress)
        return
    kwargs: dict[str, Any] = dict(amp_gain_N_per_V=rig.amp_gain_N_per_V, sensor_check=sensor_check, marker=ins.generator,
                  drive_limit_V=sup.limits.drive_V,
                  on_skip=lambda step, why: store.event("step_skipped", key=step.key, reason=why))
    proc = procedure_for(plan, gen, daq, mass_kg=rig.expected_mass_kg, **kwargs)
    proc.preload(store.results())             # a resumed run: the force per volt measured so far
    proc.disp_noise_floor_m = float(np.std(rest))
    # the probe's resolution as this run saw it (the report names steps that move less)
    store.event("probe_noise", rms_m=proc.disp_noise_floor_m)
    if progress and hasattr(progress, "restart"):
        progress.restart(len(store.done_keys()))     # the ETA counts steps from here
    online = OnlineIdentification(store.path, rig, plan.harmonics) if identify and plan.procedure is ProcedureKind.STEPPED_SINE else None
    if online:
        online.preload(store.results(), store.raw)

    progress_note = [""]       # the latest estimates, shown on the status line

    def record(step: StepSpec, res: StepResult, raw: dict) -> None:
        store.write_step(step.key, res, raw)
        if online:
            est = online.update(res, raw)
            if est:
                v = est["values"]
                bound = est.get("at_bound", [])
                progress_note[0] = said(SessionLine.ESTIMATES, F_s_N=v["F_s_N"], x_s_m=v["x_s_m"], n=v["n"],
                                        mass_kg=v["mass_kg"], at_bound=bound, misfit=bool(est.get("misfit")))

    def show(done: int, total: int, note: str) -> None:
        if progress:
            progress(done, total, f"{note} | {progress_note[0]}")

    choose = None
    if plan.adaptive_per_sweep:
        from procedures.online_id import choose_frequencies
        choose = lambda sweep: choose_frequencies(           # noqa: E731
            sweep, online.current() if online else None, plan.adaptive_per_sweep)
    refiner = None
    if plan.refine:
        from procedures.resonance import Refiner
        band = None
        if rig.simulated and rig.model:
            from sim.modal import pitch_band_Hz
            band = pitch_band_Hz(rig.model)
        refiner = Refiner(plan, lambda: store.results(warn=False), band,
                          on_end=lambda **end: store.event("refinement_end", **end),       # decision 0050
                          no_pitch=bool(rig.simulated and rig.model) and band is None).next_step   # 0056
    proc.run(store.done_keys() | skipped, record, show, choose=choose, refine=refiner)
    if online:
        store.update(identification=online.final())


class _NoFollowFileHandler(logging.FileHandler):
    """A log file that is never opened through a symbolic link (bench.storage.open_append)."""

    def _open(self):
        return open_append(self.baseFilename)


def _log_to(path: Path) -> logging.Handler | None:
    """Add a root handler writing to ``path``; the caller removes it when the run ends."""
    root = logging.getLogger()
    if any(getattr(h, "baseFilename", None) == str(path) for h in root.handlers):
        return None
    h = _NoFollowFileHandler(path)
    h.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    root.addHandler(h)
    return h
