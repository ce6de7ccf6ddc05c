"""Nothing hidden (issue 32 item 3, decision record 0056): a refinement that ends without
its peak known within the tolerance is an event, a status in modes.csv and a line in the
report; `bench dry-run` bounds the rig time (the simulated rig's clock never exceeds it)
and lists the steps it will run."""

from __future__ import annotations

import csv
import json

import pytest

from bench.cli import main
from bench.config import DEFAULTS, load_rig, parse_plan
from bench.plan_time import extra_block_seconds_max, planned_step_list, rig_time_bound_s
from bench.reports import run_modes
from bench.session import planned_steps, run_plan
from bench.storage import stored_plan


@pytest.fixture(scope="module")
def short_budget(tmp_path_factory):
    """1 N on the plain rig, 8 log points 40-160 Hz, the feed peak refined with a budget
    of 2 steps against a 0.05 % tolerance: the budget runs out."""
    plan = parse_plan({"plan": {"name": "short budget", "levels_N": [1.0],
                                "frequencies": {"start_Hz": 40.0, "stop_Hz": 160.0, "points": 8},
                                "control": {"harmonics": 5},
                                "resonance": {"refine": True, "modes": ["feed"], "max_steps": 2,
                                              "tolerance": 0.0005}}})
    store = run_plan(plan, load_rig(DEFAULTS / "sim_rig.toml"), tmp_path_factory.mktemp("budget") / "run",
                     identify=False)
    assert store.metadata["status"] == "completed"
    return store


def test_a_refinement_out_of_budget_is_an_event_a_status_and_a_report_line(short_budget, tmp_path):
    events = [json.loads(line) for line in (short_budget.path / "events.jsonl").read_text().splitlines()]
    told = [e for e in events if e["event"] == "refinement_end"]          # decision 0050's record
    assert len(told) == 1                       # once, however often the refiner was asked
    assert (told[0]["mode"], told[0]["level"], told[0]["reason"], told[0]["steps"]) == ("feed", 1.0,
                                                                                       "budget_spent", 2)
    assert main(["modes", str(short_budget.path), "--out", str(tmp_path / "m"), "--no-model"]) == 0
    (row,) = list(csv.DictReader(open(tmp_path / "m" / "modes.csv")))
    assert row["status"] == "not converged" and "budget" in row["note"]
    # the interval holds the measured maximum's bracket: the peak lies between its neighbours
    res = sorted(short_budget.results(), key=lambda r: r["freq_Hz"])
    i = max(range(len(res)), key=lambda k: res[k]["compliance_pp_m_per_N"])
    assert float(row["resonance_low_Hz"]) <= res[i - 1]["freq_Hz"]
    assert float(row["resonance_high_Hz"]) >= res[i + 1]["freq_Hz"]
    from bench.reports._markdown import modes_md
    from bench.reports._run import load_run
    md = "\n".join(modes_md(load_run(short_budget.path)))
    assert "Refinement not converged: feed mode at 1 N: the refinement budget" in md


def test_how_a_refinement_ended_follows_from_the_stored_steps(short_budget):
    """The outcome is the refiner's own decision replayed on the stored steps (no event
    needed): the same steps under a larger budget are a refinement the run stopped inside;
    test_modes' refined feed run converged and keeps "ok"."""
    from procedures.resonance import refinement_outcomes
    plan = stored_plan(short_budget.metadata)
    assert refinement_outcomes(plan, short_budget.results()) == {(0, "feed"): "budget_spent"}
    larger = parse_plan({"plan": {"name": "larger", "levels_N": [1.0],
                                  "frequencies": {"start_Hz": 40.0, "stop_Hz": 160.0, "points": 8},
                                  "resonance": {"refine": True, "modes": ["feed"], "max_steps": 20,
                                                "tolerance": 0.0005}}})
    assert refinement_outcomes(larger, short_budget.results()) == {(0, "feed"): "not finished"}
    # a plain rig's model has no pitching mode: its pitch is not chased, nor reported as not converged
    both = parse_plan({"plan": {"name": "both", "levels_N": [1.0],
                                "frequencies": {"start_Hz": 40.0, "stop_Hz": 160.0, "points": 8},
                                "resonance": {"refine": True, "modes": ["feed", "pitch"], "max_steps": 2,
                                              "tolerance": 0.0005}}})
    assert set(refinement_outcomes(both, short_budget.results(), no_pitch=True)) == {(0, "feed")}
    assert run_modes(short_budget.path, model=False).modes[0].status == "not converged"


def test_dry_run_bounds_the_rig_time_and_lists_the_steps(short_budget, tmp_path, capsys):
    plan = stored_plan(short_budget.metadata)
    res = short_budget.results()
    last = max(res, key=lambda r: r["t0_s"])
    actual = last["t0_s"] + last["n_samples"] / last["fs_Hz"]
    bound = rig_time_bound_s(plan)
    typical = planned_steps(plan)[2]
    calm = rig_time_bound_s(plan, extra_settle=False)
    extra = sum(r["settle_extra_blocks"] * extra_block_seconds_max(plan, r["freq_Hz"]) for r in res)
    assert actual <= calm + extra <= bound, (actual, calm, extra, bound, typical)
    assert calm + extra < 3.5 * actual, (actual, calm, extra)   # measured: 11.5 s against 30.8 + 4.1 s (bound 95.7 s)

    lines = planned_step_list(plan)
    assert [p.key for p in lines[:8]] == sorted(r["key"] for r in res if "-R" not in r["key"])
    assert lines[-1].key == "00007-L00-RF***-up" and lines[-1].count == 2
    plan_file = tmp_path / "p.toml"
    plan_file.write_text('[plan]\nlevels_N = [1.0, 3.0]\n[plan.frequencies]\nstart_Hz = 40.0\nstop_Hz = 160.0\n'
                         'points = 8\n[plan.resonance]\nrefine = true\nmodes = ["feed", "pitch"]\nmax_steps = 2\n'
                         'dwell_cycles = 100\n')
    assert main(["dry-run", "--plan", str(plan_file), "--steps"]) == 0
    out = capsys.readouterr().out
    assert "expected rig time: at most" in out
    assert "00000-L00-F000-up" in out and "00015-L01-F007-up" in out
    assert "00015-L01-RP***-up" in out and "refined, chosen online" in out
    assert "00015-L01-WF000-up" in out and "dwell of 100 cycles" in out
