"""One measurement, one truth (decision record 0047): each measured block is analysed once
(:func:`sim.step_record.measure_block`), its step record keeps that analysis (step format
version 2), and every reader takes the measured numbers from it: the stored compliance
(report.md's figures, the watch page, export) and the analysis's (analysis.json, the
analysis page) are the same numbers to the last bit, and nothing assesses a version-2
block again.  A version-1 step is still read, from its raw block, with the same numbers.
(A version-3 step is refused naming the file: tests/bench/test_run_format.py.)"""

from __future__ import annotations

import hashlib
import json
import shutil

import numpy as np

import bench.sources
import procedures.online_id
import procedures.stepped_sine
import sim.step_record
from bench.config import DEFAULTS, load_rig, parse_plan
from bench.session import run_plan
from bench.sources import load_source
from bench.storage import RunStore
from sim.discrepancy.analysis import data_from_steps
from sim.discrepancy.gain import frf


def _reseal(path, change) -> None:
    """Change a step file's content and seal it again, as a writer of that content would have."""
    d = json.loads(path.read_text())
    integrity = d.pop("integrity")
    change(d)
    integrity["json_sha256"] = hashlib.sha256(json.dumps(d, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    path.write_text(json.dumps(dict(d, integrity=integrity), indent=1))


def assert_one_truth(store: RunStore, mocker) -> None:
    """The analysis's measured compliance and accelerance (what analysis.json's steps[].measured
    holds: sim.discrepancy.gain.frf over the source's harmonics) equal the stored step
    results' (what report.md's figures and the watch page plot), exactly, and the verdicts
    agree; reading the run assessed no block again."""
    spy = mocker.spy(bench.sources, "assess_step")
    src = load_source(store.path)
    assert spy.call_count == 0
    results = {r["key"]: r for r in store.results()}
    C, A = frf(*(getattr(data_from_steps(src.steps), k) for k in "PAX"))
    assert src.steps
    for s, c, a in zip(src.steps, C, A):
        r = results[s.key]
        assert (float(c.real), float(c.imag)) == (r["compliance_m_per_N"]["re"], r["compliance_m_per_N"]["im"]), s.key
        assert float(abs(a)) == r["accelerance_abs_kg_inv"], s.key
        assert s.quality.status == r["quality"]["status"] != "rejected"
    assert {x.step for x in src.rejected} == {k for k, r in results.items() if r["quality"]["status"] == "rejected"}


def test_the_report_and_the_analysis_show_the_same_measured_numbers(small_run, mocker):
    assert_one_truth(small_run, mocker)


def test_each_block_is_analysed_once_and_the_online_identification_reads_the_record(tmp_path, mocker):
    plan = parse_plan({"plan": {"name": "once", "levels_N": [2.0],
                                "frequencies": {"list_Hz": [40.0, 120.0], "direction": "up"}}})
    analysed = mocker.spy(sim.step_record, "assess_step")
    again = mocker.spy(procedures.stepped_sine, "assess_step")        # unsettled() on a raw block
    online = mocker.spy(procedures.online_id, "analyse_records")
    store = run_plan(plan, load_rig(DEFAULTS / "sim_rig_pitch.toml"), tmp_path / "run")
    results = store.results()
    assert len(results) == 2 and all(r["format_version"] == 2 for r in results)
    # one analysis per measured block: the step's, plus one for each block settling discarded
    assert analysed.call_count == sum(1 + r["settle_extra_blocks"] for r in results)
    assert again.call_count == 0 and online.call_count == 0
    # the force control's own estimates of running blocks are fundamentals only; no block is fitted again
    assert not hasattr(procedures.stepped_sine, "fit_harmonics")    # the drive phase is a projection (decision 0091)
    assert (tmp_path / "run" / "identification.jsonl").stat().st_size > 0
    assert_one_truth(store, mocker)


def test_a_version_1_step_is_assessed_from_its_raw_block_with_the_same_numbers(small_run, tmp_path, mocker):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    for p in sorted((run / "steps").glob("*.json")):
        def old(d):
            for k in ("quality", "harmonics", "format_version"):
                d.pop(k)
            for ch in ("force", "accel", "disp"):
                d[ch].pop("sigma")
        _reseal(p, old)
    new, spy = load_source(small_run.path), mocker.spy(bench.sources, "assess_step")
    v1 = load_source(run)
    assert spy.call_count == len(small_run.results())
    assert [s.key for s in v1.steps] == [s.key for s in new.steps] and len(v1.rejected) == len(new.rejected)
    for a, b in zip(v1.steps, new.steps):
        for ch in ("force", "accel", "disp"):
            assert np.array_equal(getattr(a.harmonics, ch), getattr(b.harmonics, ch)), (a.key, ch)
        assert a.harmonics.sigma_disp == b.harmonics.sigma_disp and a.quality == b.quality
        # the mean period (loop plots): averaged over the periods in version 1, synthesized from the
        # harmonics (at most 200) in version 2; the average also holds the noise above them
        assert np.allclose(a.disp_m, b.disp_m, rtol=0, atol=5e-3 * np.ptp(b.disp_m))


def test_a_version_2_step_without_its_analysis_is_named_not_guessed(small_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    step = sorted((run / "steps").glob("*.json"))[0]
    _reseal(step, lambda d: d.pop("harmonics"))
    src = load_source(run)
    reason = {r.step: r.reason for r in src.rejected}[step.stem]
    assert step.name in reason and "not a version-2 step result: lacks harmonics" in reason, reason
    assert len(src.steps) + len(src.rejected) == len(small_run.results())


def test_the_record_is_of_the_cleaned_block_not_the_raw_one():
    """A hum on the probe (53.7 Hz beside a 40 Hz drive) is removed by the quality check; the
    step's compliance is that of the cleaned records: within its noise of the true X/F that
    made the block, where a fit of the raw block is pulled off by the hum."""
    from procedures.analysis import fit_harmonics
    from sim.step_record import measure_block

    fs, f, n = 10_000.0, 40.0, 2500
    t = np.arange(n) / fs
    rng = np.random.default_rng(3)
    X_true = 2e-6 * np.exp(-0.6j)
    force = 3.0 * np.sin(2 * np.pi * f * t) + 1e-4 * rng.standard_normal(n)
    disp = (abs(X_true) * 3.0 * np.sin(2 * np.pi * f * t + np.angle(X_true)) + 2e-6 * np.sin(2 * np.pi * 53.7 * t + 1.0)
            + 1e-9 * rng.standard_normal(n))
    accel = -(2 * np.pi * f) ** 2 * abs(X_true) * 3.0 * np.sin(2 * np.pi * f * t + np.angle(X_true)) \
        + 1e-4 * rng.standard_normal(n)
    m = measure_block(force, accel, disp, fs, f)
    assert [a.kind for a in m.quality.artefacts] == ["line_interference"] and m.quality.status == "flagged"
    C = complex(m.fields["compliance_m_per_N"]["re"], m.fields["compliance_m_per_N"]["im"])
    assert abs(C - X_true) < 1e-3 * abs(X_true)
    raw = fit_harmonics(disp, fs, f, 5).fundamental / fit_harmonics(force, fs, f, 5).fundamental
    assert abs(raw - X_true) > 1e-2 * abs(X_true)            # what the second estimator stored before
    assert m.fields["harmonics"]["disp"]["sigma"] == m.fields["disp"]["sigma"] < 1e-10
