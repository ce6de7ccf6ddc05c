"""`bench identify` on a stored run and on exported UFF58 time records."""
import json
import shutil

import pytest

from bench.cli import main
from bench.export import export_run

TRUTH = dict(F_s_N=10.0, x_s_m=10e-6, n=1.5, mass_kg=10.0)   # bench/defaults/sim_rig.toml [rig.model]


def estimates(out: str) -> dict:
    rows = [line.split() for line in out.splitlines() if line.split() and line.split()[0] in TRUTH]
    return {r[0]: float(r[1]) for r in rows}


def test_identify_a_stored_run_writes_run_json(small_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(small_run.path, run)
    meta = json.loads((run / "run.json").read_text())
    meta.pop("identification", None)
    (run / "run.json").write_text(json.dumps(meta))
    assert main(["identify", str(run)]) == 0
    est = estimates(capsys.readouterr().out)
    stored = json.loads((run / "run.json").read_text())["identification"]["values"]
    for k, v in TRUTH.items():
        assert est[k] == pytest.approx(v, rel=0.03)
        assert stored[k] == pytest.approx(est[k], rel=1e-4)


def test_identify_from_uff58_time_records(small_run, tmp_path, capsys):
    paths = {p.name: p for p in export_run(small_run.path, tmp_path)}
    assert main(["identify", str(paths["time.uff"])]) == 0
    est = estimates(capsys.readouterr().out)
    for k, v in TRUTH.items():
        assert est[k] == pytest.approx(v, rel=0.03)


def test_identify_refuses_a_file_without_time_records(small_run, tmp_path):
    paths = {p.name: p for p in export_run(small_run.path, tmp_path, time_records=False)}
    assert main(["identify", str(paths["frf.uff"])]) == 2
