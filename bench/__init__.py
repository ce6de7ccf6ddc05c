"""The bench application: command line, configuration, storage, reports, and the public
Python API (``import bench``; decision record 0055).

    rig = bench.load_rig(path)            plan = bench.load_plan(path)
    run = bench.run(plan, rig, out)       run = bench.open_run(path)
    run.steps(), run.modes(), run.backbone(), run.identification
    run.resume(), run.report(), run.export(), run.analyze(), run.check()

The names are loaded on first use (``import bench`` stays light, so the command line
starts, and installs its signal handlers, before numpy and the rest are imported).
Everything not listed in ``__all__`` is private.
"""

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("guideway-bench")
except _metadata.PackageNotFoundError:      # a source tree that was never installed
    __version__ = "unknown"

# name -> the module that defines it
_API = {name: "bench.api" for name in ("Run", "STEP_COLUMNS", "load_plan", "load_rig", "open_run",
                                        "plan_from_dict", "rig_from_dict", "run")}
_API.update({"Plan": "procedures.plan", "Rig": "procedures.plan", "Limits": "procedures.plan",
             "BenchError": "sim.errors", "ConfigurationError": "sim.errors", "EnvelopeError": "sim.errors",
             "LimitError": "sim.errors", "InstrumentError": "sim.errors", "RunDirectoryError": "sim.errors",
             "StorageError": "sim.errors"})

__all__ = ["__version__", *sorted(_API)]


def __getattr__(name: str):
    if name in _API:
        import importlib
        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value           # once
        return value
    raise AttributeError(f"module 'bench' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
