"""`bench analyze` on a UFF58 file as another program writes it (no bench tags): plant data
with viscous damping hidden in it, written with pyuff's own dataset builder (function type
1, ordinate data types 13/12/8, abscissa increment 1/fs), analysed through the CLI."""
import hashlib
import json

import numpy as np
import pytest

from bench.cli import main
from benchtools.twin_sources import write_foreign_uff
from sim.discrepancy.cases import make_case


def within_interval(truth: float, q: dict) -> None:
    """The true value within the analysis's own 95 % interval (widened to 2x its half-width,
    about 4 standard errors): what the fit promises (observed: 0.15 % and 0.003 % off,
    inside intervals of +-0.18 % and +-0.01 %; the tolerances were 5 % and 10 %)."""
    centre, half = (q["low"] + q["high"]) / 2, (q["high"] - q["low"]) / 2
    assert 0 < half < 0.01 * truth, q
    assert abs(truth - centre) <= 2 * half, (truth, q)


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    d = tmp_path_factory.mktemp("uff")
    # 3 levels x 8 frequencies: 1.4 s of plant and 6.6 s of `bench analyze` (the 5 x 18 grid
    # took 25 s together; c then 0.15 % off inside +-0.18 %, decision 0062)
    case = make_case(5, ("viscous_damping",), levels=3, freqs=8)
    src = write_foreign_uff(case, d / "measured.uff")
    digest = hashlib.sha256(src.read_bytes()).hexdigest()
    rc = main(["analyze", str(src)])
    return case, src, digest, rc


@pytest.mark.timeout(300)
def test_analyze_names_the_cause_in_a_foreign_uff_file_and_writes_the_schema(analysed):
    case, src, digest, rc = analysed
    assert rc == 0
    out = src.parent / "measured_analysis" / "analysis.json"
    d = json.loads(out.read_text())
    assert d["schema"] == "guideway-bench/analysis/2"
    assert list(d["parameters"]) == list(d["base"]["parameters"]) == ["F_s_N", "x_s_m", "n", "mass_kg"]
    for key in ("source", "software_version", "parameters", "base", "causes", "unexplained", "verdict",
                "candidates", "steps_used", "steps_rejected", "steps", "loops"):
        assert key in d
    assert [c["id"] for c in d["causes"]] == ["viscous_damping"], d["verdict"]
    c = d["causes"][0]["parameters"]["c"]
    within_interval(case.effects["viscous_damping"]["viscous_N_s_per_m"], c)
    assert len(d["steps_used"]) == len(case.steps) and d["steps_rejected"] == []
    st = d["steps"][0]
    assert len(st["measured"]["compliance"]) == 2 and len(st["final"]["accelerance"]) == 2
    assert d["loops"] and len(d["loops"][0]["disp_m"]) == len(d["loops"][0]["friction_final_N"])
    # the final model predicts the measured compliance better than the base model
    err = lambda which: np.median([abs(complex(*s[which]["compliance"]) / complex(*s["measured"]["compliance"]) - 1)
                                   for s in d["steps"]])
    assert err("final") < err("base")
    assert (out.parent / "analysis.html").stat().st_size > 0             # bench.reports renders the page
    assert hashlib.sha256(src.read_bytes()).hexdigest() == digest      # nothing the user gave is modified


def test_analyze_of_a_missing_source_is_a_clear_error(tmp_path, capsys):
    assert main(["analyze", str(tmp_path / "nope.uff")]) == 2


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_analyze_a_run_made_through_the_twins_names_the_viscous_damping(tmp_path):
    """A real run (SCPI, CAN FD, Modbus twins) on a rig with viscous damping (5 % of critical
    at the 50 Hz friction resonance), then `bench analyze RUN` with the run's own rig."""
    import tomllib

    from bench.config import DEFAULTS, parse_plan, parse_rig
    from bench.session import run_plan

    plan = tomllib.loads((DEFAULTS / "demo_plan.toml").read_text())
    # 3 levels x 6 frequencies (4 x 9 until decision 0083)
    plan["plan"]["levels_N"] = [1.0, 3.0, 8.5]
    plan["plan"]["frequencies"] = dict(list_Hz=[20.0, 32.0, 42.0, 50.0, 80.0, 150.0], direction="up")
    plan["plan"]["infeasible"] = "skip"
    plan["plan"].pop("resonance")            # these steps only (the demo plan refines its resonances)
    rig = tomllib.loads((DEFAULTS / "sim_rig.toml").read_text())
    rig["rig"]["model"].update(viscous_N_s_per_m=314.0, seed=7)
    run = tmp_path / "run"
    store = run_plan(parse_plan(plan), parse_rig(rig), run, identify=False)
    assert store.metadata["status"] == "completed"
    assert main(["analyze", str(run)]) == 0
    d = json.loads((run / "analysis" / "analysis.json").read_text())
    assert [c["id"] for c in d["causes"]][:1] == ["viscous_damping"], d["verdict"]
    within_interval(314.0, d["causes"][0]["parameters"]["c"])
    # every step is used or rejected with its reason (bench.sources checks periodicity)
    assert len(d["steps_used"]) + len(d["steps_rejected"]) == len(store.results())
    assert all(r["reason"] for r in d["steps_rejected"]) and len(d["steps_used"]) >= 0.8 * len(store.results())
