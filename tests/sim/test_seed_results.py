"""The seed's checkable results (physics.md, "What the seed reports")."""
import numpy as np
import pytest

from sim.dynamics import steady_state
from sim.features import cycle_features
from sim.frf import find_peaks, frf_rk4
from sim.shooting import frf_shooting

BETAS = np.linspace(0.2, 2.4, 221)
SEED_ABC = {0.5: (0.54, 0.90, 1.65), 1.5: (0.45, 0.71, 1.40)}


@pytest.fixture(scope="module")
def frf():
    cache = {}

    def get(gamma0, n):
        if (gamma0, n) not in cache:
            cache[gamma0, n] = frf_shooting(BETAS, gamma0, n)[0]
        return cache[gamma0, n]
    return get


@pytest.mark.parametrize("n,lo,hi", [(0.5, 0.90, 1.65), (1.5, 0.71, 1.40)])
def test_harmonic_resonance_lies_between_seed_frequencies_B_and_C(frf, n, lo, hi):
    harmonic = find_peaks(frf(0.6, n))[0]
    assert lo < harmonic.beta < hi


@pytest.mark.parametrize("n", [0.5, 1.5])
def test_rk4_reference_agrees_on_the_harmonic_resonance(n):
    fr = frf_rk4(np.linspace(0.6, 1.6, 26), 0.6, n)
    lo, hi = (0.90, 1.65) if n == 0.5 else (0.71, 1.40)
    assert lo < find_peaks(fr)[0].beta < hi


@pytest.mark.parametrize("n", [0.5, 1.5])
def test_superharmonic_resonances_sit_below_the_harmonic_one(frf, n):
    peaks = find_peaks(frf(0.6, n))
    harmonic, supers = peaks[0], [p for p in peaks if p.kind == "superharmonic"]
    assert supers, "no superharmonic resonance found"
    assert all(p.beta < harmonic.beta and p.G < harmonic.G for p in supers)
    # the one next to the harmonic resonance is smaller and near an integer fraction of it
    nearest = max(supers, key=lambda p: p.beta)
    assert 1.6 < nearest.ratio < 3.4


@pytest.mark.parametrize("n", [0.5, 1.5])
def test_harmonic_resonance_frequency_falls_as_force_rises(frf, n):
    betas = [find_peaks(frf(g, n))[0].beta for g in (0.3, 0.6, 0.9)]
    assert betas[0] > betas[1] > betas[2]


def test_compliance_at_resonance_higher_for_larger_n(frf):
    small, large = find_peaks(frf(0.6, 0.5)), find_peaks(frf(0.6, 1.5))
    assert large[0].G > small[0].G                         # harmonic
    sup = lambda ps: max((p for p in ps if p.kind == "superharmonic"), key=lambda p: p.beta)
    assert sup(large).G > sup(small).G                      # adjacent superharmonic


@pytest.mark.parametrize("n", [0.5, 1.5])
def test_vrar_at_frequency_A_none_at_B_near_circular_at_C(n):
    A, B, C = (cycle_features(steady_state(0.6, b, n, history_samples=4000).history)
               for b in SEED_ABC[n])
    assert A.voad and A.vrar                    # variation of acceleration direction + VRAR
    assert not B.voad and not B.vrar
    assert not C.voad and not C.vrar
    assert C.circularity < 0.05 < B.circularity  # C nearly circular, B distorted


def test_displacement_spike_at_A_sharper_for_small_n():
    spike = {n: cycle_features(steady_state(0.6, SEED_ABC[n][0], n, history_samples=4000).history).spike_index
             for n in (0.5, 1.5)}
    assert spike[0.5] > 2 * spike[1.5]


def test_small_n_damps_more_at_equal_force(frf):
    # Seed: small n means more nonlinearity and more damping, so a lower peak.
    for g in (0.3, 0.9):
        assert find_peaks(frf(g, 1.5))[0].G > find_peaks(frf(g, 0.5))[0].G
