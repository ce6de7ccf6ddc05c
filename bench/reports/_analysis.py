"""The analysis of a source (``analysis.json``, schema "guideway-bench/analysis/2", written by
``bench analyze``; a file of schema 1 is read as 2, decision 0066), read once into typed records for the analysis page and the run report.

Reading is forgiving: every part but the dict itself is optional, and a part that is
missing or malformed leaves an empty record and a line in :attr:`AnalysisData.problems`,
which the renderers show, so a page always comes out and says what it could not show.
Complex first harmonics arrive as ``[re, im]`` pairs (compliance x/P in m/N, accelerance
a/P in m/s^2/N).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from sim.discrepancy.analysis import SCHEMA, stored_analysis

log = logging.getLogger(__name__)

FRF_QUANTITIES = ("compliance", "accelerance")
MODELS = ("measured", "base", "final")


@dataclass(frozen=True)
class Interval:
    """A value with its 95 % interval (NaN when not given)."""

    value: float
    low: float = math.nan
    high: float = math.nan
    unit: str = ""


@dataclass(frozen=True)
class Cause:
    id: str
    label: str
    parameters: dict[str, Interval]
    heldout_error_before: float
    heldout_error_after: float
    delta_bic: float
    kind: str = "catalog"                    # catalog | discovered | artefact
    formula: str = ""
    sentence: str = ""


@dataclass(frozen=True)
class RestoringForce:
    """Samples of the base model's residual force against displacement and velocity."""

    x_m: np.ndarray
    v_m_s: np.ndarray
    force_N: np.ndarray
    level_index: np.ndarray


@dataclass(frozen=True)
class Candidate:
    id: str
    delta_bic: float
    heldout_error: float                     # NaN when not computed (a candidate that failed the BIC gate)
    named: bool
    round: int | None = None                 # optional: the forward-selection round it was tried in


@dataclass(frozen=True)
class StepFRF:
    """One used step: first-harmonic compliance and accelerance, measured and modelled."""

    key: str
    level_N: float
    freq_Hz: float
    direction: str
    frf: dict[str, dict[str, complex]]       # model ("measured"/"base"/"final") -> quantity -> value
    residual_by_harmonic: np.ndarray         # of the base model, harmonic 1, 2, ...

    def get(self, model: str, quantity: str) -> complex:
        return self.frf.get(model, {}).get(quantity, complex(math.nan, math.nan))


@dataclass(frozen=True)
class Loop:
    """One period of a chosen step: friction against displacement."""

    key: str
    disp_m: np.ndarray
    friction_N: dict[str, np.ndarray]        # "meas" / "base" / "final" -> force (N), same length as disp_m
    level_N: float = math.nan                # optional
    freq_Hz: float = math.nan                # optional

    @property
    def title(self) -> str:
        where = ", ".join(f"{v:.3g} {u}" for v, u in ((self.level_N, "N"), (self.freq_Hz, "Hz")) if math.isfinite(v))
        return f"{self.key} ({where})" if where else self.key


@dataclass(frozen=True)
class ModelLoop:
    """One friction model's loop at one level: measured (P - m a with the model's mass) and
    modelled friction against displacement, and their rms difference."""

    key: str
    level_N: float
    disp_m: np.ndarray
    measured_N: np.ndarray
    model_N: np.ndarray
    rms_difference_N: float


@dataclass
class AnalysisData:
    source: str = ""
    software_version: str = ""
    verdict: str = ""
    unexplained: bool = False
    parameters: dict[str, Interval] = field(default_factory=dict)         # final model
    base_parameters: dict[str, Interval] = field(default_factory=dict)
    base_reduced_chi2: float = math.nan
    base_diagnostics: dict = field(default_factory=dict)
    base_heldout_error: float = math.nan      # optional: held-out error of the base model
    final_reduced_chi2: float = math.nan      # optional: "final": {"reduced_chi2": ...}
    causes: list[Cause] = field(default_factory=list)
    candidates: list[Candidate] = field(default_factory=list)
    steps_used: list[str] = field(default_factory=list)
    steps_rejected: list[tuple[str, str]] = field(default_factory=list)
    steps_flagged: list[tuple[str, str]] = field(default_factory=list)     # optional: used, with notes
    steps: list[StepFRF] = field(default_factory=list)
    loops: list[Loop] = field(default_factory=list)
    restoring_force: RestoringForce | None = None
    problems: list[str] = field(default_factory=list)   # parts that could not be read
    friction_model: str = "masing"                      # the friction model the data prefer (decision 0078)
    friction_table: list[dict] = field(default_factory=list)   # analysis.json friction_models.table
    friction_loops: dict[str, list[ModelLoop]] = field(default_factory=dict)   # model -> its loops, level by level


