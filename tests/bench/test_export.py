"""Export of a run: CSV of the step results, UFF 58 FRFs and time records, and reading back."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import pyuff

from bench.cli import main
from bench.export import CSV_COLUMNS, export_run
from bench.sources import load_source


@pytest.fixture(scope="module")
def run(small_run):
    return small_run


@pytest.fixture(scope="module")
def exported(run, tmp_path_factory):
    out = tmp_path_factory.mktemp("exported")
    paths = export_run(run.path, out)
    return {p.name: p for p in paths}


def test_export_writes_csv_frf_time_and_mode_files(exported):
    assert set(exported) == {"steps.csv", "frf.uff", "time.uff", "modes.csv", "modes.uff"}


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


def test_frf_uff_holds_compliance_and_accelerance_per_level_and_direction(run, exported):
    """Issue 32 item 5: the accelerance A1/F1 ((m/s^2)/N, ordinate data type 12) beside
    the compliance X1/F1 (m/N, type 8), as pyuff (any UFF reader) sees them."""
    sets = pyuff.UFF(str(exported["frf.uff"])).read_sets()
    sets = [sets] if isinstance(sets, dict) else sets
    results = run.results()
    assert len(sets) == 8
    seen = set()
    for ds in sets:
        assert ds["type"] == 58 and ds["func_type"] == 4
        assert ds["abscissa_spec_data_type"] == 18 and ds["abscissa_axis_units_lab"].strip() == "Hz"
        assert ds["orddenom_spec_data_type"] == 13 and ds["orddenom_axis_units_lab"].strip() == "N"
        tags = dict(w.split("=") for w in ds["id4"].split()[1:])
        level, direction, q = float(tags["level"]), tags["dir"], tags["q"]
        seen.add((level, direction, q))
        steps = sorted((r for r in results if r["target_force_N"] == level and r["direction"] == direction),
                       key=lambda r: r["freq_Hz"])
        np.testing.assert_allclose(ds["x"], [r["freq_Hz"] for r in steps], rtol=1e-5)
        if q == "X":
            assert ds["ordinate_spec_data_type"] == 8 and ds["ordinate_axis_units_lab"].strip() == "m"
            expected = [complex(r["compliance_m_per_N"]["re"], r["compliance_m_per_N"]["im"]) for r in steps]
        else:
            assert ds["ordinate_spec_data_type"] == 12 and ds["ordinate_axis_units_lab"].strip() == "m/s^2"
            assert "accelerance" in ds["id1"]
            expected = [r["accelerance_abs_kg_inv"] * np.exp(1j * r["accelerance_phase_rad"]) for r in steps]
        np.testing.assert_allclose(ds["data"], expected, rtol=1e-9)
        assert "labels: " in ds["id5"]
    assert seen == {(lv, d, q) for lv in (1.0, 5.0) for d in ("up", "down") for q in ("X", "A")}


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


def test_time_records_read_back_give_the_stored_steps(run, exported):
    """time.uff read as `bench analyze` and `bench identify` read a UFF58 file
    (bench.sources.load_source, the one UFF58 reader): every step, with its tags, and the
    harmonics the run stored (the same analysis of the same samples)."""
    src = load_source(exported["time.uff"])
    results = {f"LC{case:04d}": r for case, r in enumerate(run.results(), start=1)}   # one load case a step
    assert sorted([s.key for s in src.steps] + [r.step for r in src.rejected]) == sorted(results)
    assert src.steps
    for s in src.steps:
        r = results[s.key]
        assert (s.direction, s.level_N) == (r["direction"], r["target_force_N"])
        assert s.freq_Hz == pytest.approx(r["freq_Hz"], rel=1e-9) and s.fs_Hz == r["fs_Hz"]
        H = s.harmonics
        assert H.disp[0] / H.force[0] == pytest.approx(complex(r["compliance_m_per_N"]["re"],
                                                               r["compliance_m_per_N"]["im"]), rel=1e-9)
        assert abs(H.accel[0] / H.force[0]) == pytest.approx(r["accelerance_abs_kg_inv"], rel=1e-9)
        assert abs(H.force[0]) == pytest.approx(r["force_N"], rel=1e-9)


def test_bench_export_command_writes_into_the_given_directory(run, tmp_path, capsys):
    assert main(["export", str(run.path), "--out", str(tmp_path / "x"), "--no-time"]) == 0
    assert sorted(p.name for p in (tmp_path / "x").iterdir()) == ["frf.uff", "modes.csv", "modes.uff", "steps.csv"]
    assert "frf.uff" in capsys.readouterr().out


def test_reading_a_file_without_dataset_58_says_so(tmp_path):
    path = tmp_path / "nodes.uff"
    pyuff.UFF(str(path)).write_sets([pyuff.prepare_15(node_nums=[1], def_cs=[0], disp_cs=[0], color=[0],
                                                      x=[0.0], y=[0.0], z=[0.0], return_full_dict=True)],
                                    mode="overwrite")
    with pytest.raises(ValueError, match="no dataset 58"):
        load_source(path)


def test_the_modes_leave_as_csv_and_as_uff_dataset_55(run, exported):
    """Issue 32 item 5: modes.csv (the columns of `bench modes`, damping in fractions) and
    one dataset 55 (normal mode) per mode and level with a value, read back by pyuff: its
    frequency and viscous damping the single-mode fit's pole, its ID lines the resonance
    with its interval and the three named damping ratios in per cent."""
    from bench.reports import run_modes
    from bench.reports._modes import COLUMNS
    with open(exported["modes.csv"], newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == COLUMNS and "damping_fit_fraction" in COLUMNS
    modes = [e for e in run_modes(run.path).modes if np.isfinite(e.resonance_Hz)]
    assert modes
    sets = pyuff.UFF(str(exported["modes.uff"])).read_sets()
    sets = [sets] if isinstance(sets, dict) else sets
    assert len(sets) == len(modes)
    for ds, e in zip(sets, modes):
        assert ds["type"] == 55 and ds["analysis_type"] == 2
        assert ds["mode_n"] == {"feed": 1, "pitch": 2}[e.mode]
        assert ds["freq"] == pytest.approx(e.natural_Hz if np.isfinite(e.natural_Hz) else e.resonance_Hz, rel=1e-5)
        assert ds["modal_damp_vis"] == pytest.approx(e.damping_ratio if np.isfinite(e.damping_ratio) else 0.0,
                                                     rel=1e-5, abs=1e-9)
        tags = dict(w.split("=") for w in ds["id4"].split()[1:])
        assert (tags["mode"], float(tags["level"])) == (e.mode, e.level_N)
        assert float(tags["fr"]) == pytest.approx(e.resonance_Hz, rel=1e-6)
        assert float(tags["lo"]) <= float(tags["fr"]) <= float(tags["hi"])
        assert "zeta % energy balance" in ds["id3"] and "half-power" in ds["id3"]
        if e.mode == "feed" and ds["modal_m"] > 0:
            assert ds["modal_m"] == pytest.approx(10.0)       # the carriage's mass, as modes.csv says
            assert ds["r1"][0] == pytest.approx(1 / np.sqrt(10.0), rel=1e-5)
