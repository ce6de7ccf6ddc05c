"""[rig.model]: every RigModel field declares its unit, range and meaning (decision 0058);
the schema, the key reference and the twin's plant read that one declaration; a bad value
is named with its unit and range."""

from __future__ import annotations

import importlib.util
import math
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path

import pytest

import sim.rig
from bench.config import DEFAULTS, ConfigError, load_rig, model_schema, parse_rig
from benchtools import REPO
from sim.rig import GROUPS, RigModel, model_key

BASE = (DEFAULTS / "sim_rig.toml").read_text()


def rig_with(tmp_path: Path, model_lines: str) -> Path:
    path = tmp_path / "my_rig.toml"
    path.write_text(BASE.replace("seed = 1\n", "seed = 1\n" + model_lines + "\n", 1))
    return path


def test_every_model_field_declares_its_unit_range_and_meaning():
    schema = model_schema()
    assert list(schema) == [f.name for f in fields(RigModel) if "key" in f.metadata]   # not friction_parameters
    for name, key in schema.items():
        assert key.meaning and key.group in GROUPS, name
        assert key.choices or key.lo < key.hi, name
        default = getattr(RigModel(), name)
        assert default in key.choices if key.choices else \
            (default > key.lo if key.lo_open else default >= key.lo) and default <= key.hi, name


def _sim_rig(**model) -> dict:
    data = tomllib.loads(BASE)
    data["rig"]["model"].update(model)
    return data


@pytest.mark.parametrize("name", [k for k, key in model_schema().items() if not key.choices])
def test_a_value_beyond_a_declared_range_is_refused_with_the_derived_message(name):
    key = model_schema()[name]
    v = int(key.hi) + 1 if key.integer else 2 * key.hi + 1
    with pytest.raises(ConfigError) as err:
        parse_rig(_sim_rig(**{name: v}), "my_rig.toml")
    low = f"> {key.lo:g}" if key.lo_open else f">= {key.lo:g}"
    assert str(err.value) == (f"my_rig.toml: [rig.model] {name}: must be {low} and <= {key.hi:g}, got {v!r}"
                              + (f" (unit: {key.unit})" if key.unit else ""))


def test_the_message_is_the_one_the_hand_written_schema_gave():
    """As main printed it before the schema was derived (the same words, unit and range)."""
    with pytest.raises(ConfigError) as err:
        parse_rig(_sim_rig(friction_v_ref_m_per_s=50.0), "my_rig.toml")
    assert str(err.value) == "my_rig.toml: [rig.model] friction_v_ref_m_per_s: must be >= 0 and <= 10, got 50.0 " \
                             "(unit: m/s)"


@dataclass(frozen=True)
class WithABrake(RigModel):
    """The rig model with one more effect, declared as any field is (and one the plant lacks)."""

    brake_N: float = model_key(0.0, "N", 0, 50, "a test brake's friction", "effect")
    magnet_N_per_A: float = model_key(0.0, "N/A", 0, 10, "a test magnet", "effect", in_plant=False)
    hum_noise_V: float = model_key(0.0, "V", 0, 1, "a test noise", "noise")
    strain_sens_V_per_m: float = model_key(1.0, "V/m", 0, 1e3, "a test sensor", "sensor", lo_open=True)


@pytest.fixture
def with_a_brake(monkeypatch):
    monkeypatch.setattr(sim.rig, "RigModel", WithABrake)


