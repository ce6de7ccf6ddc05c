"""Hypothesis settings of the fuzz tests: seeded and small in CI, long by hand.

    GUIDEWAY_FUZZ=ci    (default) derandomized (the same examples every run), example
                        counts as written in each test: the whole of tests/fuzz/ in ~1 min
    GUIDEWAY_FUZZ=long  20x the examples, a fresh random seed each run (hypothesis prints
                        the seed and the failing example to reproduce), e.g.
                        GUIDEWAY_FUZZ=long .venv/bin/python -m pytest tests/fuzz -p no:cacheprovider
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

PROFILE = os.environ.get("GUIDEWAY_FUZZ", "ci")
if PROFILE not in ("ci", "long"):
    raise ValueError(f"GUIDEWAY_FUZZ={PROFILE!r}: expected 'ci' or 'long'")
SCALE = 20 if PROFILE == "long" else 1
TIME_BOUND_S = 5.0        # an answer (a result or a typed error) within this, per example


def fuzz(max_examples: int) -> settings:
    """Settings for one property: ``max_examples`` in CI, 20x in the long profile."""
    return settings(max_examples=max_examples * SCALE, derandomize=PROFILE == "ci", deadline=None,
                    database=None, print_blob=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.function_scoped_fixture])
