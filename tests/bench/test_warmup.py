"""The warm-up (``bench warmup``, and the first run after an install, which compiles the
kernels before the user's plan): its own two-step run must not speak for the user's run.
Before, the first ``bench demo`` after an install printed the warm-up's warnings (its 1 N,
150-200 Hz plan has "no force level at or above the expected F_s", an unsettled step,
"F_s_N is poorly determined") above the demo, whose plan reaches 100 N."""

from __future__ import annotations

import logging

from bench.terminal import PROJECT
from bench.warmup import warm_up
from sim.friction import MODELS, iwan


def test_the_warm_up_s_own_run_says_no_warning_and_leaves_logging_as_it_was(caplog):
    before = {name: logging.getLogger(name).level for name in PROJECT}
    with caplog.at_level(logging.INFO):
        assert warm_up() > 0
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert not said, said
    # every friction model's compiled loop, and the Iwan elements' linear-fit loop, was compiled
    assert [name for name, m in MODELS.items() if type(m).rows is None] == ["masing"]      # its own loop
    loops = [type(m).rows for m in MODELS.values() if type(m).rows is not None] + [iwan._basis]
    assert all(loop.signatures for loop in loops)
    assert {name: logging.getLogger(name).level for name in PROJECT} == before
    logging.getLogger("bench.test").warning("heard")
    assert caplog.records[-1].getMessage() == "heard"
