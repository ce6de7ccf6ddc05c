"""`bench identify` on a stored run and on exported UFF58 time records.

The simulated rig's noise is small, so the fit's 95 % intervals are about +-0.01 %: each
true value must lie within them (widened to 2x their half-width, about 4 standard errors,
for the rounding of the printed bounds), which is what the method promises; a 3 %
tolerance would pass a fit 300 intervals off."""
import json
import re
import shutil

import pytest

from bench.cli import main
from bench.export import export_run

TRUTH = dict(F_s_N=10.0, x_s_m=10e-6, n=1.5, mass_kg=10.0)   # bench/defaults/sim_rig.toml [rig.model]


NUMBER = r"[-+0-9.eE]+"


def estimates(out: str) -> dict:
    """{parameter: (estimate, low, high)} from the printed table."""
    rows = re.findall(rf"^\s*(\w+)\s+({NUMBER})\s+\[\s*({NUMBER}),\s*({NUMBER})\]", out, re.M)
    return {name: tuple(map(float, v)) for name, *v in rows if name in TRUTH}


def assert_within_interval(truth: float, low: float, high: float) -> None:
    centre, half = (low + high) / 2, (high - low) / 2
    assert 0 < half < 1e-3 * abs(truth)                        # a tight fit, as the rig allows
    assert abs(truth - centre) <= 2 * half, (truth, low, high)


def test_identify_a_stored_run_writes_run_json(small_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    meta = json.loads((run / "run.json").read_text())
    meta.pop("identification", None)
    (run / "run.json").write_text(json.dumps(meta))
    assert main(["identify", str(run)]) == 0
    est = estimates(capsys.readouterr().out)
    stored = json.loads((run / "run.json").read_text())["identification"]
    assert set(est) == set(TRUTH)
    for k, v in TRUTH.items():
        assert_within_interval(v, stored["low"][k], stored["high"][k])
        assert stored["values"][k] == pytest.approx(est[k][0], rel=1e-4)     # printed to 5 digits


def test_identify_from_uff58_time_records(small_run, tmp_path, capsys):
    paths = {p.name: p for p in export_run(small_run.path, tmp_path)}
    assert main(["identify", str(paths["time.uff"])]) == 0
    est = estimates(capsys.readouterr().out)
    assert set(est) == set(TRUTH)
    for k, v in TRUTH.items():
        assert_within_interval(v, *est[k][1:])


def test_identify_refuses_a_file_without_time_records(small_run, tmp_path):
    paths = {p.name: p for p in export_run(small_run.path, tmp_path, time_records=False)}
    assert main(["identify", str(paths["frf.uff"])]) == 2
