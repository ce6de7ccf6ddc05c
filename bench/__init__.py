"""The bench application: command line, configuration, storage, reports, and the public
Python API (``import bench``; decision record 0055).

    rig = bench.load_rig(path)            plan = bench.load_plan(path)
    run = bench.run(plan, rig, out)       run = bench.open_run(path)
    run.steps(), run.modes(), run.backbone(), run.identification
    run.resume(), run.report(), run.export(), run.analyze(), run.check()

Every name, ``__version__`` included, is looked up when first asked for: ``import bench``
stays light (importlib.metadata alone costs about 0.1 s), so the command line starts and
catches the ending signals before numpy and the rest are imported (decision 0051).
Everything not listed in ``__all__`` is private.
"""

from enum import StrEnum

# name -> the module that defines it
_API = {name: "bench.api" for name in ("Run", "STEP_COLUMNS", "load_plan", "load_rig", "open_run",
                                        "plan_from_dict", "rig_from_dict", "run")}
_API.update({"Plan": "procedures.plan", "Rig": "procedures.plan", "Limits": "procedures.plan",
             "BenchError": "sim.errors", "ConfigurationError": "sim.errors", "EnvelopeError": "sim.errors",
             "LimitError": "sim.errors", "InstrumentError": "sim.errors", "RunDirectoryError": "sim.errors",
             "StorageError": "sim.errors"})

__all__ = sorted(_API)          # and __version__


class _Missing(StrEnum):
    """A name ``bench`` does not have (its words: bench.words.terminal_config.API)."""

    NO_ATTRIBUTE = "no_attribute"           # module, name


def _version() -> str:
    from importlib import metadata
    try:
        return metadata.version("guideway-bench")
    except metadata.PackageNotFoundError:      # a source tree that was never installed
        return "unknown"


def __getattr__(name: str):
    if name == "__version__":
        value = _version()
    elif name in _API:
        import importlib
        value = getattr(importlib.import_module(_API[name]), name)
    else:
        from .words.terminal import refused
        raise refused(AttributeError, _Missing.NO_ATTRIBUTE, module=__name__, name=name)
    globals()[name] = value           # once
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API) | {"__version__"})
