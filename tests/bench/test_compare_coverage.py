"""`bench compare` states its coverage (issue 25, item 5): steps of the reference the other
source lacks can neither agree nor disagree, so the comparison does not pass without them,
names them, and says when they are the resonance."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np

from benchtools.procs import bench_main
from benchtools.twin_sources import write_foreign_uff


def linear_rig(levels=(1.0, 3.0), freqs=(40.0, 55.0, 65.0, 72.0, 80.0, 90.0, 110.0, 150.0)):
    """Steps of a linear carriage (10 kg on 2.5e6 N/m, 2 % damping: resonance 79.6 Hz), one
    period of each record at 64 samples per period, in the layout write_foreign_uff reads;
    and each step's compliance |X/P| from the closed form."""
    m, k, c = 10.0, 2.5e6, 2 * 0.02 * math.sqrt(2.5e6 * 10.0)
    steps, compliance = [], []
    for P in levels:
        for f in freqs:
            w = 2 * math.pi * f
            H = 1.0 / (k - m * w * w + 1j * c * w)
            t = np.arange(64) / (64 * f)
            x = (P * H * np.exp(1j * w * t)).imag
            steps.append(SimpleNamespace(fs_Hz=64 * f, force_N=P * np.sin(w * t), disp_m=x, accel_m_s2=-w * w * x))
            compliance.append(abs(H))
    return SimpleNamespace(steps=steps, rig=dict(F_s_N=1.0, x_s_m=1e-6)), compliance


def test_compare_fails_when_the_five_most_compliant_steps_are_missing_and_names_them_the_resonance(tmp_path, capsys):
    case, compliance = linear_rig()
    top5 = set(np.argsort(compliance)[-5:].tolist())
    ref = write_foreign_uff(case, tmp_path / "ref.uff", seed=1)
    full = write_foreign_uff(case, tmp_path / "full.uff", seed=2)          # the same rig, other noise
    gappy = write_foreign_uff(SimpleNamespace(rig=case.rig, steps=[s for i, s in enumerate(case.steps) if i not in top5]),
                              tmp_path / "gappy.uff", seed=2)

    assert bench_main("compare", ref, full, "--out", tmp_path / "c-full") == 0
    c = json.loads((tmp_path / "c-full" / "compare.json").read_text())
    assert c["coverage"]["fraction"] == 1.0 and c["coverage"]["unmatched"] == []

    capsys.readouterr()
    assert bench_main("compare", ref, gappy, "--out", tmp_path / "c-gap") == 1
    out = capsys.readouterr().out
    c = json.loads((tmp_path / "c-gap" / "compare.json").read_text())
    assert c["overall"]["within_tolerance"] and not c["overall"]["passed"]    # what was compared agrees
    cov = c["coverage"]
    # the UFF file's load cases are the case's steps in order: LC0001 is step 0
    missing = {f"LC{i + 1:04d}" for i in top5}
    assert {m["step"] for m in cov["unmatched"]} == missing
    assert cov["matched"] == len(case.steps) - 5 and not cov["covered"]
    # the most compliant step is its level's resonance; every step named so is one of the missing
    assert f"LC{int(np.argmax(compliance)) + 1:04d}" in cov["resonance_unmatched"]
    assert set(cov["resonance_unmatched"]) <= missing
    n_res = len(cov["resonance_unmatched"])
    assert all(m["why"] == "not in the other" for m in cov["unmatched"])
    assert f"coverage: {len(case.steps) - 5} of the reference's {len(case.steps)} usable steps matched" in out
    assert f"{n_res} of the unmatched steps are at the resonance" in out and "NOT PASSED" in out
    page = (tmp_path / "c-gap" / "compare.html").read_text()
    assert f"{n_res} of the unmatched steps are at the resonance" in page and "Steps of the reference not compared" in page

    # a coverage the user accepts: the same comparison passes
    share = (len(case.steps) - 5) / len(case.steps)
    assert bench_main("compare", ref, gappy, "--min-coverage", f"{share - 0.01:.3f}", "--out", tmp_path / "c-ok") == 0
    assert bench_main("compare", ref, gappy, "--min-coverage", "1.5", "--out", tmp_path / "c-bad") == 2
    assert "--min-coverage must be a fraction in (0, 1]" in capsys.readouterr().err
