"""[rig.model] friction (decision 0075): a simulated rig on a friction model other than Masing,
measured through the twins by `bench run`, serves that model's friction (checked against
benchtools/independent_friction.py, which shares no code with sim/); a bad friction key is
one line naming it, exit 2, every problem at once, nothing written; the default rig is the
Masing rig it was."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.config import DEFAULTS, ConfigError, load_rig
from benchtools.independent_friction import force_along
from benchtools.plans import fast_plan_toml
from benchtools.procs import bench_main
from sim.friction import MODELS
from sim.rig import RigModel, model_keys

DAHL = {"F_c_N": 10.0, "sigma_N_per_m": 1e6, "exponent": 1.0}
MASS_KG, VISCOUS = 10.0, 20.0
HEAD = """[rig]
name = "simulated rig, Dahl friction"
simulated = true
[rig.calibration]
force_V_per_N = 0.0225
accel_V_per_m_s2 = 0.0102
disp_V_per_m = 8000.0
amp_gain_N_per_V = 20.0
[rig.limits]
drive_V = 7.0
force_N = 130.0
disp_m = 0.9e-3
accel_m_s2 = 20.0
[rig.model]
"""


def rig_file(tmp_path: Path, model: str, name: str = "rig.toml") -> Path:
    path = tmp_path / name
    path.write_text(HEAD + model)
    return path


@pytest.fixture(scope="module")
def dahl_run(tmp_path_factory):
    """A Dahl rig with viscous damping and quiet sensors, 1 level x 2 frequencies, six measured periods."""
    tmp = tmp_path_factory.mktemp("dahl")
    model = ('friction = "dahl"\n' + "".join(f"{k} = {v!r}\n" for k, v in DAHL.items())
             + f"mass_kg = {MASS_KG}\nviscous_N_s_per_m = {VISCOUS}\nseed = 3\n"
             "force_noise_N = 1e-5\naccel_noise_m_s2 = 1e-5\ndisp_noise_m = 1e-12\n")
    plan = tmp / "plan.toml"
    plan.write_text(fast_plan_toml([40.0, 70.0]).replace("levels_N = [1.0]", "levels_N = [6.0]")
                    .replace("measure_cycles = 4", "measure_cycles = 6"))
    out = tmp / "run"
    assert bench_main("run", "--plan", plan, "--rig", rig_file(tmp, model), "--out", out, "--no-report") == 0
    return out


def test_the_twins_serve_dahl_friction_as_an_independent_simulation_of_it_makes_it(dahl_run):
    """Friction P - m a - c v along the measured path against benchtools' DOP853 integration of
    Dahl's law along the same path (from a virgin contact: the record's first four periods,
    over which the memory of that start fades, by about 10x a period at 70 Hz, are left
    out; measured 1.1e-4 F_c at most over the last two).  The loop is not a Masing
    loop: its branch after a reversal is steeper than its rest stiffness sigma."""
    steps = sorted((dahl_run / "steps").glob("*.npz"))
    assert len(steps) == 2
    for path in steps:
        rec = np.load(path)
        fs, x = float(rec["fs_Hz"]), rec["disp_m"]
        t = np.arange(x.size) / fs
        f_Hz = json.loads(path.with_suffix(".json").read_text())["freq_Hz"]
        period = int(round(fs / f_Hz))
        v = np.gradient(x, t)
        F_meas = rec["force_N"] - MASS_KG * rec["accel_m_s2"] - VISCOUS * v
        F_ind = force_along("dahl", DAHL, t, x)
        tail = slice(x.size - 2 * period, x.size - 2)    # the last two periods (gradient's end left out)
        err = np.max(np.abs(F_meas[tail] - F_ind[tail])) / DAHL["F_c_N"]
        assert err < 1e-3, f"{path.name}: measured friction off Dahl's by {100 * err:.3g} % of F_c"
        top = tail.start + int(np.argmax(x[tail]))          # a reversal from the loop's top
        k_after = (F_meas[top + 3] - F_meas[top + 8]) / (x[top + 3] - x[top + 8])
        assert k_after > 1.3 * DAHL["sigma_N_per_m"], "the branch after the reversal is not Dahl's"


def test_the_stored_rig_names_the_model_and_its_parameters_and_reads_back(dahl_run):
    stored = json.loads((dahl_run / "run.json").read_text())["rig"]["model"]
    assert stored["friction"] == "dahl" and {k: stored[k] for k in DAHL} == DAHL
    assert not {"F_s_N", "x_s_m", "n"} & set(stored)
    assert RigModel.from_dict(stored).friction_values == DAHL


def test_dry_run_names_a_rival_model(tmp_path, capsys):
    rig = rig_file(tmp_path, 'friction = "dahl"\n' + "".join(f"{k} = {v!r}\n" for k, v in DAHL.items()))
    plan = tmp_path / "plan.toml"
    plan.write_text(fast_plan_toml([40.0]))
    assert bench_main("dry-run", "--plan", plan, "--rig", rig) == 0
    assert "(simulated, Dahl friction)" in capsys.readouterr().out.splitlines()[0]


@pytest.mark.parametrize("model, keys", [
    ('friction = "dahl"\nF_c_N = -1.0\nsigma_N_per_m = 1e6\nn = 1.5\nx_s_m = 1e-5\n',
     ["F_c_N", "exponent", "n", "x_s_m"]),                 # out of range, missing, two of Masing's keys
    ('F_c_N = 10.0\nexponent = 2.0\n', ["F_c_N", "exponent"]),     # Dahl's keys on the default Masing rig
    ('friction = "coulomb"\nmass_kg = 0.0\n', ["friction", "mass_kg"]),   # a name not in the list
])
def test_a_bad_friction_key_is_one_line_naming_it_exit_2_nothing_written(tmp_path, capsys, model, keys):
    rig = rig_file(tmp_path, model)
    with pytest.raises(ConfigError) as e:
        load_rig(rig)
    lines = [line for line in str(e.value).splitlines() if "[rig.model] " in line]
    assert len(lines) == len(str(e.value).splitlines())        # every line names a [rig.model] key
    assert sorted(line.split("[rig.model] ")[1].split(":")[0] for line in lines) == keys
    plan = tmp_path / "plan.toml"
    plan.write_text(fast_plan_toml([40.0]))
    assert bench_main("run", "--plan", plan, "--rig", rig, "--out", tmp_path / "run") == 2
    assert not (tmp_path / "run").exists()
    said = capsys.readouterr()
    assert all(k in said.err + said.out for k in keys), said


def test_the_default_rig_is_the_masing_rig_it_was():
    """No friction key in the stored model of a Masing rig (run.json as before decision 0075),
    the plant on the Masing kernel, and a friction model's parameter name is no other rig key."""
    model = load_rig(DEFAULTS / "sim_rig.toml").model
    assert model is not None and model.friction == "masing"
    keys = model.keys()
    assert "friction" not in keys and list(keys) == [k for k in model_keys() if k != "friction"]
    from sim.rig import SimulatedRig
    assert SimulatedRig(model).contact is None
    others = set(model_keys()) - {"F_s_N", "x_s_m", "n"}
    assert not {p.name for m in MODELS.values() for p in m.parameters} & others
