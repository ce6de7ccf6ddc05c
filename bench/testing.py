"""A pytest plugin for a lab's own CI: the simulated rig's instruments as real servers on
loopback, and the faults a lab wants its scripts tested against (decision record 0055).

Installed with the package (entry point ``pytest11``: ``guideway_bench``), so in any
project that has guideway-bench installed::

    def test_my_plan_runs(sim_rig, tmp_path):
        run = bench.run("plans/my_plan.toml", sim_rig, tmp_path / "run")
        assert run.status == "completed"

Fixtures:

- ``sim_rig``: the default simulated rig (``bench/defaults/sim_rig.toml``, or the file
  named by the ``guideway_rig`` ini option or ``--guideway-rig``) with its instruments
  started as servers on ephemeral loopback ports: the SCPI generator (TCP), the Modbus TCP
  sensor and the DAQ's CAN-over-TCP bridge.  It is a `bench.Rig` whose URLs point at
  them (``simulated = false``: the bench talks to them as to a real rig), so ``bench.run``,
  and a ``bench run`` process given `write_rig_file`'s file, accept it.
- ``sim_servers``: the `SimServers` behind ``sim_rig`` (the same servers), for fault
  injection: `SimServers.drop_out`.
- ``sim_rig_factory``: ``make(rig_file=None, *, seed=None, **model)`` starts another
  simulated rig, its model taken from a rig file and/or given as ``[rig.model]`` keys
  (``make(viscous_N_s_per_m=40.0)``); returns its `SimServers`.

Faults (plain functions, usable from any test):

- `interrupt_after`: a signal (SIGINT by default, the notebook's stop button) sent to
  this process once N steps are stored;
- `drop_out_after`: an instrument stops answering once N steps are stored;
- `with_limits`: the rig with tighter limits (a limit trip).

Every server binds to 127.0.0.1; nothing here sends traffic anywhere else.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from .words.terminal import refused
from .words.terminal_config import option

if TYPE_CHECKING:
    from drivers import Twins
    from procedures.plan import Rig
    from sim.rig import RigModel

INSTRUMENTS = ("generator", "daq")      # what drop_out can take away


class PluginRefusal(StrEnum):
    """What the plugin's helpers refuse (their words: bench.words.terminal_config.API)."""

    BAD_INSTRUMENT = "plugin_bad_instrument"    # call, allowed, got
    NOT_SIMULATED = "plugin_not_simulated"      # rig_file
    UNKNOWN_LIMITS = "plugin_unknown_limits"    # limits (sorted)


class PluginOption(StrEnum):
    """The plugin's option group and option (their help: bench.words.terminal_config.PLUGIN)."""

    GROUP = "group"
    RIG_FILE = "rig_file"


@dataclass
class SimServers:
    """A simulated rig served on loopback: ``rig`` (URLs set, ``simulated = false``), the
    running ``twins``, and ``model`` (the plant's sim.rig.RigModel)."""

    rig: Rig
    twins: Twins
    model: RigModel

    def drop_out(self, instrument: str) -> None:
        """``"generator"``: the SCPI server drops its connections and stops listening (the
        bench's next command fails: ConnectionLost); ``"daq"``: the DAQ stops sending blocks
        (the bench's next block times out: InstrumentTimeout)."""
        if instrument == "generator":
            self.twins.scpi_server.drop_connections()
            self.twins.scpi_server.close()
        elif instrument == "daq":
            self.twins.daq.close()
        else:
            raise refused(ValueError, PluginRefusal.BAD_INSTRUMENT, call="drop_out", allowed=INSTRUMENTS,
                          got=instrument)

    def close(self) -> None:
        self.twins.close()


def start_sim_rig(rig_file: str | Path | None = None, *, seed: int | None = None, host: str = "127.0.0.1",
                  **model: Any) -> SimServers:
    """Start a simulated rig's instruments as servers on ``host`` (loopback by default):
    the plant built from ``rig_file``'s ``[rig.model]`` (default: the bench's
    ``sim_rig.toml``) updated with ``model`` (checked as the file's keys are).  Close it
    with `SimServers.close`."""
    from drivers import start_twins
    from sim.rig import RigModel, SimulatedRig

    from .config import DEFAULTS, load_rig, parse_rig, rig_toml
    base = load_rig(Path(rig_file) if rig_file else DEFAULTS / "sim_rig.toml")
    if not base.simulated:
        raise refused(ValueError, PluginRefusal.NOT_SIMULATED, rig_file=rig_file)
    plant = base.model or RigModel()
    if model:     # the same checks and named errors as the rig file's [rig.model]
        data = rig_toml(base.to_dict())
        data["model"] = {**data.get("model", {}), **model}
        plant = parse_rig({"rig": data}, "sim_rig_factory(...)").model or plant
    if seed is not None:
        plant = replace(plant, seed=seed)
    twins = start_twins(SimulatedRig(plant), host)
    rig = replace(base, simulated=False, model=None, generator_url=twins.generator_url,
                  sensor_url=twins.sensor_url, daq_url=twins.daq_bridge_url)
    return SimServers(rig, twins, plant)


