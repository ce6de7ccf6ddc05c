"""[rig.model]: every RigModel field has a unit and a range; a bad value is named with both."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import pytest

from bench.config import DEFAULTS, MODEL_CHOICES, MODEL_SCHEMA, ConfigError, load_rig
from sim.rig import RigModel

BASE = (DEFAULTS / "sim_rig.toml").read_text()


def rig_with(tmp_path: Path, model_lines: str) -> Path:
    path = tmp_path / "my_rig.toml"
    path.write_text(BASE.replace("seed = 1\n", "seed = 1\n" + model_lines + "\n", 1))
    return path


def test_the_schema_covers_every_model_field():
    assert set(MODEL_SCHEMA) | set(MODEL_CHOICES) == {f.name for f in fields(RigModel)}


def test_the_pitch_demo_rig_parses_with_its_effects_on():
    rig = load_rig(DEFAULTS / "sim_rig_pitch.toml")
    model = RigModel.from_dict(rig.model)
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
    assert plant_effects.shaker_on(RigModel.from_dict(load_rig(DEFAULTS / "sim_rig.toml").model))
    path = tmp_path / "my_rig.toml"
    path.write_text(BASE.replace("shaker_resistance_ohm = 1.5", "shaker_resistance_ohm = 0.0"))
    with pytest.raises(ConfigError, match=r"\[rig.model\] shaker_resistance_ohm must be > 0 when the shaker model is on"):
        load_rig(path)
    path.write_text(BASE.replace("shaker_inductance_H = 0.2e-3", "shaker_inductance_H = 2.0"))
    with pytest.raises(ConfigError, match=r"\[rig.model\] shaker_inductance_H: must be >= 0 and <= 1.*unit: H"):
        load_rig(path)
    old = "\n".join(line for line in BASE.splitlines() if not line.startswith("shaker_"))
    path.write_text(old)
    assert not plant_effects.shaker_on(RigModel.from_dict(load_rig(path).model))
