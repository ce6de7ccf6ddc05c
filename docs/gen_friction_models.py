"""Draws docs/friction-models.png: the steady loops of every friction model of
sim.friction.MODELS at its typical values (the page docs/friction-models.md shows it).

Per model, the loops of x = X cos(w t) at X = 0.3, 1 and 3 pre-rolling lengths (the friction
level over the stiffness at rest), force over the friction level against x over that
length, with the virgin curve where the model has one (Masing, Iwan); the rate-dependent
models (LuGre, GMS) at 1 Hz (solid) and 60 Hz (dotted, the rig's resonances are 20-100 Hz).
The last panel: the force in steady sliding against the speed, read off each model's
steady force along a triangle wave (legs of constant speed, 2 mm long) at its legs' middle:
the Stribeck curve plus the viscous term for LuGre and GMS, the friction level for the
rate-independent models.
Run it after changing a model: ``python docs/gen_friction_models.py [OUT.png]``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from sim.friction import MODELS  # noqa: E402
from sim.friction.iwan import virgin_force  # noqa: E402
from sim.virgin import SakaiCurve  # noqa: E402

OUT = Path(__file__).resolve().parent / "friction-models.png"
M = 1024
AMPLITUDES = (0.3, 1.0, 3.0)
RATES_HZ = (1.0, 60.0)


def stiffness_at_rest(name: str, v: dict) -> float:
    if name == "masing":
        n = v["n"]
        return n * v["F_s_N"] / ((n - 1) * v["x_s_m"]) if n > 1 else math.inf
    return {"dahl": lambda: v["sigma_N_per_m"], "lugre": lambda: v["sigma0_N_per_m"],
            "gms": lambda: sum(v["k_N_per_m"]), "masing_iwan": lambda: sum(v["k_N_per_m"])}[name]()


def sliding_force(model, v: dict, speeds: np.ndarray) -> np.ndarray:
    """The force mid-leg along a triangle wave of 2 mm legs at each speed (m/s)."""
    Mt = 2048
    j = np.arange(Mt)
    X = 1e-3
    tri = X * np.where(j < Mt // 2, -1 + 4 * j / Mt, 3 - 4 * j / Mt)
    F = model.periodic_force(v, np.repeat(tri[None, :], speeds.size, axis=0), math.pi * speeds / (2 * X))
    return F[:, Mt // 4]


def draw(out: Path = OUT) -> Path:
    fig, grid = plt.subplots(2, 3, figsize=(11, 6.6))
    axes = grid.ravel()
    tau = 2 * math.pi * np.arange(M + 1) / M
    for ax, (name, model) in zip(axes, MODELS.items()):
        v = model.typical()
        level = model.friction_level(v)
        length = v["x_s_m"] if name == "masing" else level / stiffness_at_rest(name, v)
        rates = RATES_HZ if model.rate_dependent else RATES_HZ[:1]
        for a, colour in zip(AMPLITUDES, ("C0", "C1", "C2")):
            x = a * length * np.cos(tau[:-1])
            for rate, style in zip(rates, ("-", ":")):
                F = model.periodic_force(v, x[None, :], np.array([2 * math.pi * rate]))[0]
                ax.plot(np.r_[x, x[:1]] / length, np.r_[F, F[:1]] / level, style, color=colour, lw=1.2,
                        label=f"X = {a:g}" if rate == rates[0] else None)
        u = np.linspace(0, max(AMPLITUDES), 200)
        if name == "masing":
            ax.plot(u * length / v["x_s_m"], SakaiCurve(v["n"])(np.minimum(u * length / v["x_s_m"], 1.0)), "k--",
                    lw=0.8, label="virgin curve")
        elif name == "masing_iwan":
            ax.plot(u, virgin_force(v, u * length) / level, "k--", lw=0.8, label="virgin curve")
        ax.set_title(f"{model.label}" + (" (1 Hz solid, 60 Hz dotted)" if model.rate_dependent else ""),
                     fontsize=8)
        ax.set_xlabel("x / pre-rolling length")
        ax.grid(alpha=0.3)
        ax.set_ylabel("F / friction level")
    axes[0].legend(fontsize=7, loc="upper left")
    ax = axes[len(MODELS)]
    speeds = np.geomspace(1e-5, 0.1, 41)
    for name, model in MODELS.items():
        v = model.typical()
        ax.semilogx(speeds, sliding_force(model, v, speeds) / model.friction_level(v), label=model.label)
    ax.set_title("steady sliding", fontsize=8)
    ax.set_xlabel("speed (m/s)")
    ax.set_ylabel("F / friction level")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


if __name__ == "__main__":
    print(draw(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT))
