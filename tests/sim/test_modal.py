"""sim.modal against independent facts: a spring-mass-damper's analytic natural frequency
and damping ratio (receptance and accelerance), interval coverage on a seeded sample, the
grid edge, tracking by identity (not the largest peak), and the Masing model's dense peak
(the shooting engine)."""
import math

import numpy as np
import pytest
from scipy import optimize

from sim.modal import (
    LevelData,
    estimate_mode,
    fit_single_mode,
    half_power_zeta,
    level_modes,
    local_maxima,
    next_refinement_Hz,
    track_modes,
)

M, FN, ZETA = 10.0, 50.0, 0.03


def sdof(f, kind="receptance", fn=FN, zeta=ZETA, m=M):
    """Receptance X/F = 1 / (m (wn^2 - w^2 + 2 i zeta wn w)) of a spring-mass-damper (or
    its accelerance -w^2 X/F)."""
    w, wn = 2 * np.pi * np.asarray(f, float), 2 * np.pi * fn
    h = 1 / (m * (wn ** 2 - w ** 2 + 2j * zeta * wn * w))
    return h if kind == "receptance" else -w ** 2 * h


def peak_Hz(kind, fn=FN, zeta=ZETA):
    """Analytic peak of |X/F| (below fn) or |A/F| (above fn)."""
    r = math.sqrt(1 - 2 * zeta ** 2)
    return fn * r if kind == "receptance" else fn / r


@pytest.mark.parametrize("kind", ["receptance", "accelerance"])
def test_spring_mass_exact(kind):
    f = FN * np.array([0.9, 0.95, 0.98, 1.0, 1.01, 1.03, 1.06])
    fit = fit_single_mode(f, sdof(f, kind), kind)
    fn, _ = fit.natural_Hz()
    assert fn == pytest.approx(FN, rel=1e-6)
    assert fit.damping()[0] == pytest.approx(ZETA, rel=1e-5)
    assert fit.peak()[0] == pytest.approx(peak_Hz(kind), rel=1e-6)
    e = estimate_mode(f, sdof(f, kind), mode="feed", kind=kind)
    assert e.ok and e.resonance_Hz == pytest.approx(peak_Hz(kind), rel=1e-6)
    assert e.damping_ratio == pytest.approx(ZETA, rel=1e-5)


@pytest.mark.parametrize("kind", ["receptance", "accelerance"])
def test_intervals_cover_on_a_seeded_sample(kind):
    """95 % intervals of the resonance and the damping ratio cover the analytic values in
    about 95 % of 80 noisy spring-mass FRFs (1 % complex noise; the benchmark runs 1000)."""
    rng = np.random.default_rng(7)
    f = FN * np.array([0.9, 0.95, 0.97, 0.99, 1.0, 1.01, 1.02, 1.04, 1.07])
    h0 = sdof(f, kind)
    n, cf, cz, widths = 80, 0, 0, []
    for _ in range(n):
        noise = 0.01 * np.abs(h0).max() * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / math.sqrt(2)
        e = estimate_mode(f, h0 + noise, mode="feed", kind=kind)
        cf += e.resonance_low_Hz <= peak_Hz(kind) <= e.resonance_high_Hz
        cz += e.damping_ratio_low <= ZETA <= e.damping_ratio_high
        widths.append((e.damping_ratio_high - e.damping_ratio_low) / ZETA)
    assert 0.86 <= cf / n <= 1.0 and 0.86 <= cz / n <= 1.0, (cf, cz)
    assert np.median(widths) < 0.3          # informative, not covering by being huge


COARSE = np.geomspace(30.0, 300.0, 12).round(4)     # the modes tests' coarse grid; the peak near 69 Hz


def test_a_dwell_is_one_more_point_not_a_collapse_of_the_fit():
    """Issue 30 item 5: refinement steps and a dwell crowd the peak; the fit's window must
    keep a flank on both sides and the peak must not be pinned at the window's edge (on
    main: 2 intervals of zero width in this sample, e.g. 69.112 Hz [69.112, 69.112], the
    fitted peak at the window's first point, and damping ratios shifted by up to 11 %).
    Independent facts: the spring-mass's analytic peak; a seeded sample of 2 %-noise FRFs."""
    rng = np.random.default_rng(0)
    n, covered, shifts = 20, 0, []
    for _ in range(n):
        fn, zeta = rng.uniform(62.0, 75.0), rng.uniform(0.03, 0.1)
        fpk = peak_Hz("receptance", fn, zeta)
        refined = fpk * (1 + rng.uniform(-0.05, 0.05)), fpk * (1 + rng.uniform(-0.02, 0.02))
        dwell = fpk * (1 + rng.uniform(-0.005, 0.005))
        noise = rng.standard_normal((2, COARSE.size + 3))
        est = {}
        for with_dwell in (False, True):
            f = np.concatenate([COARSE, refined, [dwell] if with_dwell else []])
            h = sdof(f, fn=fn, zeta=zeta) * (1 + 0.02 * (noise[0, :f.size] + 1j * noise[1, :f.size]))
            est[with_dwell] = e = estimate_mode(f, h, mode="feed", kind="receptance")
        e, e0 = est[True], est[False]
        assert e.status == "ok", e.note
        assert e.resonance_low_Hz < e.resonance_Hz < e.resonance_high_Hz, e        # never zero width
        covered += e.resonance_low_Hz <= fpk <= e.resonance_high_Hz
        if e0.status == "ok":
            shifts.append(abs(e.damping_ratio - e0.damping_ratio) / zeta)
    assert covered >= 0.85 * n, covered                     # 95 % intervals: most of the sample
    # one more point moves the damping ratio little: measured median 1.0 %, largest 5.6 % (main: 2.3 %, 11 %)
    assert len(shifts) >= 10 and np.median(shifts) < 0.02 and max(shifts) < 0.08, shifts


