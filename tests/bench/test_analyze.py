"""`bench analyze` on a UFF58 file as another program writes it (no bench tags): plant data
with viscous damping hidden in it, written with pyuff's own dataset builder (function type
1, ordinate data types 13/12/8, abscissa increment 1/fs), analysed through the CLI."""
import hashlib
import json

import numpy as np
import pytest

from bench.cli import main
from sim.discrepancy.cases import make_case


def write_foreign_uff(case, path, periods=8):
    """One averaged period per channel repeated, with fresh sensor noise in every period
    (the issue's levels), as a record of ``periods`` periods."""
    import pyuff
    rng = np.random.default_rng(0)
    sets = []
    for s in case.steps:
        fs = s.fs_Hz
        for sdt, unit, rec, noise in ((13, "N", s.force_N, 0.003 * case.rig["F_s_N"]),
                                      (12, "m/s^2", s.accel_m_s2, 0.005 * np.std(s.accel_m_s2)),
                                      (8, "m", s.disp_m, 0.002 * case.rig["x_s_m"])):
            y = np.tile(rec, periods) + noise * rng.standard_normal(rec.size * periods)
            sets.append(pyuff.prepare_58(
                binary=1, id1=f"record {len(sets) + 1}", id2="other software", id3="NONE", id4="NONE", id5="NONE",
                func_type=1, ver_num=0, load_case_id=len(sets) // 3 + 1, rsp_ent_name="carriage", rsp_node=1,
                rsp_dir=1, ref_ent_name="shaker", ref_node=1, ref_dir=1, abscissa_spacing=1, abscissa_min=0.0,
                abscissa_inc=1.0 / fs, abscissa_spec_data_type=17, abscissa_axis_units_lab="s",
                ordinate_spec_data_type=sdt, ordinate_axis_units_lab=unit, orddenom_spec_data_type=0,
                data=y, x=np.arange(y.size) / fs))
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return path


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    d = tmp_path_factory.mktemp("uff")
    case = make_case(5, ("viscous_damping",))
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
    assert d["schema"] == "guideway-bench/analysis/1"
    for key in ("source", "software_version", "parameters", "base", "causes", "unexplained", "verdict",
                "candidates", "steps_used", "steps_rejected", "steps", "loops"):
        assert key in d
    assert [c["id"] for c in d["causes"]] == ["viscous_damping"], d["verdict"]
    c = d["causes"][0]["parameters"]["c"]
    assert c["value"] == pytest.approx(case.effects["viscous_damping"]["viscous_N_s_per_m"], rel=0.05)
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
    plan["plan"]["levels_N"] = [1.0, 3.0, 6.0, 8.5]
    plan["plan"]["frequencies"] = dict(list_Hz=[20.0, 22.0, 32.0, 42.0, 50.0, 60.0, 80.0, 110.0, 150.0],
                                       direction="up")
    plan["plan"]["infeasible"] = "skip"
    rig = tomllib.loads((DEFAULTS / "sim_rig.toml").read_text())
    rig["rig"]["model"].update(viscous_N_s_per_m=314.0, seed=7)
    run = tmp_path / "run"
    store = run_plan(parse_plan(plan), parse_rig(rig), run, identify=False)
    assert store.metadata["status"] == "completed"
    assert main(["analyze", str(run)]) == 0
    d = json.loads((run / "analysis" / "analysis.json").read_text())
    assert [c["id"] for c in d["causes"]][:1] == ["viscous_damping"], d["verdict"]
    assert d["causes"][0]["parameters"]["c"]["value"] == pytest.approx(314.0, rel=0.1)
    # every step is used or rejected with its reason (bench.sources checks periodicity)
    assert len(d["steps_used"]) + len(d["steps_rejected"]) == len(store.results())
    assert all(r["reason"] for r in d["steps_rejected"]) and len(d["steps_used"]) >= 0.8 * len(store.results())