def _float(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _interval(d, unit: str = "") -> Interval:
    if isinstance(d, dict):
        return Interval(_float(d.get("value")), _float(d.get("low")), _float(d.get("high")),
                        str(d.get("unit", unit) or ""))
    return Interval(_float(d), unit=unit)


def _intervals(d) -> dict[str, Interval]:
    if d is None:
        return {}
    if not isinstance(d, dict):
        raise ValueError(f"expected an object of parameters, got {type(d).__name__}")
    return {str(k): _interval(v) for k, v in d.items()}


def _complex(v) -> complex:
    if isinstance(v, (list, tuple)) and len(v) == 2:
        return complex(_float(v[0]), _float(v[1]))
    raise ValueError(f"expected [re, im], got {v!r}")


def _cause(d: dict) -> Cause:
    gain = d.get("gain") or {}
    return Cause(str(d["id"]), str(d.get("label") or d["id"]), _intervals(d.get("parameters")),
                 _float(gain.get("heldout_error_before")), _float(gain.get("heldout_error_after")),
                 _float(gain.get("delta_bic")), str(d.get("kind") or "catalog"), str(d.get("formula") or ""),
                 str(d.get("sentence") or ""))


def _restoring(d) -> RestoringForce | None:
    if d is None:
        return None
    arrays = [np.asarray(d[k], dtype=float) for k in ("x_m", "v_m_s", "force_N", "level_index")]
    if len({a.shape for a in arrays}) != 1 or arrays[0].ndim != 1:
        raise ValueError("x_m, v_m_s, force_N and level_index must be lists of one length")
    return RestoringForce(*arrays[:3], arrays[3].astype(int))


def _candidate(d: dict) -> Candidate:
    rnd = d.get("round")
    return Candidate(str(d["id"]), _float(d.get("delta_bic")), _float(d.get("heldout_error")), bool(d.get("named")),
                     None if rnd is None else int(rnd))


def _step(d: dict) -> StepFRF:
    frf = {}
    for model in MODELS:
        part = d.get(model)
        if isinstance(part, dict):
            frf[model] = {q: _complex(part[q]) for q in FRF_QUANTITIES if q in part}
    level_N, freq_Hz = _float(d.get("level_N")), _float(d.get("freq_Hz"))
    if not (level_N > 0 and freq_Hz > 0 and math.isfinite(level_N) and math.isfinite(freq_Hz)):
        raise ValueError(f"step {d['key']!r}: level_N {d.get('level_N')!r} and freq_Hz {d.get('freq_Hz')!r} "
                         "must be finite and > 0")
    res = np.asarray([_float(x) for x in d.get("residual_by_harmonic") or []], dtype=float)
    return StepFRF(str(d["key"]), level_N, freq_Hz, str(d.get("direction") or ""), frf, res)


def _loop(d: dict) -> Loop:
    x = np.asarray(d["disp_m"], dtype=float)
    forces = {}
    for name in ("meas", "base", "final"):
        f = d.get(f"friction_{name}_N")
        if f is not None:
            f = np.asarray(f, dtype=float)
            if f.shape != x.shape:
                raise ValueError(f"friction_{name}_N has {f.size} points, disp_m {x.size}")
            forces[name] = f
    return Loop(str(d.get("key", "?")), x, forces, _float(d.get("level_N")), _float(d.get("freq_Hz")))


def _model_loop(d: dict) -> ModelLoop:
    x, meas, model = (np.asarray(d[k], dtype=float) for k in ("disp_m", "friction_meas_N", "friction_model_N"))
    if not x.ndim == 1 or meas.shape != x.shape or model.shape != x.shape:
        raise ValueError("disp_m, friction_meas_N and friction_model_N must be lists of one length")
    return ModelLoop(str(d.get("key", "?")), _float(d.get("level_N")), x, meas, model, _float(d.get("rms_difference_N")))


def _items(a: AnalysisData, d: dict, key: str, parse) -> list:
    """Parse each entry of the list ``d[key]``; a bad entry is left out and named in problems."""
    raw = d.get(key)
    if raw is None:
        return []
    if not isinstance(raw, list):
        a.problems.append(f"'{key}' is not a list ({type(raw).__name__}): not shown")
        return []
    out = []
    for i, item in enumerate(raw):
        try:
            out.append(parse(item))
        except (KeyError, TypeError, ValueError) as e:
            a.problems.append(f"'{key}' entry {i} cannot be read ({type(e).__name__}: {e}): left out")
    return out


def analysis_data(d: dict) -> AnalysisData:
    """The typed view of an analysis dict (see the module docstring for what is optional)."""
    if not isinstance(d, dict):
        raise TypeError(f"an analysis must be a dict (analysis.json's object), got {type(d).__name__}")
    d = stored_analysis(d)
    a = AnalysisData(source=str(d.get("source") or ""), software_version=str(d.get("software_version") or ""),
                     verdict=str(d.get("verdict") or ""), unexplained=bool(d.get("unexplained", False)))
    schema = d.get("schema")
    if schema is not None and schema != SCHEMA:
        a.problems.append(f"schema {schema!r}, this page reads {SCHEMA!r}: parts may be missing")
    for target, getter in (("parameters", lambda: d.get("parameters")),
                           ("base_parameters", lambda: (d.get("base") or {}).get("parameters"))):
        try:
            setattr(a, target, _intervals(getter()))
        except (AttributeError, TypeError, ValueError) as e:
            a.problems.append(f"'{target}' cannot be read: {e}")
    base = d.get("base") if isinstance(d.get("base"), dict) else {}
    a.base_reduced_chi2 = _float(base.get("reduced_chi2"))
    a.base_diagnostics = base.get("diagnostics") if isinstance(base.get("diagnostics"), dict) else {}
    a.base_heldout_error = _float(base.get("heldout_error"))
    a.final_reduced_chi2 = _float((d.get("final") if isinstance(d.get("final"), dict) else {}).get("reduced_chi2"))
    a.causes = _items(a, d, "causes", _cause)
    a.friction_model = str(d.get("friction_model") or "masing")
    fm = d.get("friction_models")
    a.friction_table = [r for r in (fm.get("table") or [] if isinstance(fm, dict) else []) if isinstance(r, dict)]
    for r in a.friction_table:
        if r.get("fitted") and r.get("loops") is not None:
            where = f"friction_models.table[{r.get('model')}].loops"
            a.friction_loops[str(r.get("model"))] = _items(a, {where: r["loops"]}, where, _model_loop)
    a.candidates = _items(a, d, "candidates", _candidate)
    a.steps_used = [str(k) for k in d.get("steps_used") or []]
    a.steps_rejected = _items(a, d, "steps_rejected", lambda r: (str(r["step"]), str(r.get("reason", "?"))))
    a.steps_flagged = _items(a, d, "steps_flagged", lambda r: (str(r["step"]), str(r.get("reason", "?"))))
    a.steps = _items(a, d, "steps", _step)
    a.loops = _items(a, d, "loops", _loop)
    try:
        a.restoring_force = _restoring(d.get("restoring_force"))
    except (KeyError, TypeError, ValueError) as e:
        a.problems.append(f"'restoring_force' cannot be read ({type(e).__name__}: {e}): not shown")
    for p in a.problems:
        log.warning("analysis: %s", p)
    return a


def level_groups(levels_N: np.ndarray, rel_tol: float = 0.05) -> np.ndarray:
    """Group index per step: levels within ``rel_tol`` of a group's smallest are one force
    level (measured, untagged levels scatter around the plan's)."""
    levels_N = np.asarray(levels_N, dtype=float)
    order = np.argsort(levels_N)
    group = np.zeros(levels_N.size, dtype=int)
    g, first = -1, -math.inf
    for i in order:
        if not levels_N[i] <= first * (1 + rel_tol):
            g, first = g + 1, levels_N[i]
        group[i] = g
    return group


def relative_error(model: complex, measured: complex) -> float:
    """|model - measured| / |measured| (NaN when either is missing)."""
    if not (np.isfinite(model) and np.isfinite(measured)) or measured == 0:
        return math.nan
    return abs(model - measured) / abs(measured)


FRICTION_HEAD = ["friction model", "parameters (95 %)", "held-out error, compliance", "held-out error, accelerance",
                 "reduced chi-square", "BIC"]


def friction_rows(a: AnalysisData) -> list[list[str]]:
    """The friction-model table's rows as plain text (the preferred model marked), for both
    renderers; a model not fitted says so."""
    rows = []
    for r in a.friction_table:
        name = f"{r.get('label', r.get('model'))} ({r.get('model')})" + (" - preferred" if r.get("model") == a.friction_model else "")
        if not r.get("fitted"):
            rows.append([name, "not fitted", "-", "-", "-", "-"])
            continue
        parts = []
        for k, p in (r.get("parameters") or {}).items():
            if isinstance(p, dict):
                parts.append(f"{k} = {_fmt(p.get('value'))} [{_fmt(p.get('low'))}, {_fmt(p.get('high'))}]")
            elif isinstance(p, list) and p and isinstance(p[0], dict):
                parts.append(f"{k}: {len(p)} elements")
        rows.append([name, "; ".join(parts) or "-", _pct_text(r.get("heldout_error_compliance")),
                     _pct_text(r.get("heldout_error_accelerance")), _fmt(r.get("reduced_chi2")), _fmt(r.get("bic"))])
    return rows


def _fmt(v) -> str:
    x = _float(v)
    return "-" if not math.isfinite(x) else f"{x:.4g}"


def _pct_text(v) -> str:
    x = _float(v)
    return "-" if not math.isfinite(x) else f"{100 * x:.3g} %"
