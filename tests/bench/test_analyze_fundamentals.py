"""``bench analyze RUN`` on an imported run (issue 42 item 3, decision 0084): FRFs computed from
benchtools' independent Masing simulator (solve_ivp on the documented equations; this
module's own least-squares fundamental of its records), written as other software writes
them (benchtools.frf_files: a pandas CSV of mobility, a savemat struct array of held
displacements), imported with ``bench import`` and analysed with ``bench analyze``: the
intervals cover the simulator's values, BIC prefers Masing, one held level leaves F_s and
x_s open and names the time records' harmonics (by the code in analysis.json)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchtools.frf_files import CSV_MAPPING, MAT_MAPPING, write_csv, write_mat
from benchtools.independent_masing import simulate_level
from benchtools.procs import bench_main

F_S, X_S, N, M = 10.0, 1e-5, 1.5, 10.0
TRUE = {"F_s_N": F_S, "x_s_m": X_S, "n": N, "mass_kg": M}
W_S = math.sqrt(F_S / (X_S * M))
NOISE = 0.005                  # an analyser's: 0.5 % of each FRF value, complex Gaussian (seeded)
SETTLE = 24


def _fundamental(t, y, beta):
    A = np.column_stack([np.cos(beta * t), np.sin(beta * t), np.ones_like(t)])
    c, s, _ = np.linalg.lstsq(A, y, rcond=None)[0]
    return c - 1j * s


def _noisy(H, rng):
    return H * (1 + NOISE * (rng.standard_normal(H.size) + 1j * rng.standard_normal(H.size)) / math.sqrt(2))


def _force_levels(levels_N, freqs, rng):
    betas = [2 * math.pi * f / W_S for f in freqs]
    out = {}
    for P in levels_N:
        H = [_fundamental(t, u, b) * X_S / (_fundamental(t, p, b) * F_S)
             for (t, u, _a, p), b in zip(simulate_level(N, P / F_S, betas, SETTLE, 4,
                                                        40.0 * max(betas) / (2 * math.pi) * 1.037, rtol=1e-9), betas)]
        out[P] = (freqs, _noisy(np.array(H), rng))
    return out


def _held_levels(amplitudes, freqs, rng):
    """Per frequency the force that holds the amplitude (the harmonic balance's, then one
    correction by the simulator's own response: a controller's second iteration), each
    simulated from rest; the file says the held amplitude."""
    from sim.describing import Control, Level, receptance
    out = {}
    for a_h in amplitudes:
        H = []
        guess = Level(freqs, np.full(freqs.size, 1e-7 + 0j), Control.RESPONSE, a_h * X_S, 1.0)
        Hb, _ = receptance("masing", {k: TRUE[k] for k in ("F_s_N", "x_s_m", "n")}, M, guess)
        for f, hb in zip(freqs, Hb):
            b = 2 * math.pi * f / W_S
            P = a_h * X_S / abs(hb)
            for _ in range(2):
                (t, u, _a, p), = simulate_level(N, P / F_S, [b], SETTLE, 4, 40.0 * b / (2 * math.pi) * 1.037, rtol=1e-9)
                X = _fundamental(t, u, b) * X_S
                Fc = _fundamental(t, p, b) * F_S
                P *= a_h * X_S / abs(X)
            H.append(X / Fc)
        out[a_h * X_S] = (freqs, _noisy(np.array(H), rng))
    return out


def _analyse(tmp, name, writer, levels, mapping, capsys):
    src = writer(tmp / name, levels)
    (tmp / "map.toml").write_text(mapping)
    run = tmp / "run"
    assert bench_main("import", src, "--out", run, "--mapping", tmp / "map.toml") == 0
    capsys.readouterr()
    assert bench_main("analyze", run) == 0
    out = capsys.readouterr().out
    return json.loads((run / "analysis" / "analysis.json").read_text()), out, run


@pytest.fixture(scope="module")
def forced(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("forced")
    levels = _force_levels((1.5, 4.0, 8.0), np.linspace(40.0, 110.0, 10), np.random.default_rng(42))
    return tmp, levels


def _covers(model: dict, names=TRUE) -> dict[str, bool]:
    p = model["parameters"]
    return {k: p[k]["low"] <= TRUE[k] <= p[k]["high"] for k in names}


def test_force_controlled_levels_cover_the_simulator_and_prefer_masing(forced, capsys):
    """3 force levels 0.15-0.8 F_s x 10 frequencies, 0.5 % noise, as a CSV of mobility: the
    95 % intervals of F_s, x_s, n, m cover the simulator's values, each identified; Masing is
    preferred by BIC (Dahl's reduced chi-square far above); the terminal says it in a few
    lines; the page holds the figure.  Flips: the noise rule's rescaling dropped (the nominal
    1e-3 kept: red on the noise's range only; the intervals, scaled by the reduced
    chi-square, still cover), the preferred model taken by the largest BIC (red: dahl)."""
    tmp, levels = forced
    a, out, run = _analyse(tmp, "frf.csv", write_csv, levels, CSV_MAPPING, capsys)
    f = a["fundamentals"]
    masing = f["models"]["masing"]
    print("\n" + out, {m: round(d["seconds"], 1) for m, d in a["fundamentals"]["models"].items()})
    assert a["kind"] == "fundamentals" and f["preferred"] == "masing"
    assert set(f["models"]) == {"masing", "dahl"}
    assert masing["structure"] == "none" and "mode" in masing["bic_by_structure"]
    assert all(masing["parameters"][k]["status"] == "identified" for k in TRUE)
    assert all(_covers(masing).values()), _covers(masing)
    assert f["models"]["dahl"]["reduced_chi2"] > 10 * masing["reduced_chi2"]
    assert f["noise"]["rule"] == "residuals" and 0.002 < f["noise"]["relative_sigma"] < 0.006
    assert len(out.strip().splitlines()) <= 8 and "preferred by BIC: masing" in out
    html = (run / "analysis" / "analysis.html").read_text()
    assert "data:image/png;base64," in html and "not a bench measurement" in html
    assert len(f["levels"]) == 3 and all(set(lv["fitted"]) == {"masing", "dahl"} for lv in f["levels"])


@pytest.fixture(scope="module")
def held():
    return _held_levels((0.15, 0.5, 1.2), np.linspace(55.0, 100.0, 6), np.random.default_rng(5))


def test_response_controlled_levels_cover_the_simulator(tmp_path, held, capsys):
    """Three held displacements (0.15, 0.5, 1.2 x_s) x 6 frequencies in a savemat struct
    array: the intervals cover.  Flip: the held run's levels fitted as force-controlled (the
    held metres taken for newtons; red: bench analyze exits 1, the fit fails)."""
    a, out, _ = _analyse(tmp_path, "tests.mat", write_mat, held, MAT_MAPPING, capsys)
    masing = a["fundamentals"]["models"]["masing"]
    print("\n" + out, {m: round(d["seconds"], 1) for m, d in a["fundamentals"]["models"].items()})
    assert a["fundamentals"]["level_kind"] == "disp" and a["fundamentals"]["levels"][0]["control"] == "response"
    assert masing["reduced_chi2"] < 3
    assert all(_covers(masing).values()), _covers(masing)


def test_one_held_level_leaves_F_s_and_x_s_open_and_names_the_harmonics(tmp_path, held, capsys):
    """One held amplitude is one complex K_eq for three friction parameters: F_s and x_s
    degenerate, the harmonics of time records named as what would separate them (the code
    in analysis.json, not the sentence).  Flip: the section's separations emptied (red:
    'harmonics' not in [])."""
    one = {k: v for k, v in held.items() if math.isclose(k, 0.5 * X_S)}
    a, out, _ = _analyse(tmp_path, "one.mat", write_mat, one, MAT_MAPPING, capsys)
    f = a["fundamentals"]
    masing = f["models"]["masing"]
    print("\n" + out, {m: round(d["seconds"], 1) for m, d in a["fundamentals"]["models"].items()})
    assert masing["parameters"]["F_s_N"]["status"] == masing["parameters"]["x_s_m"]["status"] == "degenerate"
    assert {"F_s_N", "x_s_m"} <= set(masing["degenerate"])
    assert "harmonics" in f["separations"]


def test_the_mappings_noise_is_the_fits_and_a_bad_one_is_refused(tmp_path, held, capsys):
    """``noise`` under [import] is the fit's relative sigma (rule ``mapping``, not the
    residuals'); a noise outside (0, 1) is refused at import, one line naming import.noise,
    exit 2, nothing written; the run's report carries the fit's verdict.  Flips: the mapping's
    noise ignored (red: rule residuals), the check's bound dropped (red: exit 0), the report
    given no analysis (red)."""
    from bench.api import open_run
    one = {k: v for k, v in held.items() if math.isclose(k, 0.5 * X_S)}
    a, _, run = _analyse(tmp_path, "one.mat", write_mat, one, MAT_MAPPING.replace("[import]\n", "[import]\nnoise = 0.004\n"),
                       capsys)
    assert a["fundamentals"]["noise"] == {"relative_sigma": 0.004, "rule": "mapping"}
    text = open_run(run).report().read_text()
    assert "fitted to the fundamentals" in text and a["verdict"].splitlines()[0] in text
    (tmp_path / "bad.toml").write_text(MAT_MAPPING.replace("[import]\n", "[import]\nnoise = 2.0\n"))
    assert bench_main("import", tmp_path / "one.mat", "--out", tmp_path / "bad", "--mapping", tmp_path / "bad.toml") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "import.noise" in err[0]
    assert not (tmp_path / "bad").exists()
