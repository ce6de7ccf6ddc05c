"""Run the lab's quick plan and print its compliance per step (public API only).

    python scripts/run_quick.py OUT [RIG_FILE]
"""

import sys
from pathlib import Path

import bench

HERE = Path(__file__).resolve().parent.parent


def main(out: str, rig_file: str | None = None) -> int:
    rig = bench.load_rig(rig_file) if rig_file else bench.load_rig(Path(bench.__file__).parent / "defaults" / "sim_rig.toml")
    plan = bench.load_plan(HERE / "plans" / "quick.toml")
    bench.run(plan, rig, out, labels={"script": "run_quick"}, report=False)
    run = bench.open_run(out)                    # what another script, later, reads back
    steps = run.steps()
    assert len(steps) == len(plan.schedule()), "a step is missing"
    print(f"{run.status}: {len(steps)} steps")
    for row in steps.itertuples():
        print(f"{row.target_force_N:6.2f} N {row.freq_Hz:8.2f} Hz  |X/F| {row.compliance_abs_m_per_N:.4e} m/N")
    return 0 if run.status == "completed" else 1


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
