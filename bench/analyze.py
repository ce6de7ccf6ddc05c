"""``bench analyze SOURCE``: where the Masing model is wrong in measured data, and why.

SOURCE (a run directory or a UFF58 file of time records) is read into steps by
:func:`bench.sources.load_source`; :func:`sim.discrepancy.analyze_steps` does the physics;
the measurement artefacts found in the time records (:mod:`sim.artefacts`, through the
source) are added to the causes with ``kind: "artefact"``; this module only picks the starting values (``--rig`` file, else the run's own rig, else
estimated from the data) and writes ``analysis.json`` (schema in docs/analysis.md) and
``analysis.html``.  An imported run (``bench import``: fundamentals only) is not analysed so:
:func:`analyze_imported` fits the friction models to its fundamentals instead
(:mod:`bench.fundamentals`, decision 0084).  Nothing in SOURCE is modified.
"""

from __future__ import annotations

import logging
from enum import StrEnum
from pathlib import Path

from sim.artefacts import artefact_causes
from sim.discrepancy import analyze_steps
from sim.errors import ConfigurationError

from . import __version__
from .reports import write_analysis_html
from .sources import SourceProblem, load_source
from .storage import write_json
from .words import terminal_data as words

log = logging.getLogger(__name__)


class AnalyzeSaid(StrEnum):
    """``bench analyze``'s refusal and log lines (words: :data:`bench.words.terminal_data.ANALYZE`)."""

    NO_STEPS = "no_steps_to_analyse"        # path, rejected: [{step, reason}]
    ANALYSING = "analysing"                 # steps, path, rejected: counts
    ARTEFACT = "artefact"                   # sentence: the artefact cause's (sim.artefacts)
    VERDICT = "verdict"                     # verdict: the analysis' (sim.discrepancy)
    IMPORTED = "imported_fundamentals"      # run, path: an imported run (bench import) holds fundamentals only
    FUNDAMENTALS = "analysing_fundamentals"  # levels, points, path: an imported run, the fit to fundamentals


def default_out_dir(source: Path) -> Path:
    """SOURCE/analysis for a run directory, <stem>_analysis next to a file."""
    return source / "analysis" if source.is_dir() else source.parent / f"{source.stem}_analysis"


def _guess(source: Path, rig: Path | None) -> tuple[dict | None, float | None]:
    """Starting values (None: from the data) and the rig file's friction_v_ref_m_per_s
    (None: the file names none), at which a velocity-dependent friction is stated."""
    from .config import load_rig, parse_rig, rig_toml
    if rig is not None:
        r = load_rig(rig)
    elif source.is_dir() and (source / "run.json").exists():
        from .storage import RunStore
        r = parse_rig({"rig": rig_toml(RunStore.open(source).metadata["rig"])}, f"{source}/run.json")
    else:
        return None, None     # a foreign file: start from the data themselves
    v_ref = r.model.friction_v_ref_m_per_s if r.model else None
    return r.guess(), float(v_ref) if v_ref else None


def imported_origin(source: Path) -> dict | None:
    """run.json's ``origin`` of an imported run (``bench import``), else None."""
    if not (Path(source) / "run.json").is_file():
        return None
    from .frf_import import origin_of
    from .storage import RunStore
    return origin_of(RunStore.open(Path(source)).metadata)


def refuse_imported(source: Path) -> None:
    """Refuse an imported run where time records are needed (``bench identify``): it holds
    the fundamentals only (``bench analyze`` fits them, :mod:`bench.fundamentals`)."""
    origin = imported_origin(source)
    if origin is not None:
        raise words.refused(ConfigurationError, AnalyzeSaid.IMPORTED, run=source, path=origin.get("file", "?"))


def analyze_imported(source: Path, out_dir: Path | None = None) -> dict:
    """An imported run: the friction models fitted to its fundamentals (decision 0084);
    ``analysis.json`` holds the ``fundamentals`` section, ``verdict`` its lines."""
    from sim.discrepancy.analysis import SCHEMA

    from .fundamentals import fit_run, fundamentals_section
    from .reports import write_fundamentals_html
    rl, fits = fit_run(Path(source))
    log.info("%s", words.said(AnalyzeSaid.FUNDAMENTALS, levels=len(rl.levels),
                              points=sum(lv.frequency_Hz.size for lv in rl.levels), path=source))
    section = fundamentals_section(rl, fits)
    result = {"schema": SCHEMA, "source": str(source), "software_version": __version__, "kind": "fundamentals",
              "fundamentals": section, "verdict": words.fundamentals_verdict(section), "causes": [],
              "unexplained": False}
    out = Path(out_dir) if out_dir else default_out_dir(source)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "analysis.json", result)
    write_fundamentals_html(result, out / "analysis.html")
    log.info("%s", words.said(AnalyzeSaid.VERDICT, verdict=result["verdict"]))
    return result


def analyze_source(source: Path, out_dir: Path | None = None, rig: Path | None = None, *, src=None) -> dict:
    """Analyse SOURCE, write ``analysis.json`` (and ``analysis.html``) to ``out_dir``; return the dict.
    ``src``: SOURCE already read by :func:`bench.sources.load_source` (not read again)."""
    source = Path(source)
    if not source.exists():
        raise words.refused(ConfigurationError, SourceProblem.NO_SUCH_SOURCE, path=source)
    if imported_origin(source) is not None:
        return analyze_imported(source, out_dir)
    src = src if src is not None else load_source(source)
    steps, rejected = list(src.steps), [dict(step=r.step, reason=r.reason) for r in src.rejected]
    if not steps:
        raise words.refused(ConfigurationError, AnalyzeSaid.NO_STEPS, path=source, rejected=rejected)
    guess, v_ref = _guess(source, Path(rig) if rig else None)
    log.info("%s", words.said(AnalyzeSaid.ANALYSING, steps=len(steps), path=source, rejected=len(rejected)))
    artefacts = artefact_causes(src.quality(), total=len(src.steps) + len(src.rejected))
    for c in artefacts:
        log.info("%s", words.said(AnalyzeSaid.ARTEFACT, sentence=c["sentence"]))
    analysis = analyze_steps(steps, guess, source=str(source), software_version=__version__, rejected=rejected,
                             v_ref_m_per_s=v_ref, artefacts=artefacts)
    result = analysis.to_dict()
    out = Path(out_dir) if out_dir else default_out_dir(source)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "analysis.json", result)
    write_analysis_html(result, out / "analysis.html")
    log.info("%s", words.said(AnalyzeSaid.VERDICT, verdict=result["verdict"]))
    return result
