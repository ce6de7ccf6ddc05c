"""The rig file (TOML): instruments, calibration, limits, expected values and, for a
simulated rig, the plant's model ([rig.model], checked against sim.rig.RigModel's own
declaration, decision 0058).  Every error names the file, the key and the allowed values."""

from __future__ import annotations

from dataclasses import replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

from drivers import check_daq_url, check_generator_url, check_sensor_url
from procedures.plan import Limits, Rig

from .toml_tables import _REQUIRED, ConfigError, _collecting, _load, _Section
from .words.terminal import refused

if TYPE_CHECKING:      # sim.rig compiles the plant's kernels: imported when a model is parsed
    from sim.rig import RigModel


class RigRule(StrEnum):
    """A rig file's rule across keys (its words: bench.words.terminal_config.RULE)."""

    MODEL_NOT_SIMULATED = "model_not_simulated"     # source: a [rig.model] of a rig that is not simulated


LIMIT_KEYS = ("drive_V", "force_N", "disp_m", "accel_m_s2")
RIG_KEYS = {
    "rig": ("name", "notes", "simulated", "instruments", "calibration", "limits", "expected", "model"),
    "rig.instruments": ("generator", "sensor", "daq"),
    "rig.calibration": ("force_V_per_N", "accel_V_per_m_s2", "disp_V_per_m", "amp_gain_N_per_V"),
    "rig.limits": LIMIT_KEYS,
    "rig.expected": ("mass_kg", "x_s_m", "F_s_N", "n"),
}


def _limits(sec: _Section, required: bool = True) -> Limits:
    """The rig's limits (all four required) or a plan's tighter ones (each optional: one
    left out is the rig's, procedures.safety.tightest)."""
    need = _REQUIRED if required else None

    def one(key, hi):
        return sec.number(key, need, 0, hi, lo_open=True) if required or key in sec.data else None
    lim = Limits(drive_V=one("drive_V", 10), force_N=one("force_N", 1000), disp_m=one("disp_m", 0.01),
                 accel_m_s2=one("accel_m_s2", 1e4))
    sec.done()
    return lim



def model_schema() -> dict:
    """[rig.model]: each key of sim.rig.RigModel as it declares itself (unit, range, choices;
    decision 0058), key -> sim.rig.ModelKey.  Ranges are what a real carriage rig can have;
    cross-field rules (n != 1, J > m e^2, ...) are the model's own and reach the user through
    the same error."""
    from sim.rig import model_keys
    return model_keys()


def _check_model(sec: _Section) -> RigModel | None:
    """Each [rig.model] key against its unit and range, then the model's own rules: the
    parsed sim.rig.RigModel, or None when a key's problem was collected.  A friction model's
    parameters are checked against that model's own declaration (sim.friction.Parameter,
    decision 0075); a parameter of another model than the one named is refused."""
    from sim import rig as sim_rig
    from sim import rig_friction
    from sim.friction import MODELS

    schema = model_schema()
    sec.unknown(set(schema) | set(rig_friction.parameter_owners()))
    friction = sec.choice("friction", rig_friction.MASING, schema["friction"].choices)
    named = "friction" not in sec.bad        # a model not in the list: its parameters are not judged
    own = rig_friction.own_parameters(friction) if named else ()
    misplaced = rig_friction.misplaced(friction, [k for k in sec.data if k not in sec.named]) if named else []
    for key, owners in misplaced:
        sec.bad.add(key)
        sec.coded(rig_friction.FrictionKey.NOT_OF_MODEL, source=sec.source, key=key, model=friction,
                  owners=list(owners))
    for p in (MODELS[friction].parameters if own else ()):
        sec.number(p.name, _REQUIRED, p.lo, p.hi, lo_open=p.lo_open, unit=p.unit)
    owned = rig_friction.parameter_owners()
    for key in sec.data:
        if key in sec.bad or key in own or key in sec.named or key == "friction" or key not in schema \
                or (not named and key in owned):
            continue
        spec = schema[key]
        if spec.choices:
            sec.choice(key, None, spec.choices)
            continue
        sec.number(key, None, spec.lo, spec.hi, lo_open=spec.lo_open, integer=spec.integer,
                   unit=spec.unit or "")
    if sec.errors:
        return None              # the model's own rules once its values are right
    try:
        return sim_rig.RigModel.from_dict(sec.data)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{sec.source}: [rig.model] {e}") from None


