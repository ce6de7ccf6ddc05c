"""What the tests and the benchmarks share (decision record 0057); not installed, not part
of the product.  The benchmarks import the product and this package, never ``tests``.

- ``procs``: `bench` in a process of its own, waiting on its run directory, signals;
- ``plans``: the small plans the process tests and benchmarks run;
- ``independent_masing``: an independent simulator (no code shared with ``sim``);
- ``twin_sources``: generated sources for ``bench twin``;
- ``identification``: the generated rigs of the identification acceptance tests.
"""

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
