"""The live page's words (``bench watch``, decision 0067), by code.

``WARNING``: the warnings the page lists (:class:`bench.watch.snapshot.PageWarning`) other
than the plan's identifiability warnings and the log's lines, which it shows as they were
written.
"""

from __future__ import annotations

from . import Words, say

WARNING: Words = {
    "force_not_reached": lambda key, target_N, error, iterations: (f"{key}: force {target_N:g} N not reached "
                                                                   f"(error {100 * error:+.1f} %, {iterations} "
                                                                   "iterations)"),
}


def warning(code: str, fields) -> str:
    """A warning of the page in words."""
    return say(WARNING, code, fields)
