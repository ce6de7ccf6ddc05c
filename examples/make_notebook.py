"""Writes examples/tutorial.ipynb from the cells below (the notebook is generated, so its
source stays reviewable here; `python examples/make_notebook.py` after an edit)."""

import json
from pathlib import Path

CELLS = [
    ("markdown", """# guideway-bench from a notebook

Open the simulated rig, run a small stepped sine, plot the compliance per force level from the
run's table, look at its modes, and compare two lubricants (two rigs). Everything here is the
public API, `import bench`; the same calls drive the real rig when the rig file names its
instruments. The stop button is safe: it ends a run with the output ramped down, switched off
and confirmed, and `run.resume()` goes on."""),
    ("code", """import tomllib
from pathlib import Path

import matplotlib.pyplot as plt

import bench

DEFAULTS = Path(bench.__file__).parent / "defaults"
OUT = Path("tutorial_runs")
rig_a = bench.load_rig(DEFAULTS / "sim_rig.toml")
plan = bench.plan_from_dict({
    "name": "tutorial", "levels_N": [0.3, 3.0],
    "frequencies": {"start_Hz": 30.0, "stop_Hz": 150.0, "points": 7, "spacing": "log"},
    "control": {"settle_cycles": 8, "min_settle_s": 0.0, "measure_cycles": 8, "ramp_s": 0.05},
})
print(rig_a.name, "|", len(plan.schedule()), "steps")"""),
    ("code", """run_a = bench.run(plan, rig_a, OUT / "oil_a", labels={"lubricant": "A"}, report=False)
steps = run_a.steps()
print(run_a.status, len(steps), "steps")
steps[["target_force_N", "freq_Hz", "force_N", "compliance_abs_m_per_N", "thd_disp"]].head()"""),
    ("code", """fig, ax = plt.subplots(figsize=(6, 3.5))
for level, g in steps.groupby("target_force_N"):
    ax.loglog(g["freq_Hz"], g["compliance_abs_m_per_N"], "o-", label=f"{level:g} N")
ax.set_xlabel("frequency (Hz)"); ax.set_ylabel("|X1/F1| (m/N)"); ax.legend(title="force amplitude")
ax.set_title("oil A: compliance per force level");"""),
    ("code", """run_a.modes()[["mode", "level_N", "status", "resonance_Hz", "resonance_low_Hz", "resonance_high_Hz"]]"""),
    ("markdown", """A second lubricant: the same rig file with a friction curve that saturates later
(x_s 15 um instead of 10 um: a softer pre-rolling spring), built in code with the file's
checks (a bad value is named with its key and unit)."""),
    ("code", """data = tomllib.loads((DEFAULTS / "sim_rig.toml").read_text())
data["rig"]["model"]["x_s_m"] = 15e-6
rig_b = bench.rig_from_dict(data, source="oil B")
run_b = bench.run(plan, rig_b, OUT / "oil_b", labels={"lubricant": "B"}, report=False)
both = {"A": run_a.steps(), "B": run_b.steps()}
fig, ax = plt.subplots(figsize=(6, 3.5))
for name, df in both.items():
    g = df[df["target_force_N"] == 0.3]
    ax.loglog(g["freq_Hz"], g["compliance_abs_m_per_N"], "o-", label=f"oil {name}")
ax.set_xlabel("frequency (Hz)"); ax.set_ylabel("|X1/F1| (m/N) at 0.3 N"); ax.legend()
peak = {k: df.loc[df[df.target_force_N == 0.3].compliance_abs_m_per_N.idxmax(), "freq_Hz"] for k, df in both.items()}
print("peak compliance at 0.3 N:", peak)
assert peak["B"] < peak["A"], "a softer friction spring, a lower resonance\""""),
    ("code", """ident = run_a.identification
{k: (round(v, 9), round(ident["low"][k], 9), round(ident["high"][k], 9)) for k, v in ident["values"].items()}"""),
]


def cell(kind: str, text: str) -> dict:
    c = {"cell_type": kind, "metadata": {}, "source": text.splitlines(keepends=True)}
    if kind == "code":
        c.update(execution_count=None, outputs=[])
    return c


nb = {"nbformat": 4, "nbformat_minor": 5, "cells": [cell(k, t) for k, t in CELLS],
      "metadata": {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"},
                   "language_info": {"name": "python"}}}
for i, c in enumerate(nb["cells"]):
    c["id"] = f"cell-{i}"
Path(__file__).with_name("tutorial.ipynb").write_text(json.dumps(nb, indent=1) + "\n")
