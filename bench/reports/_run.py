"""The run, read once: a typed record of what a run directory holds, for the renderers.

``load_run`` reads run.json, the steps, the events, the identification history and, if
present, ``analysis/analysis.json``; it groups the steps into sweeps (one force level, one
direction) and, for a simulated rig, computes the model comparison.  Nothing here draws
or formats: figures and renderers work from :class:`RunData` alone.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

from procedures.kind import ProcedureKind, Quantity, of_stored_plan

from ..files import read_file
from ..storage import Accounting, RunStore
from ._held import comparison_of
from ._identification import IdentificationData, identification_data
from ._model import ModelComparison
from ._modes import RunModes, modes_of
from ._steps import Series, legacy_pp, series_of

log = logging.getLogger(__name__)

ROUTINE_EVENTS = {"start", "end", "sensor", "output_off", "probe_noise", "refinement_end"}   # (0050)
# a phase-resonance run's progress (bench/backbone.py): each controller block, the probe
# blocks and each point; a lost or missed lock is not progress and stays listed
PROGRESS_EVENTS = {"lock_block", "backbone_probe", "backbone_point"}
ANALYSIS_JSON = Path("analysis") / "analysis.json"
ANALYSIS_HTML = Path("analysis") / "analysis.html"


@dataclass(frozen=True)
class ProbeResolution:
    """The displacement probe's resolution (its rms noise at rest) and where it comes from."""

    rms_m: float
    source: str
    below: dict[str, float]          # step key -> displacement fundamental amplitude (m), below rms_m

    def sentence(self, key: str) -> str:
        return (f"below the probe's resolution: the displacement fundamental {1e9 * self.below[key]:.3g} nm is less "
                f"than the probe's noise {1e9 * self.rms_m:.3g} nm rms ({self.source}); the step still measures "
                f"force and acceleration (accelerance, mass), its displacement carries little weight in the fit")


def probe_resolution(meta: dict, results: list[dict], events: list[dict]) -> ProbeResolution | None:
    """The probe's rms noise at rest as the run measured it (event ``probe_noise``), else the
    simulated rig model's ``disp_noise_m``; None when neither is known."""
    rms, source = math.nan, ""
    for e in events:
        if e.get("event") == "probe_noise":
            rms, source = float(e.get("rms_m") or math.nan), "measured at rest before the run"
    rig = meta.get("rig") or {}
    if not (math.isfinite(rms) and rms > 0) and rig.get("simulated"):
        from procedures.plan import stored_model
        from sim.rig import RigModel
        model = stored_model(rig) or RigModel()          # a run that stored no model ran the default one
        rms, source = float(model.disp_noise_m), "the simulated rig model's disp_noise_m"
    if not (math.isfinite(rms) and rms > 0):
        return None
    below = {}
    for r in results:
        try:
            a1 = float(r["disp"]["amplitude"][0])
        except (KeyError, IndexError, TypeError, ValueError):
            continue
        if a1 < rms:
            below[r["key"]] = a1
    return ProbeResolution(rms, source, below)