def load_rig(path: Path) -> Rig:
    return parse_rig(_load(path), str(path))


def parse_rig(data: dict, source: str = "rig") -> Rig:
    """The rig in ``data``; every independent problem of it named in one ConfigError."""
    return _collecting(_parse_rig, data, source)


def _parse_rig(data: dict, source: str, errors: list[str]) -> Rig:
    top = _Section(source, "", data, ("rig",), errors, RIG_KEYS)
    r = top.table("rig")
    top.done()
    simulated = r.flag("simulated", False)
    ins = r.table("instruments")
    # a simulated rig starts its own twins and fills the URLs in at run time
    urls = {k: ins.text(k, "" if simulated else _REQUIRED) for k in ("generator", "sensor", "daq")}
    for key, check in (("generator", check_generator_url), ("sensor", check_sensor_url), ("daq", check_daq_url)):
        if urls[key] or not simulated:         # only known schemes: pyserial's spy:// writes files
            try:
                check(urls[key])
            except ValueError as e:
                ins.problem(f"{ins.where(key)}: {e}")
    ins.done()
    cal = r.table("calibration")
    exp = r.table("expected")
    rig = Rig(
        name=r.text("name", "rig"), notes=r.text("notes", ""), simulated=simulated,
        generator_url=urls["generator"], sensor_url=urls["sensor"], daq_url=urls["daq"],
        force_V_per_N=cal.number("force_V_per_N", _REQUIRED, 0, 100, lo_open=True),
        accel_V_per_m_s2=cal.number("accel_V_per_m_s2", _REQUIRED, 0, 100, lo_open=True),
        disp_V_per_m=cal.number("disp_V_per_m", _REQUIRED, 0, 1e7, lo_open=True),
        amp_gain_N_per_V=cal.number("amp_gain_N_per_V", _REQUIRED, 0, 1e4, lo_open=True),
        limits=_limits(r.table("limits")),
        expected_mass_kg=exp.number("mass_kg", 10.0, 0, 1e4, lo_open=True),
        expected_x_s_m=exp.number("x_s_m", 20e-6, 0, 1e-2, lo_open=True),
        expected_F_s_N=exp.number("F_s_N", 10.0, 0, 1e4, lo_open=True),
        expected_n=exp.number("n", 1.5, 0.05, 10))
    r.used.add("model")
    if r.data.get("model") and not simulated:
        raise refused(ConfigError, RigRule.MODEL_NOT_SIMULATED, source=source)
    if simulated:
        rig = replace(rig, model=_check_model(r.table("model")))
    cal.done()
    exp.done()
    r.done()
    return rig


def stored_rig(r: dict, source: str) -> Rig:
    """The rig of a stored run (run.json's ``rig``), checked as its file was."""
    return parse_rig({"rig": rig_toml(r)}, source)


def rig_toml(r: dict) -> dict:
    """The stored rig (run.json) back into the TOML layout."""
    return {"name": r["name"], "notes": r["notes"], "simulated": r["simulated"],
            "instruments": {"generator": r["generator_url"], "sensor": r["sensor_url"], "daq": r["daq_url"]},
            "calibration": {k: r[k] for k in ("force_V_per_N", "accel_V_per_m_s2", "disp_V_per_m",
                                              "amp_gain_N_per_V")},
            "limits": r["limits"],
            "expected": {"mass_kg": r["expected_mass_kg"], "x_s_m": r["expected_x_s_m"],
                         "F_s_N": r["expected_F_s_N"], "n": r["expected_n"]},
            **({"model": dict(r["model"])} if r["model"] else {})}
