"""Export of a run: CSV of the step results, UFF 58 FRFs and time records, and reading back."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import pyuff

from bench.cli import main
from bench.export import CSV_COLUMNS, export_run, import_uff58


@pytest.fixture(scope="module")
def run(small_run):
    return small_run


@pytest.fixture(scope="module")
def exported(run, tmp_path_factory):
    out = tmp_path_factory.mktemp("exported")
    paths = export_run(run.path, out)
    return {p.name: p for p in paths}


def test_export_writes_csv_frf_and_time_files(exported):
    assert set(exported) == {"steps.csv", "frf.uff", "time.uff"}


def test_csv_has_the_documented_columns_and_one_row_per_step(run, exported):
    with open(exported["steps.csv"], newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == CSV_COLUMNS
    results = run.results()
    assert [r["key"] for r in rows] == [r["key"] for r in results]
    for row, r in zip(rows, results):
        assert float(row["freq_Hz"]) == r["freq_Hz"]
        assert float(row["compliance_re_m_per_N"]) == r["compliance_m_per_N"]["re"]
        assert float(row["compliance_abs_m_per_N"]) == r["compliance_abs_m_per_N"]
        assert float(row["compliance_pp_m_per_N"]) == r["compliance_pp_m_per_N"]
        assert float(row["thd_disp"]) == r["disp"]["thd"]
        assert int(row["control_iterations"]) == r["control_iterations"]
        assert row["force_converged"] in ("0", "1") and row["direction"] in ("up", "down")


def test_frf_uff_holds_one_compliance_frf_per_level_and_direction(run, exported):
    sets = pyuff.UFF(str(exported["frf.uff"])).read_sets()
    sets = [sets] if isinstance(sets, dict) else sets
    results = run.results()
    assert len(sets) == 4
    seen = set()
    for ds in sets:
        assert ds["type"] == 58 and ds["func_type"] == 4
        assert ds["abscissa_spec_data_type"] == 18 and ds["abscissa_axis_units_lab"].strip() == "Hz"
        assert ds["ordinate_axis_units_lab"].strip() == "m" and ds["orddenom_axis_units_lab"].strip() == "N"
        tags = dict(w.split("=") for w in ds["id4"].split()[1:])
        level, direction = float(tags["level"]), tags["dir"]
        seen.add((level, direction))
        steps = sorted((r for r in results if r["target_force_N"] == level and r["direction"] == direction),
                       key=lambda r: r["freq_Hz"])
        np.testing.assert_allclose(ds["x"], [r["freq_Hz"] for r in steps], rtol=1e-5)
        expected = [complex(r["compliance_m_per_N"]["re"], r["compliance_m_per_N"]["im"]) for r in steps]
        np.testing.assert_allclose(ds["data"], expected, rtol=1e-9)
    assert seen == {(1.0, "up"), (1.0, "down"), (5.0, "up"), (5.0, "down")}


def test_time_uff_holds_force_acceleration_and_displacement_of_every_step(run, exported):
    sets = pyuff.UFF(str(exported["time.uff"])).read_sets()
    results = run.results()
    assert len(sets) == 3 * len(results)
    units = {13: ("N", "force_N"), 12: ("m/s^2", "accel_m_s2"), 8: ("m", "disp_m")}
    for i, r in enumerate(results):
        raw = run.raw(r["key"])
        fs = float(raw["fs_Hz"])
        for ds in sets[3 * i:3 * i + 3]:
            assert ds["func_type"] == 1 and ds["abscissa_spacing"] == 1
            assert ds["abscissa_spec_data_type"] == 17 and ds["abscissa_axis_units_lab"].strip() == "s"
            assert ds["abscissa_inc"] == pytest.approx(1 / fs, rel=1e-5)
            unit, key = units[ds["ordinate_spec_data_type"]]
            assert ds["ordinate_axis_units_lab"].strip() == unit
            assert r["key"] in ds["id4"]
            np.testing.assert_allclose(ds["data"], raw[key], rtol=1e-10, atol=1e-12 * np.abs(raw[key]).max())


def test_imported_frfs_give_the_stored_compliance(run, exported):
    imp = import_uff58(exported["frf.uff"])
    results = run.results()
    assert len(imp.steps) == len(results)
    for s in imp.steps:
        assert s["source"] == "uff58-frf"
        same = [r for r in results if (r["target_force_N"], r["direction"]) == (s["target_force_N"], s["direction"])]
        r = min(same, key=lambda r: abs(r["freq_Hz"] - s["freq_Hz"]))
        assert s["freq_Hz"] == pytest.approx(r["freq_Hz"], rel=1e-5)
        assert s["compliance_abs_m_per_N"] == pytest.approx(r["compliance_abs_m_per_N"], rel=1e-9)
        assert s["compliance_phase_rad"] == pytest.approx(r["compliance_phase_rad"], abs=1e-9)


def test_imported_time_records_rebuild_the_step_results(run, exported):
    imp = import_uff58(exported["time.uff"])
    results = {r["key"]: r for r in run.results()}
    assert [s["key"] for s in imp.steps] == list(results)
    for s in imp.steps:
        r = results[s["key"]]
        assert s["source"] == "uff58-time"
        assert (s["direction"], s["level_index"], s["target_force_N"]) == \
            (r["direction"], r["level_index"], r["target_force_N"])
        for k in ("freq_Hz", "force_N", "compliance_abs_m_per_N", "compliance_pp_m_per_N",
                  "accelerance_abs_kg_inv", "fs_Hz"):
            assert s[k] == pytest.approx(r[k], rel=1e-9), k
        assert s["compliance_phase_rad"] == pytest.approx(r["compliance_phase_rad"], abs=1e-9)
        assert s["disp"]["thd"] == pytest.approx(r["disp"]["thd"], rel=1e-6)
        np.testing.assert_allclose(imp.raw[s["key"]]["disp_m"], run.raw(s["key"])["disp_m"], rtol=1e-10)


def test_bench_export_command_writes_into_the_given_directory(run, tmp_path, capsys):
    assert main(["export", str(run.path), "--out", str(tmp_path / "x"), "--no-time"]) == 0
    assert sorted(p.name for p in (tmp_path / "x").iterdir()) == ["frf.uff", "steps.csv"]
    assert "frf.uff" in capsys.readouterr().out


def test_import_of_a_file_without_dataset_58_says_so(tmp_path):
    path = tmp_path / "nodes.uff"
    pyuff.UFF(str(path)).write_sets([pyuff.prepare_15(node_nums=[1], def_cs=[0], disp_cs=[0], color=[0],
                                                      x=[0.0], y=[0.0], z=[0.0], return_full_dict=True)],
                                    mode="overwrite")
    with pytest.raises(ValueError, match="no dataset 58"):
        import_uff58(path)
