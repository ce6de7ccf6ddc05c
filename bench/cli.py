"""Command line: `bench <command>`.  The application configures logging; libraries don't."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

log = logging.getLogger(__name__)


class Progress:
    """One status line with a bar and an ETA, redrawn in place on a terminal."""

    def __init__(self, label: str, stream=sys.stderr):
        self.label, self.stream, self.t0 = label, stream, time.monotonic()
        self.tty = stream.isatty()

    def __call__(self, done: int, total: int, note: str = "") -> None:
        frac = done / max(total, 1)
        el = time.monotonic() - self.t0
        eta = el / frac - el if frac > 0 else float("nan")
        bar = "#" * int(30 * frac)
        line = f"{self.label} [{bar:<30}] {done}/{total} {el:5.1f}s eta {eta:5.1f}s {note}"
        if self.tty:
            self.stream.write("\r" + line[:150].ljust(150))
            if done >= total:
                self.stream.write("\n")
        elif done >= total or done == 1 or done % max(1, total // 10) == 0:
            self.stream.write(line + "\n")
        self.stream.flush()


def cmd_paper(args) -> int:
    from sim.paper import reproduce

    out = Path(args.out)
    files = reproduce(out, quick=args.quick, progress=Progress("paper figures"))
    print(f"wrote {len(files)} files to {out}/ (start with {out}/README.md)")
    return 0


def cmd_frf(args) -> int:
    import numpy as np

    from sim.frf import find_peaks, frf_rk4
    from sim.shooting import frf_shooting

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


def cmd_demo(args) -> int:
    """The main job.  Until the stepped-sine procedure lands it reproduces the paper."""
    args.quick = False
    return cmd_paper(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bench", description=__doc__)
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("paper", help="redraw the seed paper's numerical figures (PNG + CSV)")
    s.add_argument("--out", default="out/paper")
    s.add_argument("--quick", action="store_true", help="coarse grids (seconds)")
    s.set_defaults(func=cmd_paper)

    s = sub.add_parser("demo", help="the main job: full run on the simulated rig with its report")
    s.add_argument("--out", default="out/demo")
    s.set_defaults(func=cmd_demo)

    s = sub.add_parser("frf", help="compliance G(beta) of the model at one force level (CSV to stdout)")
    s.add_argument("--gamma0", type=float, default=0.6)
    s.add_argument("--n", type=float, default=1.5)
    s.add_argument("--beta-min", type=float, default=0.2)
    s.add_argument("--beta-max", type=float, default=2.0)
    s.add_argument("--points", type=int, default=200)
    s.add_argument("--engine", choices=("shooting", "rk4"), default="shooting")
    s.set_defaults(func=cmd_frf)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except ValueError as e:  # bad input: say what is wrong, no traceback
        log.error("%s", e)
        return 2
    except KeyboardInterrupt:
        log.error("interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
