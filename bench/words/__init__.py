"""The words a person reads, made at the edge (issue 35 item 1, decision 0067).

A decision is a value: a code (a ``StrEnum`` member, defined beside the code that decides)
and its fields (numbers, keys, file names).  The words are made here, by one renderer per
output, each a mapping from a code to a function of the fields that returns the words:

- :mod:`bench.words.terminal` (with ``terminal_config``, ``terminal_run`` and ``terminal_data``, split by
  subject, decision 0071): what ``bench`` prints and logs (``bench check``'s lines, a
  damaged step's one-line error);
- :mod:`bench.words.report`: the report's markdown (the same words as the terminal's where
  the report names the same thing; the module says which);
- :mod:`bench.words.page`: the live page's words (``bench watch``: the warnings it makes of
  the stored steps).

A renderer is keyed by the code's string, so the modules that decide import no renderer's
module and the renderers import no deciding module (no cycle between bench's modules).  Code
outside the renderers passes values; a test makes every renderer say codes only and checks
that nothing a decision depends on changes (tests/bench/test_decisions_are_values.py).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

Words = Mapping[str, Callable[..., str]]


@dataclass(frozen=True)
class Said:
    """A decision's value: its ``code`` (a ``StrEnum`` member beside the deciding code) and
    its ``fields``; a renderer makes its words (:func:`say`)."""

    code: str
    fields: Mapping[str, Any] = field(default_factory=dict)


def say(words: Words, code: str, fields: Mapping[str, Any]) -> str:
    """The words ``words`` makes of ``code`` with ``fields`` (a code it has no words for is
    shown as itself, never an error while reporting an error)."""
    make = words.get(str(code))
    return make(**fields) if make is not None else f"{code} {dict(fields)}".rstrip(" {}")