def test_half_power_matches_the_analytic_damping():
    f = np.linspace(40, 60, 801)
    mag = np.abs(sdof(f))
    i = int(np.argmax(mag))
    assert half_power_zeta(f, mag, f[i], mag[i]) == pytest.approx(ZETA, rel=0.02)
    assert math.isnan(half_power_zeta(f[i - 3:], mag[i - 3:], f[i], mag[i]))   # one side missing


def test_a_peak_at_the_grid_edge_is_not_given_a_value():
    f = np.geomspace(60, 300, 10)            # above the resonance: compliance falls from the first point
    for e in (estimate_mode(f, sdof(f), mode="feed", kind="receptance"),
              estimate_mode(np.geomspace(20, 45, 8), sdof(np.geomspace(20, 45, 8)), mode="feed", kind="receptance")):
        assert e.status in ("below grid", "above grid")
        assert math.isnan(e.resonance_Hz) and math.isnan(e.damping_ratio) and math.isfinite(e.edge_Hz)
    assert estimate_mode(f, sdof(f), mode="feed", kind="receptance").status == "below grid"


def two_modes(f, big_upper=True):
    """A feed-like mode at 50 Hz and a pitch-like one at 200 Hz (the upper one larger)."""
    X = sdof(f) + sdof(f, fn=200.0, zeta=0.01, m=(0.5 if big_upper else 50.0))
    w = 2 * np.pi * f
    return LevelData(1.0, np.asarray(f), X, -w ** 2 * X, np.abs(X))


def test_modes_are_tracked_by_identity_not_the_largest_peak():
    f = np.concatenate([np.linspace(40, 60, 21), np.linspace(185, 215, 31)])
    d = two_modes(f)
    assert np.abs(d.compliance_pp).argmax() >= 21           # the largest compliance is the upper mode's
    feed, pitch = level_modes(d, feed_predicted_Hz=48.0, pitch=True, pitch_band_Hz=(150.0, math.inf))
    dense = np.linspace(45, 55, 20001)          # the sum's own peaks, by brute force
    ref_feed = dense[np.abs(two_modes(dense).compliance).argmax()]
    dense = np.linspace(190, 210, 20001)
    ref_pitch = dense[np.abs(two_modes(dense).accelerance).argmax()]
    assert feed.ok and feed.resonance_Hz == pytest.approx(ref_feed, rel=2e-4)
    assert pitch.ok and pitch.resonance_Hz == pytest.approx(ref_pitch, rel=2e-4)
    # with no prediction at all the feed mode is the lowest prominent maximum, still not the largest
    assert level_modes(d)[0].resonance_Hz == pytest.approx(feed.resonance_Hz)
    ests = track_modes([d, two_modes(f, big_upper=False)], pitch=True)
    assert [e.mode for e in ests] == ["feed", "pitch", "feed", "pitch"]


def test_prominence_ignores_ripple():
    f = np.linspace(40, 60, 41)
    mag = np.abs(sdof(f)) * (1 + 1e-4 * np.sin(40 * f))
    assert len(local_maxima(f, mag)) == 1


def _refine(curve, model: bool = True, tol: float = 0.002) -> list[float]:
    """next_refinement_Hz's loop from 12 log points 30-300 Hz on the sdof's phase with the
    magnitude ``curve(f)``; the vertex is the fit's (``model``) or the measured maximum
    itself (no model: a parabola that is not concave).  Returns the frequencies."""
    f = list(np.geomspace(30, 300, 12))
    last = None
    for _ in range(30):
        mag = curve(np.array(f))
        i = int(np.argmax(mag))
        e = estimate_mode(f, sdof(f), mode="feed", kind="receptance", curve=mag, peak_index=i)
        nxt = next_refinement_Hz(f, mag, i, e.resonance_Hz if model else f[i], e.damping_ratio, tol, 30, 300, last)
        if nxt is None:
            return f
        f.append(nxt)
        last = nxt
    pytest.fail("refinement did not end within 30 steps")


