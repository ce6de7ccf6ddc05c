"""``bench analyze SOURCE``: where the Masing model is wrong in measured data, and why.

SOURCE (a run directory or a UFF58 file of time records) is read into steps by
``bench.sources.load_source`` (contract 2); :func:`sim.discrepancy.analyze_steps` does the
physics; this module only picks the starting values (``--rig`` file, else the run's own
rig, else estimated from the data), writes ``analysis.json`` (schema in docs/analysis.md)
and, when ``bench.reports`` is there, ``analysis.html``.  Nothing in SOURCE is modified.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np

from sim.discrepancy import analyze_steps

from .storage import write_json

log = logging.getLogger(__name__)


def default_out_dir(source: Path) -> Path:
    """SOURCE/analysis for a run directory, <stem>_analysis next to a file."""
    return source / "analysis" if source.is_dir() else source.parent / f"{source.stem}_analysis"


def one_period(x: np.ndarray, fs_Hz: float, freq_Hz: float, points: int = 256) -> np.ndarray:
    """A record folded onto one period of ``freq_Hz`` and averaged in phase bins (at most
    ``points``, at most the samples per period; a bin no sample fell in is interpolated)."""
    points = max(8, min(points, int(fs_Hz / freq_Hz)))
    phase = (np.arange(x.size) * freq_Hz / fs_Hz) % 1.0
    b = np.minimum((phase * points).astype(int), points - 1)
    count = np.bincount(b, minlength=points)
    out = np.bincount(b, weights=x, minlength=points) / np.maximum(count, 1)
    filled = count > 0
    if not filled.all():
        i = np.arange(points)
        out = np.interp(i, i[filled], out[filled], period=points)
    return out


@dataclass(frozen=True)
class _Step:
    """The fields of ``bench.sources.MeasuredStep`` the analysis uses (fallback reader)."""

    key: str
    level_N: float
    freq_Hz: float
    harmonics: object
    fs_Hz: float
    force_N: np.ndarray | None
    accel_m_s2: np.ndarray | None
    disp_m: np.ndarray | None
    direction: str = ""


def _step_from_result(r: dict, raw: dict | None) -> _Step:
    from sim.identify import StepHarmonics
    recs = {}
    if raw is not None:
        fs = float(raw["fs_Hz"])
        recs = {k: one_period(np.asarray(raw[k], float), fs, r["freq_Hz"]) for k in ("force_N", "accel_m_s2", "disp_m")}
    level = r.get("target_force_N")
    if level is None or not math.isfinite(level):
        level = r["force_N"]
    return _Step(key=r["key"], level_N=float(level), freq_Hz=float(r["freq_Hz"]),
                 harmonics=StepHarmonics.from_result(r), fs_Hz=float(r.get("fs_Hz", 0.0)),
                 force_N=recs.get("force_N"), accel_m_s2=recs.get("accel_m_s2"), disp_m=recs.get("disp_m"),
                 direction=r.get("direction", ""))


def _load_fallback(source: Path) -> tuple[list, list[dict]]:
    """Run directory or UFF58 time records, read with storage/export (until bench.sources)."""
    steps, rejected = [], []
    if source.is_dir():
        from .storage import RunStore
        store = RunStore.open(source)
        for r in store.results():
            try:
                steps.append(_step_from_result(r, store.raw(r["key"])))
            except (KeyError, OSError, ValueError) as e:
                rejected.append(dict(step=r.get("key", "?"), reason=f"unreadable step: {e}"))
    else:
        from .export import import_uff58
        imp = import_uff58(source)
        for r in imp.steps:
            if r.get("source") != "uff58-time":
                rejected.append(dict(step=r["key"], reason="an FRF without time records (no force, "
                                                           "acceleration and displacement harmonics)"))
                continue
            steps.append(_step_from_result(r, imp.raw.get(r["key"])))
    return steps, rejected


def load_steps(source: Path) -> tuple[list, list[dict]]:
    """(steps, rejected) from ``bench.sources.load_source`` when available."""
    try:
        from .sources import load_source
    except ImportError:
        return _load_fallback(source)
    src = load_source(source)
    return list(src.steps), [dict(step=r.step, reason=r.reason) for r in src.rejected]


def _guess(source: Path, rig: Path | None) -> dict | None:
    from .config import load_rig, parse_rig
    if rig is not None:
        r = load_rig(rig)
    elif source.is_dir() and (source / "run.json").exists():
        from .cli import _rig_toml
        from .storage import RunStore
        r = parse_rig({"rig": _rig_toml(RunStore.open(source).metadata["rig"])}, f"{source}/run.json")
    else:
        return None           # a foreign file: start from the data themselves
    return dict(F_s_N=r.expected_F_s_N, x_s_m=r.expected_x_s_m, n=r.expected_n, mass_kg=r.expected_mass_kg)


def _version() -> str:
    try:
        return metadata.version("guideway-bench")
    except metadata.PackageNotFoundError:
        return "unknown"


def analyze_source(source: Path, out_dir: Path | None = None, rig: Path | None = None) -> dict:
    """Analyse SOURCE, write ``analysis.json`` (and ``analysis.html``) to ``out_dir``; return the dict."""
    source = Path(source)
    if not source.exists():
        raise ValueError(f"{source}: no such run directory or file")
    steps, rejected = load_steps(source)
    if not steps:
        raise ValueError(f"{source}: no usable steps ({len(rejected)} rejected"
                         + (f", first: {rejected[0]['step']}: {rejected[0]['reason']}" if rejected else "") + ")")
    guess = _guess(source, Path(rig) if rig else None)
    log.info("analysing %d steps of %s (%d rejected)", len(steps), source, len(rejected))
    analysis = analyze_steps(steps, guess, source=str(source), software_version=_version(), rejected=rejected)
    result = analysis.to_dict()
    out = Path(out_dir) if out_dir else default_out_dir(source)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "analysis.json", result)
    try:
        from .reports import write_analysis_html
    except ImportError:
        log.info("bench.reports is not installed: analysis.json only")
    else:
        write_analysis_html(result, out / "analysis.html")
    log.info("verdict: %s", result["verdict"])
    return result
