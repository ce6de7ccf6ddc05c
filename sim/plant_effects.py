"""The rig's optional effects beyond the Masing model, as coefficients for the plant kernel.

Fields of :class:`sim.rig.RigModel` (SI units, all 0 = off):

- velocity-dependent rolling friction, F = F_Masing(x) * (1 + alpha |x'| / v_ref):
  ``friction_alpha`` (dimensionless), ``friction_v_ref_m_per_s`` (m/s);
- a pitching mode of carriage and column about the guideway contact line:
  ``pitch_inertia_kg_m2`` (J), ``pitch_stiffness_N_m_per_rad`` (k_th),
  ``pitch_damping_N_m_s_per_rad`` (c_th), ``drive_height_m`` (h, where the shaker force
  acts and the impedance head's accelerometer sits), ``cg_height_m`` (e, inertial coupling
  m e).  Off when J = 0.  Equations (:mod:`sim._plant_kernel`):

      m x'' + m e th'' = P - F(x, x') - c x' - c2 x'|x'| - k x - k3 x^3
      m e x'' + J th'' = h P - k_th th - c_th th'

  the accelerometer reads x'' + h th'', the eddy-current probe reads x.  The mass matrix
  is positive definite when J > m e^2 (a column's J about the contact line is its J about
  the centre of gravity plus m e^2, so every real carriage satisfies it).
- a hardening spring k3 x^3: ``cubic_spring_N_per_m3``;
- quadratic damping c2 x'|x'| (oil, air): ``quadratic_damping_N_s2_per_m2``;
- asymmetric friction, F_Masing (1 + a sign F_Masing) (saturates at +F_s (1 + a) and
  -F_s (1 - a)): ``friction_asymmetry`` (a, dimensionless, |a| < 0.5).
- an electrodynamic shaker instead of an ideal force source (decision 0025), on when
  ``shaker_force_constant_N_per_A`` (Bl) > 0: ``shaker_resistance_ohm`` (R, > 0),
  ``shaker_inductance_H`` (L), ``shaker_armature_mass_kg`` (m_a),
  ``shaker_suspension_N_per_m`` (k_a), ``shaker_damping_N_s_per_m`` (c_a).  A voltage
  amplifier whose blocked force per generator volt at DC is ``amp_gain_N_per_V``:

      L i' = (amp_gain_N_per_V R / Bl) V_gen - R i - Bl x_d'      x_d = x + h th
      P    = Bl i - k_a x_d - c_a x_d' - m_a x_d''                  (impedance head)

  The armature mass joins the mass matrix at the drive point (:func:`mass_matrix`).

:func:`coefficients` turns a model into the kernel's coefficient array (``None`` when
none of these effects is on: the rig then keeps the plain, faster kernel), and
:func:`highest_linear_frequency_Hz` gives the fastest linearised mode, which the rig's
step size must resolve.
"""

from __future__ import annotations

import logging
import math
from dataclasses import fields

import numpy as np

from ._plant_kernel import ASYM, N_COEF, Q_DAMP, S_BEMF, S_CA, S_KA, S_MA, S_ON, S_TAU, S_XS
from .errors import ConfigurationError

log = logging.getLogger(__name__)

ASYMMETRY_LIMIT = 0.5