@dataclass
class RunData:
    """Everything the run report shows, read and computed once."""

    path: Path
    meta: dict
    results: list[dict]
    events: list[dict]
    levels_N: list[float]
    series: list[Series]
    ident: IdentificationData
    comparison: ModelComparison | None        # simulated rig with a stored model only
    comparison_error: str | None              # why the comparison failed, if it did
    modes: RunModes | None                    # each mode per level (sim.modal, decision 0043)
    analysis: dict | None                     # analysis/analysis.json, when `bench analyze` wrote it
    analysis_error: str | None                # why analysis.json could not be read, if so
    accounting: Accounting | None = None      # the steps counted against the plan (None: no plan stored)
    attention: list[tuple[str, str, str]] = field(default_factory=list)   # (step, rejected|flagged, why)
    attention_error: str | None = None        # why the step quality could not be computed, if so
    probe: ProbeResolution | None = None      # the probe's resolution and the steps that move less

    @property
    def below_resolution(self) -> dict[str, float]:
        """Step key -> displacement fundamental (m) of the steps that move less than the probe resolves."""
        return self.probe.below if self.probe else {}

    @property
    def plan(self) -> dict:
        return self.meta.get("plan") or {}

    @property
    def rig(self) -> dict:
        return self.meta.get("rig") or {}

    @property
    def title(self) -> str:
        origin = self.meta.get("origin")
        if isinstance(origin, dict) and origin.get("kind") == "imported":
            return f"{origin.get('name', '?')} (imported)"
        return f"{self.plan.get('name', '?')} on {self.rig.get('name', '?')}"

    @property
    def legacy(self) -> bool:
        return legacy_pp(self.results)

    @property
    def notable_events(self) -> list[dict]:
        return [e for e in self.events if e.get("event") not in ROUTINE_EVENTS | PROGRESS_EVENTS]

    @property
    def kind(self) -> ProcedureKind:
        """The procedure that ran (a plan stored before the field existed: a stepped sine)."""
        return of_stored_plan(self.plan)[0]

    @property
    def level_quantity(self) -> Quantity:
        """What the plan's levels are amplitudes of: every level is printed in its unit."""
        return of_stored_plan(self.plan)[1]

    def level(self, value: float) -> str:
        """A level with its unit: '3e-06 m', '1 N'."""
        return self.level_quantity.format(value)


def _analysis(run_dir: Path) -> tuple[dict | None, str | None]:
    path = run_dir / ANALYSIS_JSON
    if not path.is_file():
        return None, None
    try:
        d = json.loads(read_file(path))
        if not isinstance(d, dict):
            raise ValueError(f"expected a JSON object, got {type(d).__name__}")
        return d, None
    except (OSError, ValueError, RecursionError) as e:   # the report must come out; say why the analysis is missing
        log.warning("cannot read %s: %s", path, e)
        return None, f"{path} cannot be read: {e}"


def load_run(run_dir: Path) -> RunData:
    store = RunStore.open(Path(run_dir))
    accounting = store.account()         # first: a stored plan that is not valid is named (RunDirError)
    meta, results, events = store.metadata, store.results(), store.events()
    plan, rig = meta.get("plan") or {}, meta.get("rig") or {}
    levels_N = plan.get("levels_N") or sorted({r["target_force_N"] for r in results})
    series = series_of(results, levels_N)
    attention, attention_error = step_attention(store.path)
    flagged = None if attention_error else {k for k, _, _ in attention}
    cmp, cmp_error = None, None
    if results and rig.get("simulated") and rig.get("model"):
        try:
            cmp = comparison_of(meta, results, flagged)
        except Exception as e:
            log.warning("model comparison failed: %s", e)
            cmp_error = f"{type(e).__name__}: {e}"
    analysis, analysis_error = _analysis(store.path)
    return RunData(store.path, meta, results, events, list(levels_N), series,
                   identification_data(store.path, meta, analysis),
                   cmp, cmp_error, _modes(store.path, meta, results, cmp), analysis, analysis_error,
                   accounting, attention, attention_error, probe_resolution(meta, results, events))


def _modes(path: Path, meta: dict, results: list[dict], cmp: ModelComparison | None) -> RunModes | None:
    if not results:
        return None
    try:
        return modes_of(path, meta, results, cmp)
    except Exception as e:  # noqa: BLE001 - the report must come out; the section says why
        log.warning("modes of %s could not be estimated: %s", path, e)
        return None


def step_attention(run_dir: Path) -> tuple[list[tuple[str, str, str]], str | None]:
    """(step, "rejected" | "flagged", why) of every step that is not simply usable, by the
    one step quality check ``bench analyze`` applies (:meth:`bench.sources.Source.attention`)."""
    from ..sources import load_source
    try:
        return load_source(run_dir).attention(), None
    except Exception as e:  # noqa: BLE001 - the report must come out; say why the check is missing
        log.warning("step quality of %s could not be computed: %s", run_dir, e)
        return [], f"{type(e).__name__}: {e}"
