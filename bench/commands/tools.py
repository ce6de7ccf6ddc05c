"""`bench paper`, `frf`, `warmup`, `twins` and `twin`: the simulated rig's tools (argument
handling and printing)."""

from __future__ import annotations

import logging
import sys
from enum import StrEnum
from pathlib import Path

from sim.errors import ConfigurationError

from ..terminal import Progress
from ..words import terminal_data as words
from . import ExitCode

log = logging.getLogger(__name__)


class ToolLine(StrEnum):
    """What these commands print, and their refusals (words:
    :data:`bench.words.terminal_data.TOOLS`)."""

    PAPER_PROGRESS = "paper_progress"       # the progress line's label
    PAPER_WROTE = "paper_wrote"             # count, out
    BAD_POINTS = "bad_points"               # points
    FRF_PROGRESS = "frf_progress"           # gamma0, n, engine
    FRF_PEAK = "frf_peak"                   # kind, beta, G
    COMPILING = "compiling"
    COMPILED = "compiled"                   # seconds
    NOT_SIMULATED = "not_simulated"         # rig: its file
    STOPPING_TWINS = "stopping_twins"
    TWIN_PARAMETERS = "twin_parameters"     # parameters: {name: {value, ...}}
    TWIN_APPLIED = "twin_applied"           # cause, keys: written to [rig.model]
    TWIN_NOT_IN_PLANT = "twin_not_in_plant"  # cause, reason
    TWIN_WROTE = "twin_wrote"               # rig, plan, twin: the paths
    TWIN_RUN_IT = "twin_run_it"             # rig, plan


def say(code: ToolLine, **fields) -> str:
    return words.said(code, **fields)


def cmd_paper(args) -> int:
    from sim.paper import reproduce

    out = Path(args.out)
    pitch_model, measured, name, others = None, None, "", []
    if args.rig:
        from ..config import load_rig
        from ..rig_model import paper_model
        models = [(Path(r).stem, paper_model(load_rig(Path(r)), r)) for r in args.rig]
        (name, pitch_model), others = models[0], models[1:]
    if args.runs:
        from ..reports import run_modes
        measured = []
        for r in args.runs:
            rm = run_modes(Path(r), model=False)
            measured.append({"label": rm.label, "rows": rm.rows()})
    files = reproduce(out, quick=args.quick, progress=Progress(say(ToolLine.PAPER_PROGRESS)), pitch_model=pitch_model,
                      measured=measured, pitch_name=name, other_models=others)
    print(say(ToolLine.PAPER_WROTE, count=len(files), out=out))
    return 0


def cmd_frf(args) -> int:
    import numpy as np

    from sim.frf import find_peaks, frf_rk4
    from sim.shooting import frf_shooting

    if args.points < 1:
        raise words.refused(ConfigurationError, ToolLine.BAD_POINTS, points=args.points)
    betas = np.linspace(args.beta_min, args.beta_max, args.points)
    prog = Progress(say(ToolLine.FRF_PROGRESS, gamma0=args.gamma0, n=args.n, engine=args.engine))
    if args.engine == "shooting":
        fr, _ = frf_shooting(betas, args.gamma0, args.n, progress=prog)
    else:
        fr = frf_rk4(betas, args.gamma0, args.n, progress=prog)
    print("beta,G,converged")
    for b, G, c in zip(fr.beta, fr.G, fr.converged):
        print(f"{b:.6g},{G:.6g},{int(c)}")
    for p in find_peaks(fr):
        print(say(ToolLine.FRF_PEAK, kind=p.kind, beta=p.beta, G=p.G), file=sys.stderr)
    return 0


def cmd_warmup(args) -> int:
    from ..warmup import warm_up
    if not args.verbose:
        logging.getLogger().setLevel(logging.ERROR)     # the warm-up run's chatter is noise here
    print(say(ToolLine.COMPILING), flush=True)
    print(say(ToolLine.COMPILED, seconds=warm_up()))
    return 0


def cmd_twins(args) -> int:
    from drivers import run_standalone
    from sim.rig import SimulatedRig

    from ..config import DEFAULTS, load_rig
    rig = load_rig(Path(args.rig) if args.rig else DEFAULTS / "sim_rig.toml")
    if not rig.simulated:
        raise words.refused(ConfigurationError, ToolLine.NOT_SIMULATED, rig=args.rig)
    import threading

    from ..signals import ENDING, handling
    stop = threading.Event()          # serving until a signal is this command's work: it ends it, exit 0
    with handling(lambda signum, frame: stop.set(), *ENDING):
        run_standalone(SimulatedRig(rig.model), args.host, serial_ports=args.serial, stop=stop)
    print(say(ToolLine.STOPPING_TWINS))
    return 0


def cmd_twin(args) -> int:
    """rig.toml and plan.toml of a simulated twin of the rig that measured SOURCE."""
    from ..twin import make_twin
    twin, paths = make_twin(Path(args.source), Path(args.analysis) if args.analysis else None,
                            Path(args.out) if args.out else None, plain=args.plain)
    print(say(ToolLine.TWIN_PARAMETERS, parameters=twin.parameters))
    for cid, keys in twin.applied.items():
        print(say(ToolLine.TWIN_APPLIED, cause=cid, keys=keys))
    if twin.shaker.get("note"):
        print(twin.shaker["note"])
    for item in twin.not_in_plant:
        print(say(ToolLine.TWIN_NOT_IN_PLANT, cause=item["cause"], reason=item["reason"]))
    print(say(ToolLine.TWIN_WROTE, rig=paths["rig"], plan=paths["plan"], twin=paths["twin"]))
    print(say(ToolLine.TWIN_RUN_IT, rig=paths["rig"], plan=paths["plan"]))
    return ExitCode.OK