def validate(model) -> None:
    """Raise ValueError naming the field when an effect's parameters are not physical."""
    for name in effect_fields(model):
        v = getattr(model, name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            raise ConfigurationError(f"{name} must be finite and >= 0, got {v!r}")
    a = model.friction_asymmetry
    if isinstance(a, bool) or not isinstance(a, (int, float)) or not (math.isfinite(a) and abs(a) < ASYMMETRY_LIMIT):
        raise ConfigurationError(f"friction_asymmetry must be finite with |a| < {ASYMMETRY_LIMIT}, got {a!r}")
    if model.friction_alpha > 0 and model.friction_v_ref_m_per_s <= 0:
        raise ConfigurationError(f"friction_v_ref_m_per_s must be > 0 when friction_alpha > 0, "
                         f"got {model.friction_v_ref_m_per_s!r}")
    if pitch_on(model):
        if model.pitch_stiffness_N_m_per_rad <= 0:
            raise ConfigurationError(f"pitch_stiffness_N_m_per_rad must be > 0 when the pitch is on "
                             f"(pitch_inertia_kg_m2 > 0), got {model.pitch_stiffness_N_m_per_rad!r}")
        m_e2 = model.mass_kg * model.cg_height_m ** 2
        if model.pitch_inertia_kg_m2 <= m_e2:
            raise ConfigurationError(f"pitch_inertia_kg_m2 must be > mass_kg * cg_height_m^2 = {m_e2:g} "
                             f"(positive-definite mass matrix), got {model.pitch_inertia_kg_m2!r}")
    if shaker_on(model) and model.shaker_resistance_ohm <= 0:
        raise ConfigurationError(f"shaker_resistance_ohm must be > 0 when the shaker model is on "
                         f"(shaker_force_constant_N_per_A > 0), got {model.shaker_resistance_ohm!r}")


def effect_fields(model) -> tuple[str, ...]:
    """The fields of ``model`` (a :class:`sim.rig.RigModel`) declared as an effect or the
    shaker whose range starts at 0 (every one but the friction asymmetry's): each must be
    finite and >= 0 in the model itself, whatever file it came from."""
    return tuple(f.name for f in fields(model)
                 if (k := f.metadata.get("key")) and k.group in ("effect", "shaker") and k.lo == 0)


def shaker_on(model) -> bool:
    return model.shaker_force_constant_N_per_A > 0


def pitch_on(model) -> bool:
    return model.pitch_inertia_kg_m2 > 0


def any_on(model) -> bool:
    return (model.friction_alpha > 0 or model.cubic_spring_N_per_m3 > 0 or pitch_on(model)
            or model.quadratic_damping_N_s2_per_m2 > 0 or model.friction_asymmetry != 0 or shaker_on(model))


def mass_matrix(model) -> np.ndarray:
    """[[m, m e], [m e, J]] (kg, kg m, kg m^2), plus m_a [[1, h], [h, h^2]] with the shaker on."""
    m, e = model.mass_kg, model.cg_height_m
    M = np.array([[m, m * e], [m * e, model.pitch_inertia_kg_m2]])
    if shaker_on(model):
        h = model.drive_height_m if pitch_on(model) else 0.0
        M += model.shaker_armature_mass_kg * np.array([[1.0, h], [h, h * h]])
    return M


def coefficients(model, physical: bool = False) -> np.ndarray | None:
    """The kernel's coefficient array (layout in :mod:`sim._plant_kernel`), or None.
    ``physical``: in newtons and metres (F_s = x_s = 1), whatever is on, for the contact
    kernel of a friction model other than Masing (:mod:`sim._contact_kernel`)."""
    if not (physical or any_on(model)):
        return None
    F_s, x_s = (1.0, 1.0) if physical else (model.F_s_N, model.x_s_m)
    c = np.zeros(N_COEF)
    if pitch_on(model):
        inv = np.linalg.inv(mass_matrix(model))
        c[0], c[1] = F_s / x_s * inv[0, 0], F_s / x_s * inv[0, 1]
        c[2], c[3] = F_s * inv[1, 0], F_s * inv[1, 1]
        c[8] = model.drive_height_m
        c[9] = model.pitch_stiffness_N_m_per_rad / F_s
        c[10] = model.pitch_damping_N_m_s_per_rad / F_s
    else:
        c[0] = F_s / (x_s * mass_matrix(model)[0, 0])
    c[4] = model.viscous_N_s_per_m * x_s / F_s
    c[5] = model.spring_N_per_m * x_s / F_s
    c[6] = model.cubic_spring_N_per_m3 * x_s ** 3 / F_s
    if model.friction_alpha > 0:
        c[7] = model.friction_alpha * x_s / model.friction_v_ref_m_per_s
    c[Q_DAMP] = model.quadratic_damping_N_s2_per_m2 * x_s ** 2 / F_s
    c[ASYM] = model.friction_asymmetry
    if shaker_on(model):
        Bl, R = model.shaker_force_constant_N_per_A, model.shaker_resistance_ohm
        c[S_ON], c[S_TAU], c[S_BEMF] = 1.0, model.shaker_inductance_H / R, Bl * Bl / (R * F_s)
        c[S_KA], c[S_CA] = model.shaker_suspension_N_per_m / F_s, model.shaker_damping_N_s_per_m / F_s
        c[S_MA], c[S_XS] = model.shaker_armature_mass_kg / F_s, x_s
    return c


def shaker_frf(model, freq_Hz, structure_impedance):
    """Linear force per generator volt (complex amplitude ratio P / V_gen) of the shaker on a
    structure of drive-point impedance ``structure_impedance`` = P / x_d' (N s/m) at
    ``freq_Hz`` (decision 0025); ``amp_gain_N_per_V`` itself with the shaker off."""
    w = 2 * np.pi * np.asarray(freq_Hz, dtype=float)
    Zs = np.asarray(structure_impedance, dtype=complex)
    if not shaker_on(model):
        return model.amp_gain_N_per_V + 0 * Zs
    R, Bl = model.shaker_resistance_ohm, model.shaker_force_constant_N_per_A
    Ze = R + 1j * w * model.shaker_inductance_H
    Za = 1j * w * model.shaker_armature_mass_kg + model.shaker_damping_N_s_per_m \
        + model.shaker_suspension_N_per_m / (1j * w)
    return model.amp_gain_N_per_V * R / Ze * Zs / (Zs + Za + Bl * Bl / Ze)


def highest_linear_frequency_Hz(model, feed_stiffness_N_per_m: float) -> float:
    """Highest natural frequency (Hz) of the undamped linearised plant whose feed
    stiffness is ``feed_stiffness_N_per_m`` (friction tangent plus springs)."""
    k_a = model.shaker_suspension_N_per_m if shaker_on(model) else 0.0
    if not pitch_on(model):
        return math.sqrt((feed_stiffness_N_per_m + k_a) / mass_matrix(model)[0, 0]) / (2 * math.pi)
    h = model.drive_height_m
    K = np.diag([feed_stiffness_N_per_m, model.pitch_stiffness_N_m_per_rad]) + k_a * np.array([[1, h], [h, h * h]])
    w2 = np.linalg.eigvals(np.linalg.solve(mass_matrix(model), K)).real
    return math.sqrt(max(w2.max(), 0.0)) / (2 * math.pi)