def _gen_keys(monkeypatch):
    """docs/gen_keys.py as a module (it wraps the parser's accessors to record them: undone
    after the test)."""
    import bench.config as config
    for kind in ("number", "numbers", "choice", "text", "flag"):
        monkeypatch.setattr(config._Section, kind, getattr(config._Section, kind))
    spec = importlib.util.spec_from_file_location("gen_keys_under_test", REPO / "docs" / "gen_keys.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_new_model_field_reaches_the_schema_and_the_key_reference_with_no_other_edit(with_a_brake, monkeypatch):
    assert {"brake_N", "magnet_N_per_A"} <= set(model_schema())
    rig = parse_rig(_sim_rig(brake_N=5.0), "my_rig.toml")
    assert isinstance(rig.model, WithABrake) and rig.model.brake_N == 5.0
    with pytest.raises(ConfigError) as err:
        parse_rig(_sim_rig(brake_N=60.0), "my_rig.toml")
    assert str(err.value) == "my_rig.toml: [rig.model] brake_N: must be >= 0 and <= 50, got 60.0 (unit: N)"
    with pytest.raises(ConfigError, match="brake_N must be finite and >= 0"):     # the plant's own check
        WithABrake(brake_N=-math.inf)
    # the model's own checks read the declarations too (decision 0066): >= 0, or > 0 when open at 0
    with pytest.raises(ConfigError, match="hum_noise_V must be finite and >= 0, got -1.0"):
        WithABrake(hum_noise_V=-1.0)
    with pytest.raises(ConfigError, match="strain_sens_V_per_m must be finite and > 0, got 0.0"):
        WithABrake(strain_sens_V_per_m=0.0)
    with pytest.raises(ConfigError, match="strain_sens_V_per_m must be finite and > 0, got nan"):
        WithABrake(strain_sens_V_per_m=math.nan)
    rows = _gen_keys(monkeypatch).model_rows()
    assert "| `brake_N` | number >= 0 and <= 50 (N) | `0` | a test brake's friction |" in rows
    assert "| `magnet_N_per_A` | number >= 0 and <= 10 (N/A) | `0` | a test magnet (not in the plant yet) |" in rows


def test_the_twin_lists_a_cause_whose_key_the_plant_lacks_as_not_in_the_plant(with_a_brake, monkeypatch):
    from bench import twin
    monkeypatch.setitem(twin.CAUSE_KEYS, "magnetic_drag", lambda p, ctx: {"magnet_N_per_A": 2.0})
    monkeypatch.setitem(twin.CAUSE_KEYS, "brake", lambda p, ctx: {"brake_N": 3.0})
    model, applied, missed = twin.apply_causes({}, [{"id": "magnetic_drag"}, {"id": "brake"}], {"mass_kg": 10.0})
    assert applied == {"brake": {"brake_N": 3.0}} and model == {"brake_N": 3.0}
    assert [m["cause"] for m in missed] == ["magnetic_drag"] and "no magnet_N_per_A" in missed[0]["reason"]


def test_the_pitch_demo_rig_parses_with_its_effects_on():
    model = load_rig(DEFAULTS / "sim_rig_pitch.toml").model
    assert model.pitch_inertia_kg_m2 > 0 and model.friction_alpha > 0


@pytest.mark.parametrize("line, fragments", [
    ("pitch_inertia_kg_m2 = -0.3", ["my_rig.toml", "[rig.model] pitch_inertia_kg_m2", ">= 0", "kg m^2"]),
    ("friction_v_ref_m_per_s = 50.0", ["[rig.model] friction_v_ref_m_per_s", "<= 10", "m/s"]),
    ("cubic_spring_N_per_m3 = true", ["[rig.model] cubic_spring_N_per_m3", "must be a number"]),
    ("friction_alpha = 0.5", ["[rig.model]", "friction_v_ref_m_per_s must be > 0 when friction_alpha > 0"]),
    ("pitch_inertia_kg_m2 = 0.05\ncg_height_m = 0.1\npitch_stiffness_N_m_per_rad = 1e5",
     ["[rig.model]", "pitch_inertia_kg_m2 must be > mass_kg * cg_height_m^2 = 0.1"]),
    ("pitch_inertia_kg_m2 = 0.3", ["pitch_stiffness_N_m_per_rad must be > 0 when the pitch is on"]),
    ("steps_per_period = 10.5", ["[rig.model] steps_per_period", "integer"]),
    ('line_channel = "probe"', ["[rig.model] line_channel", "must be one of", "'disp'", "'probe'"]),
    ("line_amplitude = -1e-9", ["[rig.model] line_amplitude", ">= 0", "unit of line_channel"]),
    ('line_channel = "disp"\nline_amplitude = 1e-8', ["line_freq_Hz must be > 0 when line_channel is set"]),
])
def test_a_bad_model_value_names_the_key_and_what_is_allowed(tmp_path, line, fragments):
    with pytest.raises(ConfigError) as err:
        load_rig(rig_with(tmp_path, line))
    for fragment in fragments:
        assert fragment in str(err.value)


def test_the_shaker_keys_are_checked_and_old_rig_files_keep_an_ideal_force_source(tmp_path):
    from sim import plant_effects
    assert plant_effects.shaker_on(load_rig(DEFAULTS / "sim_rig.toml").model)
    path = tmp_path / "my_rig.toml"
    path.write_text(BASE.replace("shaker_resistance_ohm = 1.5", "shaker_resistance_ohm = 0.0"))
    with pytest.raises(ConfigError, match=r"\[rig.model\] shaker_resistance_ohm must be > 0 when the shaker model is on"):
        load_rig(path)
    path.write_text(BASE.replace("shaker_inductance_H = 0.2e-3", "shaker_inductance_H = 2.0"))
    with pytest.raises(ConfigError, match=r"\[rig.model\] shaker_inductance_H: must be >= 0 and <= 1.*unit: H"):
        load_rig(path)
    old = "\n".join(line for line in BASE.splitlines() if not line.startswith("shaker_"))
    path.write_text(old)
    assert not plant_effects.shaker_on(load_rig(path).model)
