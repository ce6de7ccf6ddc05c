"""`bench paper`, `frf`, `warmup`, `twins` and `twin`: the simulated rig's tools (argument
handling and printing)."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from sim.errors import ConfigurationError

from ..terminal import Progress
from . import ExitCode

log = logging.getLogger(__name__)


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
    files = reproduce(out, quick=args.quick, progress=Progress("paper figures"), pitch_model=pitch_model,
                      measured=measured, pitch_name=name, other_models=others)
    print(f"wrote {len(files)} files to {out}/ (start with {out}/README.md)")
    return 0


def cmd_frf(args) -> int:
    import numpy as np

    from sim.frf import find_peaks, frf_rk4
    from sim.shooting import frf_shooting

    if args.points < 1:
        raise ConfigurationError(f"--points must be >= 1, got {args.points}")
    betas = np.linspace(args.beta_min, args.beta_max, args.points)
    prog = Progress(f"FRF gamma0={args.gamma0} n={args.n} ({args.engine})")
    if args.engine == "shooting":
        fr, _ = frf_shooting(betas, args.gamma0, args.n, progress=prog)
    else:
        fr = frf_rk4(betas, args.gamma0, args.n, progress=prog)
    print("beta,G,converged")
    for b, G, c in zip(fr.beta, fr.G, fr.converged):
        print(f"{b:.6g},{G:.6g},{int(c)}")
    for p in find_peaks(fr):
        print(f"# {p.kind} resonance: beta={p.beta:.4f} G={p.G:.4f}", file=sys.stderr)
    return 0


def cmd_warmup(args) -> int:
    from ..warmup import warm_up
    if not args.verbose:
        logging.getLogger().setLevel(logging.ERROR)     # the warm-up run's chatter is noise here
    print("compiling the simulation kernels (once per machine and change of sim/) ...", flush=True)
    print(f"kernels compiled and cached in {warm_up():.0f} s")
    return 0


def cmd_twins(args) -> int:
    from drivers import run_standalone
    from sim.rig import SimulatedRig

    from ..config import DEFAULTS, load_rig
    rig = load_rig(Path(args.rig) if args.rig else DEFAULTS / "sim_rig.toml")
    if not rig.simulated:
        raise ConfigurationError(f"{args.rig}: not a simulated rig (simulated = true is needed)")
    import threading

    from ..signals import ENDING, handling
    stop = threading.Event()          # serving until a signal is this command's work: it ends it, exit 0
    with handling(lambda signum, frame: stop.set(), *ENDING):
        run_standalone(SimulatedRig(rig.model), args.host, serial_ports=args.serial, stop=stop)
    print("stopping twins")
    return 0


def cmd_twin(args) -> int:
    """rig.toml and plan.toml of a simulated twin of the rig that measured SOURCE."""
    from ..twin import make_twin
    twin, paths = make_twin(Path(args.source), Path(args.analysis) if args.analysis else None,
                            Path(args.out) if args.out else None, plain=args.plain)
    v = twin.parameters
    print("twin: " + ", ".join(f"{k} {v[k]['value']:.4g}" for k in ("F_s_N", "x_s_m", "n", "mass_kg")))
    for cid, keys in twin.applied.items():
        print(f"cause {cid} -> " + ", ".join(f"{k} = {x:.4g}" if isinstance(x, float) else f"{k} = {x}"
                                             for k, x in keys.items()))
    if twin.shaker.get("note"):
        print(twin.shaker["note"])
    for item in twin.not_in_plant:
        print(f"not in the plant: {item['cause']}: {item['reason']}")
    print(f"wrote {paths['rig']}, {paths['plan']} and {paths['twin']}")
    print(f"run it: bench run --plan {paths['plan']} --rig {paths['rig']} --out RUN")
    return ExitCode.OK
