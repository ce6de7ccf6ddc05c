"""Response-controlled stepped sine (procedure = "response_controlled", decision 0044):
the response held at its level at every frequency, and the force it needed against facts
the procedure does not compute: the Masing loop's single-harmonic balance at the measured
amplitude, F1 = |a1 - m w^2 X + i b1| (sim.backbone's coefficients, themselves checked
against the independent simulator)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from bench.config import DEFAULTS, ConfigError, load_rig, parse_plan
from bench.session import run_plan
from sim.backbone import loop_coefficients

FREQS = [40.0, 55.0, 65.0, 70.0, 90.0]


def rc_plan(levels, freqs, quantity="disp", **control) -> dict:
    return {"plan": {"procedure": "response_controlled", "response": {"quantity": quantity, "levels": levels},
                     "frequencies": {"list_Hz": freqs}, "control": control}}


def test_the_masing_rig_needs_the_harmonic_balance_force_at_a_held_amplitude(tmp_path):
    X = 3e-6
    rig = load_rig(DEFAULTS / "sim_rig.toml")
    store = run_plan(parse_plan(rc_plan([X], FREQS)), rig, tmp_path / "run")
    assert store.metadata["status"] == "completed"
    m = dataclasses.asdict(rig.model)
    results = sorted(store.results(), key=lambda r: r["index"])
    assert [r["freq_Hz"] for r in results] == FREQS
    for r in results:
        rc = r["response_control"]
        assert rc["quantity"] == "disp" and rc["target"] == X
        assert abs(rc["error"]) <= 0.02 and r["force_converged"]
        assert rc["measured"] == pytest.approx(r["disp"]["amplitude"][0])
        w = 2 * math.pi * r["freq_Hz"]
        a1, b1 = loop_coefficients(rc["measured"], m["F_s_N"], m["x_s_m"], m["n"])
        assert r["force_N"] == pytest.approx(abs(a1 - m["mass_kg"] * w * w * rc["measured"] + 1j * b1), rel=0.02)
        assert r["target_force_N"] == r["force_N"]       # the force the level needed is the measurement


def test_the_response_plan_is_checked():
    with pytest.raises(ConfigError, match="levels_N: not used"):
        parse_plan({"plan": {**rc_plan([1e-6], [50.0])["plan"], "levels_N": [1.0]}})
    with pytest.raises(ConfigError, match=r"\[plan.response\] levels\[0\]: must be >= 1e-09 and <= 0.001 \(m"):
        parse_plan(rc_plan([0.01], [50.0]))
    with pytest.raises(ConfigError, match="needs procedure"):
        parse_plan({"plan": {"levels_N": [1.0], "frequencies": {"list_Hz": [50.0]}, "response": {"levels": [1e-6]}}})
    from bench.session import EnvelopeError, check_envelope
    with pytest.raises(EnvelopeError, match="acceleration"):     # 0.5 mm at 50 Hz: 49 m/s^2 > 20
        check_envelope(parse_plan(rc_plan([0.5e-3], [50.0])), load_rig(DEFAULTS / "sim_rig.toml"))
