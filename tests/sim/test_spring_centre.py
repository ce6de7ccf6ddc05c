"""The springs' rest position x_c as a fitted parameter (decision record 0038).

A stiffness term acts about the springs' rest position; the analysis knows each step's mean
displacement only relative to the median step's, so the rest position on that scale is a
parameter, shared by the stiffness terms and present only when one of them is.  The fact
checked here is made without the analysis: the independent simulator
(benchtools/independent_masing.py, solve_ivp) puts a cubic spring's rest position off the
probe's zero, where each level's carriage starts, and the truth of x_c is that position
minus the median step's measured mean displacement.
"""

import math

import numpy as np
import pytest

from sim.discrepancy.effects import CENTRE, EFFECTS
from sim.discrepancy.models import Data, Model


def _data(x0, amp=1e-6, steps=4, K=9):
    """Steps whose displacement is x0 + amp sin(w t) (harmonics as sum Im(X_k e^{i k w t}))."""
    X = np.zeros((steps, K), complex)
    X[:, 0] = amp
    one = np.ones((steps, K))
    return Data(omega=np.full(steps, 2 * math.pi * 50.0), P=np.zeros_like(X), A=np.zeros_like(X), X=X,
                sP=one, sA=one, sX=one, level=np.zeros(steps, int), x0=np.asarray(x0, float))


def test_the_centre_joins_with_the_first_stiffness_term_only():
    m0 = Model()
    th = np.array([math.log(10.0), math.log(20e-6), 1.5, math.log(5.0)])
    m1, t1 = m0.extend(th, "viscous_damping", np.zeros(1))
    assert m1.effects == ("viscous_damping",) and t1.size == 5          # a catalog effect: no centre
    m2, t2 = m1.extend(t1, "cubic_stiffness", np.zeros(1), 1e15)
    assert m2.effects == ("viscous_damping", "cubic_stiffness", CENTRE) and t2.size == 7
    assert m2.scales[CENTRE] == pytest.approx(20e-6)                     # fitted in units of x_s
    m3, t3 = m2.extend(t2, "even_stiffness", np.zeros(1))
    assert m3.effects.count(CENTRE) == 1 and t3.size == 8               # one shared rest position


@pytest.mark.parametrize("term,fn", [("cubic_stiffness", lambda u: u ** 3),
                                     ("quadratic_stiffness", lambda u: u * np.abs(u)),
                                     ("even_stiffness", lambda u: u ** 2)])
def test_a_stiffness_term_acts_about_the_rest_position(term, fn):
    """Harmonics 1..K of the term's force against the same force sampled directly on
    x0 + a sin(w t) - x_c and resolved by the FFT; for the cubic also in closed form:
    harmonic 1 of (d + a sin)^3 is 3 d^2 a + 3/4 a^3 (d = x0 - x_c)."""
    x0 = np.array([-2e-6, 0.0, 1e-6, 3e-6])
    d = _data(x0)
    th = np.array([math.log(10.0), math.log(20e-6), 1.5, math.log(5.0)])
    m, t = Model().extend(th, term, np.zeros(1), 1.0)
    x_c = 0.7e-6
    t[m.slices[term]] = 1.0
    t[m.slices[CENTRE]] = x_c / m.scales[CENTRE]
    ctx = m.context(t, d)
    G = EFFECTS[term].force(ctx, np.ones(1))
    M = 512
    ph = 2 * math.pi * np.arange(M) / M
    u = x0[:, None] + 1e-6 * np.sin(ph)[None, :] - x_c
    want = 2j * np.fft.fft(fn(u), axis=1)[:, 1:10] / M
    assert np.allclose(G, want, rtol=0, atol=1e-5 * np.abs(want).max()), (G[:, :3], want[:, :3])
    if term == "cubic_stiffness":
        dd, a = x0 - x_c, 1e-6
        assert np.allclose(G[:, 0], 3 * dd ** 2 * a + 0.75 * a ** 3, rtol=1e-5)


def _uff_case(tmp_path, centre_over_x_s):
    from bench.sources import load_source
    from benchtools.independent_masing import generate_uff

    rig = dict(F_s_N=9.0, x_s_m=20e-6, n=1.8, mass_kg=7.0)
    F_s, x_s = rig["F_s_N"], rig["x_s_m"]
    k3 = 0.35 * F_s / (2 * x_s) ** 3
    w = math.sqrt(F_s / (x_s * rig["mass_kg"]))
    path = tmp_path / "rig.uff"
    generate_uff(path, **rig, levels_N=list(np.linspace(0.1, 0.85, 3) * F_s),
                 freqs_Hz=list(np.geomspace(0.4, 2.5, 6) * w / (2 * math.pi)), settle=40, settle_first=60, measure=6, seed=4,
                 cubic_N_per_m3=k3, spring_centre_m=centre_over_x_s * x_s)
    steps = load_source(path).steps
    # the truth on the analysis' scale: the rest position minus the median step's mean position
    x_c = centre_over_x_s * x_s - float(np.median([np.mean(s.disp_m) for s in steps]))
    return steps, rig, k3, x_c


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_a_cubic_about_an_off_zero_rest_position_is_named_with_k3_and_x_c_covered(tmp_path):
    from sim.discrepancy import analyze_steps

    steps, rig, k3, x_c = _uff_case(tmp_path, 1.5)
    a = analyze_steps(steps, {k: v * 1.15 for k, v in rig.items()})
    d = a.to_dict()
    assert [c["id"] for c in d["causes"]] == ["cubic_stiffness"], d["verdict"]
    p = d["causes"][0]["parameters"]
    assert p["k3"]["low"] <= k3 <= p["k3"]["high"], (p["k3"], k3)
    assert p["x_c"]["low"] <= x_c <= p["x_c"]["high"], (p["x_c"], x_c)
    assert p["x_c"]["high"] - p["x_c"]["low"] < 0.5 * abs(x_c)            # and it is resolved, not just wide
    assert "acting about x_c" in d["causes"][0]["sentence"]
    assert d["final"]["effects"] == ["cubic_stiffness", CENTRE]
