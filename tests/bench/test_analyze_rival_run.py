"""Issue 41 item 5 (decision 0078): a rival friction model hidden in the simulated rig
(decision 0075), measured through the twins by `bench run`, is named by `bench analyze RUN`
(analysis.json's friction_model), with Dahl's parameters covering the rig's."""

from __future__ import annotations

import json

import pytest

from benchtools.plans import fast_plan_toml
from benchtools.procs import bench_main

from .test_rig_friction import DAHL, rig_file

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]


def test_a_dahl_rig_measured_through_the_twins_is_named_dahl_by_bench_analyze(tmp_path):
    model = ('friction = "dahl"\n' + "".join(f"{k} = {v!r}\n" for k, v in DAHL.items())
             + "mass_kg = 10.0\nseed = 4\n")
    plan = tmp_path / "plan.toml"
    plan.write_text(fast_plan_toml([35.0, 45.0, 55.0, 70.0]).replace("levels_N = [1.0]", "levels_N = [3.0, 6.0, 12.0]"))
    run = tmp_path / "run"
    assert bench_main("run", "--plan", plan, "--rig", rig_file(tmp_path, model), "--out", run, "--no-report") == 0
    assert bench_main("analyze", run) == 0
    d = json.loads((run / "analysis" / "analysis.json").read_text())
    assert d["friction_model"] == "dahl", d["verdict"]
    assert "as in Dahl's model" in d["verdict"]
    p = d["parameters"]["F_c_N"]
    assert p["low"] <= DAHL["F_c_N"] <= p["high"] or abs(p["value"] / DAHL["F_c_N"] - 1) < 0.01, p
