"""The small plans of the process tests and the benchmarks, written once.

A fast step (``FAST``): 4 settle and 4 measured periods, 2 control periods, no ramp and no
minimum settling time; a test that waits for "the first step with the output on" then
waits well under a second.
"""

from __future__ import annotations

FAST = dict(settle_cycles=4, min_settle_s=0.0, measure_cycles=4, control_cycles=2, ramp_s=0.0)
FAST_CONTROL = "[plan.control]\n" + "".join(f"{k} = {v!r}\n" for k, v in FAST.items())
FREQS = (60.0, 80.0, 100.0, 120.0)
MANY_FREQS = [40.0 + 10 * k for k in range(30)]        # far more steps than a test gets to

# the session-wide small run of tests/bench/conftest.py (a default-controlled sweep)
SMALL_PLAN = """
[plan]
name = "small test plan"
levels_N = [1.0, 5.0]
[plan.frequencies]
start_Hz = 30.0
stop_Hz = 300.0
points = 5
direction = "both"
"""


def fast_plan_toml(freqs=MANY_FREQS, *, name: str | None = None, direction: str | None = None,
                   extra: str = "") -> str:
    """A plan file at 1 N over ``freqs`` with fast steps; ``extra``: more TOML after it."""
    head = "[plan]\n" + (f'name = "{name}"\n' if name else "") + "levels_N = [1.0]\n"
    freq = "[plan.frequencies]\n" + f"list_Hz = {list(freqs)}\n" + (f'direction = "{direction}"\n' if direction else "")
    return head + freq + FAST_CONTROL + extra


def small_plan(levels=(1.0,), freqs=FREQS, limits=None):
    """A parsed plan: ``levels`` x ``freqs`` upwards with fast steps (and ``limits``)."""
    from bench.config import parse_plan
    plan = {"name": "exit paths", "levels_N": list(levels),
            "frequencies": {"list_Hz": list(freqs), "direction": "up"}, "control": dict(FAST)}
    if limits:
        plan["limits"] = limits
    return parse_plan({"plan": plan})
