"""What the Masing model gets wrong in measured stepped-sine data, and why.

Public surface: :func:`analyze_steps` -> :class:`Analysis` (``to_dict()`` is the
analysis.json schema of docs/analysis.md), the catalog :data:`CATALOG`, the library of
force terms :data:`LIBRARY` (both in :data:`EFFECTS`, :mod:`sim.discrepancy.effects`), and the test-case
generator in :mod:`sim.discrepancy.cases`.
"""

from .analysis import SCHEMA, Analysis, analyze_steps
from .models import CATALOG, EFFECTS, LIBRARY

__all__ = ["SCHEMA", "Analysis", "analyze_steps", "CATALOG", "EFFECTS", "LIBRARY"]
