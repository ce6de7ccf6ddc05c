"""Every output speaks the procedure's language (issue 31 items 1-2, issue 30 items 4 and 9;
decision record 0052): the procedure's kind and controlled quantity are typed from the
plan to run.json, and what a user reads (dry-run's output, report.md, modes.csv, the
exported steps) names the quantity that was controlled in its unit; a phase-resonance run
with a level not locked is never "went well" and exits 1.

The runs are real ``bench`` processes on the simulated rig with tiny plans (a few steps)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from bench.config import DEFAULTS, parse_plan, parse_stored_plan
from procedures.kind import FORCE, PHASE, ProcedureKind, of_stored_plan

REPO = Path(__file__).resolve().parents[2]
RIG = str(DEFAULTS / "sim_rig.toml")
RC_LEVELS = (1e-6, 3e-6)


def bench(*args: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    """``bench ARGS`` in a process of its own, from the repository."""
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=REPO, text=True, capture_output=True,
                          timeout=timeout)


def write_toml(path: Path, text: str) -> str:
    path.write_text(text)
    return str(path)


RC_PLAN = """[plan]
name = "held displacement"
procedure = "response_controlled"
[plan.response]
quantity = "disp"
levels = [1e-6, 3e-6]
[plan.frequencies]
list_Hz = [50.0, 65.0, 80.0]
[plan.control]
settle_cycles = 10
measure_cycles = 10
harmonics = 9
"""


def test_the_kind_and_quantities_are_typed_from_the_plan():
    rc = parse_plan({"plan": {"procedure": "response_controlled", "frequencies": {"list_Hz": [50.0]},
                              "response": {"quantity": "accel", "levels": [5.0]}}})
    assert rc.procedure is ProcedureKind.RESPONSE_CONTROLLED
    assert (rc.level_quantity.unit, rc.controlled.unit) == ("m/s^2", "m/s^2")
    pr = parse_plan({"plan": {"procedure": "phase_resonance", "levels_N": [1.0], "backbone": {"start_Hz": 80.0}}})
    assert pr.level_quantity == FORCE and pr.controlled == PHASE
    assert pr.describe() == {"kind": "phase_resonance", "level_quantity": "force", "level_unit": "N",
                             "controlled_quantity": "phase", "controlled_unit": "deg"}
    # the stored plan round-trips through run.json's JSON, and an older one without the
    # field is a stepped sine
    stored = json.loads(json.dumps(rc.to_dict()))
    assert stored["procedure"] == "response_controlled"
    assert parse_stored_plan(stored, "run.json").procedure is ProcedureKind.RESPONSE_CONTROLLED
    old = {k: v for k, v in parse_plan({"plan": {"levels_N": [1.0], "frequencies": {"list_Hz": [50.0]}}})
           .to_dict().items() if k != "procedure"}
    assert parse_stored_plan(old, "run.json").procedure is ProcedureKind.STEPPED_SINE
    assert of_stored_plan(old) == (ProcedureKind.STEPPED_SINE, FORCE)
    assert of_stored_plan(stored)[1].unit == "m/s^2"


def test_dry_run_names_response_levels_in_their_unit(tmp_path):
    """Issue 30 item 9: dry-run's refusal said "0.0009 N at 20 Hz" for 0.9 mm and its
    table's column was "level N"."""
    refused = write_toml(tmp_path / "big.toml", RC_PLAN.replace("[1e-6, 3e-6]", "[0.9e-3]")
                         .replace("[50.0, 65.0, 80.0]", "[20.0, 40.0]"))
    p = bench("dry-run", "--plan", refused, "--rig", RIG, timeout=60)
    assert p.returncode == 3, p.stdout + p.stderr
    refusal = p.stdout.splitlines()[-1] if "REFUSED" in p.stdout else p.stderr
    assert "0.0009 m at 20 Hz" in p.stdout + p.stderr, refusal
    assert not re.search(r"0\.0009 N\b", p.stdout + p.stderr)
    ok = bench("dry-run", "--plan", write_toml(tmp_path / "ok.toml", RC_PLAN), "--rig", RIG, timeout=60)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert "response-controlled stepped sine" in ok.stdout
    assert "levels: 1e-06 m, 3e-06 m (displacement amplitude" in ok.stdout
    assert "level m" in ok.stdout and "level N" not in ok.stdout
