"""The report's words (markdown, decision 0067), by code.

``PROBLEM``: a run directory's problems, as the terminal says them (the report lists the
steps it could not use with the words ``bench check`` prints for them).
"""

from __future__ import annotations

from . import Words, say
from .terminal import PROBLEM as _TERMINAL_PROBLEM

PROBLEM: Words = dict(_TERMINAL_PROBLEM)


def problem(code: str, fields) -> str:
    """A run directory's problem in the report's words."""
    return say(PROBLEM, code, fields)
