import math

import numpy as np
import pytest

from sim.dynamics import steady_state
from sim.rig import RigModel, SimulatedRig


def fit(x, fs, f):
    """Amplitude and phase of the fundamental (least squares over whole periods)."""
    t = np.arange(x.size) / fs
    A = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t), np.ones_like(t)])
    c = np.linalg.lstsq(A, x, rcond=None)[0]
    return math.hypot(c[0], c[1]), math.atan2(c[1], c[0])


def drive(rig, f, force_N, settle_s=1.0, fs=25600.0, periods=20):
    m = rig.model
    rig.set_generator(freq_Hz=f, amplitude_Vpp=2 * force_N / m.amp_gain_N_per_V, output_on=True)
    rig.run(int(settle_s * fs), fs)
    return rig.run(int(round(periods * fs / f)), fs)


def test_rig_compliance_matches_the_dimensionless_model():
    rig = SimulatedRig(RigModel(seed=1))
    m = rig.model
    f = 40.0
    b = drive(rig, f, 0.6 * m.F_s_N, settle_s=2.0)
    x_amp = 0.5 * (b.disp_V.max() - b.disp_V.min()) / m.disp_sens_V_per_m
    beta = 2 * math.pi * f / m.omega_s
    G = steady_state(0.6, beta, m.n).G
    assert x_amp / m.x_s_m / 0.6 == pytest.approx(G, rel=0.01)


def test_far_above_resonance_acceleration_is_force_over_mass():
    rig = SimulatedRig(RigModel())
    m = rig.model
    b = drive(rig, 1000.0, 5.0, settle_s=0.2)
    a, _ = fit(b.accel_V / m.accel_sens_V_per_m_s2, b.fs_Hz, 1000.0)
    F, _ = fit(b.force_V / m.force_sens_V_per_N, b.fs_Hz, 1000.0)
    assert F == pytest.approx(5.0, rel=0.005)
    assert a == pytest.approx(5.0 / m.mass_kg, rel=0.02)


def test_same_seed_same_data_other_seed_other_noise():
    blocks = []
    for seed in (3, 3, 4):
        rig = SimulatedRig(RigModel(seed=seed))
        blocks.append(drive(rig, 80.0, 2.0, settle_s=0.1, periods=4))
    assert np.array_equal(blocks[0].force_V, blocks[1].force_V)
    assert not np.array_equal(blocks[0].force_V, blocks[2].force_V)


def test_output_off_means_no_force_and_no_motion():
    rig = SimulatedRig(RigModel(force_noise_N=0, accel_noise_m_s2=0, disp_noise_m=0))
    rig.set_generator(freq_Hz=50, amplitude_Vpp=1.0, output_on=False)
    b = rig.run(5000, 25600.0)
    assert np.all(b.force_V == 0) and np.all(b.disp_V == 0)
    assert rig.time_s == pytest.approx(5000 / 25600.0)
    assert rig.gap_m() == pytest.approx(rig.model.probe_standoff_m)


def test_displacement_delay_shows_as_phase_lag():
    f, delay = 200.0, 50e-6
    phases = []
    for d in (0.0, delay):
        rig = SimulatedRig(RigModel(disp_delay_s=d, seed=2))
        b = drive(rig, f, 3.0, settle_s=0.3)
        phases.append(fit(b.disp_V, b.fs_Hz, f)[1])
    lag = (phases[0] - phases[1]) % (2 * np.pi)
    assert lag == pytest.approx(2 * np.pi * f * delay, rel=0.005)   # observed 5e-4: the fitted phase of a low-noise block


def test_gain_error_scales_the_reading():
    amps = []
    for err in (0.0, 0.05):
        rig = SimulatedRig(RigModel(force_gain_error=err, seed=5))
        b = drive(rig, 300.0, 4.0, settle_s=0.1)
        amps.append(fit(b.force_V, b.fs_Hz, 300.0)[0])
    assert amps[1] / amps[0] == pytest.approx(1.05, rel=1e-3)


def test_amplifier_limits_the_force():
    rig = SimulatedRig(RigModel(amp_force_limit_N=20.0))
    rig.set_generator(amplitude_Vpp=10.0, output_on=True)   # would be 100 N
    assert rig.drive_force()[0] == 20.0


@pytest.mark.parametrize("bad", [dict(mass_kg=0), dict(n=1.0), dict(x_s_m=float("nan")), dict(disp_delay_s=-1)])
def test_bad_rig_model_is_refused(bad):
    with pytest.raises(ValueError):
        RigModel(**bad)


def test_unknown_rig_model_key_is_named():
    with pytest.raises(ValueError, match="masss_kg"):
        RigModel.from_dict({"masss_kg": 3})


def test_a_step_mark_makes_the_noise_independent_of_what_ran_before():
    # two plants with different histories, marked with the same step key, measure the same
    # noise; another key gives other noise (the output is off: the record is noise only)
    blocks = {}
    for name, history, key in (("a", 3000, "00001-L00-F000-up"), ("b", 17, "00001-L00-F000-up"),
                               ("c", 3000, "00002-L00-F001-up")):
        rig = SimulatedRig(RigModel(seed=9))
        rig.run(history, 25600.0)
        rig.mark_step(key)
        blocks[name] = rig.run(2048, 25600.0).force_V
    assert np.array_equal(blocks["a"], blocks["b"])
    assert not np.array_equal(blocks["a"], blocks["c"])


def test_an_interference_line_on_the_probe_is_added_at_the_rig_time_not_locked_to_the_drive():
    """The line reads line_amplitude on its channel only, and keeps its phase across a change
    of drive frequency (it runs on the rig's clock, like mains)."""
    kw = dict(disp_noise_m=0.0, force_noise_N=0.0, accel_noise_m_s2=0.0, seed=3)
    rigs = {amp: SimulatedRig(RigModel(line_channel="disp", line_freq_Hz=50.0, line_amplitude=amp, **kw))
            for amp in (0.0, 30e-9)}
    blocks = {amp: [drive(r, f, 2.0, settle_s=0.2, periods=25) for f in (37.0, 71.0)] for amp, r in rigs.items()}
    m = rigs[0.0].model
    for i in range(2):
        with_line, without = blocks[30e-9][i], blocks[0.0][i]
        diff = (with_line.disp_V - without.disp_V) / m.disp_sens_V_per_m
        amp, phase = fit(diff, with_line.fs_Hz, 50.0)
        assert amp == pytest.approx(30e-9, rel=1e-3)
        # the phase at the block start is the rig clock's, whatever the drive frequency
        want = (2 * math.pi * 50.0 * with_line.t0_s) % (2 * math.pi)
        assert math.cos(phase - want) == pytest.approx(1.0, abs=1e-4)
        assert np.array_equal(with_line.force_V, without.force_V)
        assert np.array_equal(with_line.accel_V, without.accel_V)