def write_rig_file(rig: Rig, path: str | Path) -> Path:
    """``rig`` as a rig file (TOML) at ``path``, for a ``bench`` process (``--rig path``)."""
    from .config import rig_toml
    path = Path(path)
    path.write_text(_toml({"rig": rig_toml(rig.to_dict())}))
    return path


def _toml(data: dict, prefix: str = "") -> str:
    """A small TOML writer for the rig layout (tables of strings, numbers and booleans)."""
    scalars = {k: v for k, v in data.items() if not isinstance(v, dict)}
    tables = {k: v for k, v in data.items() if isinstance(v, dict)}
    lines = [f"[{prefix}]"] if prefix and scalars else []
    for k, v in scalars.items():
        lines.append(f"{k} = {_value(v)}")
    out = "\n".join(lines) + ("\n\n" if lines else "")
    for k, v in tables.items():
        out += _toml(v, f"{prefix}.{k}" if prefix else k)
    return out


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    import json
    return json.dumps(str(v))


def with_limits(rig: Rig, **limits: float) -> Rig:
    """``rig`` with some of its limits replaced (``drive_V``, ``force_N``, ``disp_m``,
    ``accel_m_s2``), e.g. a force limit the plan's top level will trip."""
    unknown = set(limits) - {"drive_V", "force_N", "disp_m", "accel_m_s2"}
    if unknown:
        raise refused(ValueError, PluginRefusal.UNKNOWN_LIMITS, limits=sorted(unknown))
    return replace(rig, limits=replace(rig.limits, **limits))


def _stored_steps(out: Path) -> int:
    steps = Path(out) / "steps"
    return len(list(steps.glob("*.json"))) if steps.is_dir() else 0


@contextmanager
def _when_stored(out: str | Path, steps: int, action: Callable[[], None], timeout_s: float) -> Iterator[threading.Event]:
    """Run ``action`` in a thread once ``out`` holds ``steps`` stored steps; the event is set
    when it ran.  The watcher ends with the block (or after ``timeout_s``)."""
    done, stop = threading.Event(), threading.Event()

    def watch() -> None:
        t_end = time.monotonic() + timeout_s
        while not stop.is_set() and time.monotonic() < t_end:
            if _stored_steps(Path(out)) >= steps:
                action()
                done.set()
                return
            stop.wait(0.02)

    t = threading.Thread(target=watch, name="guideway-fault", daemon=True)
    t.start()
    try:
        yield done
    finally:
        stop.set()
        t.join(5)


def interrupt_after(out: str | Path, steps: int, signum: int = signal.SIGINT, *,
                    timeout_s: float = 600) -> AbstractContextManager[threading.Event]:
    """Within the block, send ``signum`` to this process once the run directory ``out``
    holds ``steps`` stored steps (SIGINT: what Ctrl-C and a notebook's stop button send)::

        with interrupt_after(out, 3), pytest.raises(KeyboardInterrupt):
            bench.run(plan, sim_rig, out)
    """
    return _when_stored(out, steps, lambda: os.kill(os.getpid(), signum), timeout_s)


def drop_out_after(servers: SimServers, out: str | Path, steps: int, instrument: str = "daq", *,
                   timeout_s: float = 600) -> AbstractContextManager[threading.Event]:
    """Within the block, ``servers.drop_out(instrument)`` once ``out`` holds ``steps`` steps."""
    if instrument not in INSTRUMENTS:
        raise refused(ValueError, PluginRefusal.BAD_INSTRUMENT, call="drop_out_after", allowed=INSTRUMENTS,
                      got=instrument)
    return _when_stored(out, steps, lambda: servers.drop_out(instrument), timeout_s)


# ---------------------------------------------------------------------------- pytest hooks and fixtures


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("guideway-bench", option(PluginOption.GROUP))
    group.addoption("--guideway-rig", default=None, help=option(PluginOption.RIG_FILE))
    parser.addini("guideway_rig", option(PluginOption.RIG_FILE), default="")


def _rig_file(config: pytest.Config) -> str | None:
    opt = config.getoption("--guideway-rig", default=None)
    ini = config.getini("guideway_rig")
    if opt:
        return str(opt)
    if ini:
        return str(Path(config.rootpath) / str(ini))
    return None


@pytest.fixture
def sim_rig_factory() -> Iterator[Callable[..., SimServers]]:
    """``make(rig_file=None, *, seed=None, **model) -> SimServers``; every rig it started is
    stopped after the test."""
    started: list[SimServers] = []

    def make(rig_file: str | Path | None = None, *, seed: int | None = None, **model: Any) -> SimServers:
        servers = start_sim_rig(rig_file, seed=seed, **model)
        started.append(servers)
        return servers

    yield make
    for s in reversed(started):
        s.close()


@pytest.fixture
def sim_servers(request: pytest.FixtureRequest, sim_rig_factory) -> SimServers:
    """The simulated rig's servers (see ``sim_rig``)."""
    return sim_rig_factory(_rig_file(request.config))


@pytest.fixture
def sim_rig(sim_servers: SimServers) -> Rig:
    """A `bench.Rig` whose instruments are the simulated rig's, served on loopback."""
    return sim_servers.rig