def _bracket(f, curve, tol: float = 0.002) -> tuple[float, float]:
    """The measured maximum's neighbours, asserted within ``tol`` of it."""
    fs = np.sort(f)
    i = int(np.argmax(curve(fs)))
    assert fs[i + 1] / fs[i] - 1 <= 1.01 * tol and fs[i] / fs[i - 1] - 1 <= 1.01 * tol
    return fs[i - 1], fs[i + 1]


def test_refinement_brackets_the_peak_within_tolerance():
    """Driving next_refinement_Hz with the analytic FRF from a coarse 12-point grid ends
    with the measured maximum's neighbours within the tolerance, the peak between them."""
    f = _refine(lambda f: np.abs(sdof(f)))
    lo, hi = _bracket(f, lambda f: np.abs(sdof(f)))
    assert lo < peak_Hz("receptance") < hi
    assert len(f) - 12 <= 8                   # 5 (measured; as before decision 0063)


def test_a_vertex_stuck_at_the_maximum_does_not_crawl():
    """Without a model's vertex (it stays at the measured maximum) the refinement used to
    step by the tolerance from the moving maximum and spend 30 steps on this peak; the line
    search alternates such a step with halving the open gap (decision 0063): 15 steps."""
    f = _refine(lambda f: np.abs(sdof(f)), model=False)
    lo, hi = _bracket(f, lambda f: np.abs(sdof(f)))
    assert lo < peak_Hz("receptance") < hi
    assert len(f) - 12 <= 16


def test_a_jump_converges_on_its_edge():
    """A response that jumps (a fold met from rest: 0.4 x the sdof below 51.3 Hz, the sdof
    above) peaks at the jump's edge; converged means what it means on a smooth peak, the
    measured maximum's neighbours within the tolerance (decision 0063): the edge lies between
    them, and the mode's interval holds it (before, at [51.303, 51.384] it did not)."""
    def curve(f):
        return np.abs(sdof(f)) * np.where(np.asarray(f) < 51.3, 0.4, 1.0)
    f = _refine(curve)
    lo, hi = _bracket(f, curve)
    assert lo < 51.3 < hi
    e = estimate_mode(f, sdof(f), mode="feed", kind="receptance", curve=curve(np.array(f)))
    assert e.resonance_low_Hz <= 51.3 <= e.resonance_high_Hz


def test_a_peak_the_grid_does_not_resolve_gets_the_bracket_not_the_fits_interval():
    """5 log points 30-300 Hz around a 3 % peak: no point in its half-power band but the
    maximum, so the resonance's interval is the measured maximum's bracket (it holds the
    analytic peak) and there is no damping ratio."""
    f = np.geomspace(30, 300, 5)
    e = estimate_mode(f, sdof(f, fn=70.0), mode="feed", kind="receptance")
    assert e.status == "coarse" and math.isnan(e.damping_ratio)
    assert e.resonance_low_Hz < peak_Hz("receptance", fn=70.0) < e.resonance_high_Hz
    assert (e.resonance_low_Hz, e.resonance_high_Hz) == (f[1], f[2]) or (e.resonance_low_Hz, e.resonance_high_Hz) == (f[0], f[2])


def test_two_tied_points_either_side_of_a_peak_are_no_plateau():
    """Two points either side of a 3.5 %-damped peak at the same height, 0.8 % below it, are
    tied within their noise (0.1 %), but the peak between them is higher (its half-power
    points measured): the gap between
    tied points is searched (the fit's vertex), not called closed because the points
    beside them lie within half the pair's span (decision 0069; the campaign's oil B 1 N
    pitch: tied at 229.05 and 235.59 Hz, "converged", 0.55 % off)."""
    def mode(f):
        x = np.asarray(f, float) / 232.0
        return x * x / (1 - x * x + 2j * 0.035 * x)
    fine = np.linspace(220, 245, 250001)
    pk = float(fine[np.argmax(np.abs(mode(fine)))])
    level = 0.992 * abs(mode(pk))
    lo = optimize.brentq(lambda f: abs(mode(f)) - level, 220, pk)
    hi = optimize.brentq(lambda f: abs(mode(f)) - level, pk, 245)
    f = np.sort(np.concatenate([np.geomspace(30, 300, 16), [0.965 * pk, 0.996 * lo, lo, hi, 1.004 * hi, 1.035 * pk]]))
    A = mode(f)
    mag, sd = np.abs(A), 0.001 * np.abs(A)
    i = int(np.argmax(mag * (f > 150)))
    e = estimate_mode(f, A, mode="pitch", kind="accelerance", peak_index=i, sd=sd)
    assert e.resonance_low_Hz <= pk <= e.resonance_high_Hz
    nxt = next_refinement_Hz(f, mag, i, e.resonance_Hz, e.damping_ratio, 0.002, 30, 300, None, sd)
    assert nxt is not None and lo < nxt < hi, nxt
