"""One model of the rig and an honest overall line (issue 25 items 2 and 3, decision 0042),
on real runs of the simulated rigs: the pitching rig interrupted with Ctrl-C and resumed,
steps below the probe's resolution, a failed final fit."""

from __future__ import annotations

import dataclasses
import json
import math
import re

import pytest

from bench.config import DEFAULTS, load_rig, parse_plan
from bench.reports import write_report
from bench.session import run_plan
from bench.storage import RunStore
from bench.watch.snapshot import RunReader
from bench.words.numbers import number, percent

TRUTH = dict(F_s_N=12.0, x_s_m=7e-6, n=1.2, mass_kg=10.0)
FAST = dict(settle_cycles=20, min_settle_s=0.0, measure_cycles=8, control_cycles=2, ramp_s=0.0)


def pitch_rig():
    rig = load_rig(DEFAULTS / "sim_rig_pitch.toml")
    return dataclasses.replace(rig, model=dataclasses.replace(rig.model, **TRUTH, viscous_N_s_per_m=60.0,
                                                            pitch_damping_N_m_s_per_rad=25.0))


def plan(levels, freqs):
    return parse_plan({"plan": {"name": "truth", "levels_N": list(levels),
                                "frequencies": {"list_Hz": list(freqs), "direction": "up"}, "control": dict(FAST)}})


def overall(report: str) -> str:
    return next(ln for ln in report.splitlines() if ln.startswith("Overall:"))


def identification_rows(report: str) -> dict[str, list[str]]:
    sec = report.split("## Identification of F_s, x_s, n and m")[1].split("\n## ")[0]
    rows = [ln.strip("|").split("|") for ln in sec.splitlines() if re.match(r"\| (F_s|x_s|n|m) \|", ln)]
    return {r[0].strip(): [c.strip() for c in r] for r in rows}


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_pitching_rig_interrupted_and_resumed_identifies_the_truth_and_says_it_was_interrupted(tmp_path):
    out = tmp_path / "run"
    p, rig = plan((3.0, 7.0, 11.0), (30.0, 55.0, 100.0, 180.0, 400.0)), pitch_rig()

    def ctrl_c(done, total, note):
        if done == 6:
            raise KeyboardInterrupt         # the technician presses Ctrl-C
    with pytest.raises(KeyboardInterrupt):
        run_plan(p, rig, out, sim_seed=1, progress=ctrl_c)
    run_plan(p, rig, out, resume=True, sim_seed=1)
    meta = RunStore.open(out).metadata
    assert meta["status"] == "completed"
    final = meta["identification"]
    assert final["source"].startswith("final fit with the rig's modes")
    assert final["model"]["effects"][:2] == ["second_mode", "viscous_damping"]
    # the online estimates fitted the rig's modes too: never absurd, within the search bounds
    hist = [json.loads(ln) for ln in (out / "identification.jsonl").read_text().splitlines()]
    assert hist and all(h["source"].startswith("online") for h in hist)
    for h in hist[3:]:
        assert 0.3 < h["values"]["F_s_N"] / TRUTH["F_s_N"] < 3 and 0.3 < h["values"]["x_s_m"] / TRUTH["x_s_m"] < 3

    report = write_report(out).read_text()
    line = overall(report)
    assert "interrupted 1 time" in line and "resumed 1 time" in line, line
    assert "no limit trip, error or interruption" not in line and "**went well**:" not in line
    rows = identification_rows(report)
    assert set(rows) == {"F_s", "x_s", "n", "m"}
    assert all(r[-1] == "yes" for r in rows.values()), rows    # truth in interval, all four


def test_steps_below_the_probes_resolution_are_named_with_what_they_are_still_good_for(tmp_path):
    out = tmp_path / "run"
    # plain rig: 10 kg; at 0.1 N and 1 kHz it moves 0.1 / (10 (2 pi 1000)^2) = 0.25 nm, under the
    # probe's 2 nm rms; at 60 Hz 70 nm
    run_plan(plan((0.1,), (60.0, 1000.0)), load_rig(DEFAULTS / "sim_rig.toml"), out, sim_seed=1, identify=False)
    noise = [e for e in RunStore.open(out).events() if e["event"] == "probe_noise"]
    assert len(noise) == 1 and 1e-9 < noise[0]["rms_m"] < 5e-9
    report = write_report(out).read_text()
    line = overall(report)
    assert "1 step moves less than the probe resolves" in line and "acceleration" in line, line
    assert "**went well**:" not in line
    attention = report.split("## Steps needing attention")[1]
    rows = [ln for ln in attention.splitlines() if "below the probe's resolution" in ln]
    key = next(r["key"] for r in RunStore.open(out).results() if r["freq_Hz"] == 1000.0)
    assert len(rows) == 1 and rows[0].split("|")[1].strip() == key, rows
    # the stored fundamental holds the probe's noise too: 0.25 nm of motion reads as a few tenths
    m = re.search(r"displacement fundamental ([\d.]+) nm is less than the probe's noise ([\d.]+) nm rms", rows[0])
    assert m and 0.1 < float(m[1]) < 1.0 and float(m[2]) == pytest.approx(1e9 * noise[0]["rms_m"], rel=0.01), rows[0]


def test_a_failed_final_fit_is_reported_as_failed_with_its_reason_and_no_absurd_number(tmp_path, mocker):
    out = tmp_path / "run"
    # the final fit (the one identification of the stored steps) overflows
    mocker.patch("procedures.online_id.identify_steps", side_effect=OverflowError("math range error"))
    run_plan(plan((1.0, 3.0), (60.0, 100.0)), load_rig(DEFAULTS / "sim_rig.toml"), out, sim_seed=1)
    meta = RunStore.open(out).metadata
    assert meta["status"] == "completed" and "OverflowError" in meta["identification"]["error"]
    report = write_report(out).read_text()
    assert "did not complete" not in report
    assert "**The final fit failed**: OverflowError: math range error" in report
    assert "the final identification failed (OverflowError" in overall(report)

    # a final fit whose numbers overflowed (as the live page showed F_s = 5e-211 N)
    store = RunStore.open(out)
    store.update(identification=dict(values=dict(F_s_N=5e-211, x_s_m=1e200, n=1.0, mass_kg=10.0),
                                     low=dict(F_s_N=0.0, x_s_m=1.0, n=0.9, mass_kg=9.0),
                                     high=dict(F_s_N=1.0, x_s_m=math.inf, n=1.1, mass_kg=11.0),
                                     rel_std={}, reduced_chi2=1.0, warnings=[], steps_used=4))
    report = write_report(out).read_text()
    assert "5e-211" not in report and "1e+200" not in report and not re.search(r"\d{30}", report)
    assert "**The final fit failed**" in report and "needs attention" in overall(report)
    snap = RunReader(out).snapshot()["identification"]
    assert snap["final"].get("values") is None and "failed" in snap["final"]["error"]


def test_the_number_formatter_refuses_what_no_measurement_is():
    assert number(12.0) == "12" and number(7e-6, 1e6) == "7" and number(0.0) == "0"
    assert number(5e-211) == "absurd (fit failed)" and number(-1e200) == "absurd (fit failed)"
    assert number(math.inf) == "unbounded" and number(math.nan) == "not a number" and number(None) == "n/a"
    assert percent(1e198) == "absurd (fit failed)" and percent(0.05) == "+5.00 %"
