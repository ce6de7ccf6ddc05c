"""Studies and batch analysis on dask.distributed: the same command and the same numbers
on one machine (a LocalCluster, the default) or on a cluster (``scheduler="tcp://..."``).

- :func:`compliance_map` (:mod:`.maps`): G(beta, gamma0) for one or more n, one task
  per (n, gamma0) row, up and down sweeps, ridges and jump regions;
- :func:`identification_mc` (:mod:`.montecarlo`): how well a plan identifies the
  friction parameters on random rigs with noise;
- :func:`analyze_batch` (:mod:`.batch`): one per-source analysis over many sources, a
  summary table; :func:`map_cases` runs any picklable function over a list of arguments
  on the same engine (the analysis benchmark uses it).

The engine (:mod:`.engine`) writes one Parquet part per task and resumes by skipping the
parts that exist.  Names are imported lazily: ``bench --help`` need not load dask.
"""

import importlib
from enum import StrEnum

from ..words import terminal_data as words

_PUBLIC = {"Engine": "engine", "Outcome": "engine", "Study": "engine", "task_seed": "engine",
           "MapSpec": "maps", "compliance_map": "maps", "McSpec": "montecarlo",
           "identification_mc": "montecarlo", "analyze_batch": "batch", "map_cases": "batch"}

__all__ = sorted(_PUBLIC)


class StudiesSaid(StrEnum):
    """The package's own refusal (words: :data:`bench.words.terminal_data.STUDIES`)."""

    NO_ATTRIBUTE = "no_attribute"           # module, name


def __getattr__(name):
    if name in _PUBLIC:
        return getattr(importlib.import_module(f".{_PUBLIC[name]}", __name__), name)
    raise words.refused(AttributeError, StudiesSaid.NO_ATTRIBUTE, module=__name__, name=name)
