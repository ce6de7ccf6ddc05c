"""Issue 41 items 3 and 5 (decisions 0078, 0087): a rival friction model hidden in the simulated
rig (decision 0075), measured through the twins by `bench run`, is named by `bench analyze RUN`
(analysis.json's friction_model, its printed line) and by `bench identify RUN`, with Dahl's
parameters covering the rig's; the loops of every fitted model are stored and drawn, and
Dahl's meets the measured loop where Masing's does not.  A response-controlled run too."""

from __future__ import annotations

import contextlib
import io
import json
import re
from html import unescape

import numpy as np
import pytest

from benchtools.plans import FAST_CONTROL, fast_plan_toml
from benchtools.procs import bench_main

from .test_rig_friction import DAHL, rig_file

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]
MODEL = ('friction = "dahl"\n' + "".join(f"{k} = {v!r}\n" for k, v in DAHL.items()) + "mass_kg = 10.0\nseed = 4\n")


def _measured_and_analyzed(tmp, plan_text):
    """Run the plan on the Dahl rig and analyze it: (run, the lines analyze printed)."""
    plan = tmp / "plan.toml"
    plan.write_text(plan_text)
    run = tmp / "run"
    assert bench_main("run", "--plan", plan, "--rig", rig_file(tmp, MODEL), "--out", run, "--no-report") == 0
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert bench_main("analyze", run) == 0
    return run, out.getvalue()


@pytest.fixture(scope="module")
def dahl_run(tmp_path_factory):
    """A Dahl rig, 3 force levels x 4 frequencies, analyzed."""
    return _measured_and_analyzed(tmp_path_factory.mktemp("dahl"), fast_plan_toml([35.0, 45.0, 55.0, 70.0])
                                  .replace("levels_N = [1.0]", "levels_N = [3.0, 6.0, 12.0]"))


def _analysis(run) -> dict:
    return json.loads((run / "analysis" / "analysis.json").read_text())


def test_a_dahl_rig_measured_through_the_twins_is_named_dahl_by_bench_analyze(dahl_run):
    run, printed = dahl_run
    d = _analysis(run)
    assert d["friction_model"] == "dahl", d["verdict"]
    assert "as in Dahl's model" in d["verdict"]
    assert "friction model: dahl;" in printed, printed
    p = d["parameters"]["F_c_N"]
    assert p["low"] <= DAHL["F_c_N"] <= p["high"] or abs(p["value"] / DAHL["F_c_N"] - 1) < 0.01, p


def _rms(loop) -> float:
    gap = np.asarray(loop["friction_meas_N"]) - np.asarray(loop["friction_model_N"])
    return float(np.sqrt(np.mean(gap ** 2)))


def test_every_fitted_model_has_its_loop_at_every_level_and_dahls_meets_the_measured_one(dahl_run):
    """From analysis.json's arrays as a user reads them: at each of the 3 levels the Dahl loop
    is within 1 % of F_c of the measured one (the twin's time-domain Dahl kernel against the
    model's steady periodic force), Masing's misses by more than 2 %, and the stored rms says
    the same; models not fitted have no loops."""
    rows = {r["model"]: r for r in _analysis(dahl_run[0])["friction_models"]["table"]}
    for name, r in rows.items():
        assert ("loops" in r) == bool(r["fitted"]), name
    dahl, masing = rows["dahl"]["loops"], rows["masing"]["loops"]
    assert len(dahl) == len(masing) == 3
    assert sorted(lp["level_N"] for lp in dahl) == pytest.approx([3.0, 6.0, 12.0], rel=0.05)
    for a, b in zip(dahl, masing):
        assert a["key"] == b["key"] and len(a["disp_m"]) == len(a["friction_model_N"]) == 64
        assert _rms(a) < 0.01 * DAHL["F_c_N"] < 0.02 * DAHL["F_c_N"] < _rms(b), (a["key"], _rms(a), _rms(b))
        assert a["rms_difference_N"] == pytest.approx(_rms(a), rel=0.5)


def test_the_analysis_page_draws_each_models_loops_and_marks_dahl_preferred(dahl_run):
    page = (dahl_run[0] / "analysis" / "analysis.html").read_text()
    section = page[page.index("Hysteresis loops of each friction model"):]
    assert section.index("<img") < section.index("</table>")
    body = section[:section.index("</table>")]
    rows = {}
    for tr in re.findall(r"<tr>(.*?)</tr>", body)[1:]:
        cells = [unescape(c) for c in re.findall(r"<td>(.*?)</td>", tr)]
        rows[cells[0]] = [float(c) for c in cells[1:]]
    (preferred,) = [k for k in rows if k.endswith("- preferred")]
    assert "(dahl)" in preferred, rows
    masing = next(v for k, v in rows.items() if "(masing)" in k)
    assert len(rows[preferred]) == 3 and all(a < b / 10 for a, b in zip(rows[preferred], masing)), rows


def test_bench_identify_names_the_friction_model_the_analysis_prefers(dahl_run, capsys):
    run = dahl_run[0]
    assert bench_main("identify", run) == 0
    out = capsys.readouterr().out
    assert re.search(r"friction model the data prefer: Dahl \(dahl\).*F_c 10(\.0*)? N", out), out
    ident = json.loads((run / "run.json").read_text())["identification"]
    fm = ident["friction_model"]
    assert fm["model"] == "dahl"
    p = fm["parameters"]["exponent"]
    assert p["low"] <= DAHL["exponent"] <= p["high"] or abs(p["value"] - DAHL["exponent"]) < 0.01, p


def test_a_response_controlled_dahl_run_is_named_dahl_over_its_held_levels(tmp_path):
    """Response control: the steps hold 2, 5 and 12 um; the held-out levels are those three
    (not the 7 force groups their forces fall into), and Dahl is named."""
    plan = ('[plan]\nprocedure = "response_controlled"\n[plan.response]\nquantity = "disp"\n'
            "levels = [2e-6, 5e-6, 12e-6]\n[plan.frequencies]\nlist_Hz = [35.0, 45.0, 55.0, 70.0]\n" + FAST_CONTROL)
    run, printed = _measured_and_analyzed(tmp_path, plan)
    d = _analysis(run)
    assert d["friction_model"] == "dahl", d["verdict"]
    assert "friction model: dahl;" in printed
    assert sorted({s["level_index"] for s in d["steps"]}) == [0, 1, 2]
    assert len(next(r for r in d["friction_models"]["table"] if r["model"] == "dahl")["loops"]) == 3
