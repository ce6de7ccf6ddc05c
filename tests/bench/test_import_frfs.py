"""`bench import` (issue 42 items 1 and 2, decision 0081): measured FRFs from files the bench
did not write (pyuff in another layout, a scipy.io.savemat struct array, a pandas CSV) and
from data the code under test did not make (the independent Masing simulator of
benchtools/, with an analyser's noise), into a run directory whose modes per level
`bench modes` gives; the round trip through the bench's own frf.uff; the bad input, one
line each, exit 2, nothing written.

The truth of the Masing levels is the simulator's own: the peak of its |X1/F1| (a golden
section search on its steady states) and its energy balance there."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from bench.reports._backbone import stepped_points
from bench.reports._modes import run_modes
from benchtools.frf_files import CSV_MAPPING, MAT_MAPPING, UFF_MAPPING, sdof, write_csv, write_mat, write_uff
from benchtools.masing_peaks import golden_max, steady_state
from benchtools.procs import bench_main
from sim.errors import ConfigurationError

MODEL = dict(F_s_N=10.0, x_s_m=1e-5, n=1.5, mass_kg=10.0)
LEVELS_N = (1.0, 2.0, 3.5)
SETTLE, MEASURE, RTOL = 12, 3, 1e-7
NOISE = 0.002                    # an analyser's: 0.2 % of each FRF value, complex Gaussian (seeded)


def _H(force_N: float, f_Hz: float) -> complex:
    return steady_state(MODEL, force_N, f_Hz, SETTLE, MEASURE, RTOL)[2]


@pytest.fixture(scope="module")
def masing():
    """Per level: (frequencies, X1/F1 with noise, the simulator's peak frequency, its energy
    balance there).  The grid: 1.5 Hz steps over +-10.5 Hz around the coarse maximum."""
    rng = np.random.default_rng(42)
    out = {}
    for P in LEVELS_N:
        coarse = np.arange(45.0, 90.0, 7.0)
        fc = coarse[int(np.argmax([abs(_H(P, f)) for f in coarse]))]
        f = np.arange(fc - 10.5, fc + 10.6, 1.5)
        H = np.array([_H(P, x) for x in f])
        k = int(np.argmax(np.abs(H)))
        f_peak = golden_max(lambda x, P=P: abs(_H(P, x)), f[k - 1], f[k + 1], rel_tol=1e-3)
        Hp = _H(P, f_peak)
        w = 2 * math.pi * f_peak
        zeta = -Hp.imag / (2 * MODEL["mass_kg"] * w * w * abs(Hp) ** 2)
        noisy = H * (1 + NOISE * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) / math.sqrt(2))
        out[P] = (f, noisy, f_peak, zeta)
    return out


def _modes(run):
    return {(e.mode, round(e.level_N, 9)): e for e in run_modes(run, model=False).modes}


def _check_against_simulator(run, masing, energy: bool):
    modes = _modes(run)
    for P, (_, _, f_peak, zeta) in masing.items():
        e = modes[("feed", P)]
        assert e.ok, (P, e.status, e.note)
        assert e.resonance_low_Hz <= f_peak <= e.resonance_high_Hz, (P, e.resonance_Hz, f_peak)
        assert abs(e.resonance_Hz / f_peak - 1) < 0.01, (P, e.resonance_Hz, f_peak)
        eb = e.extra.get("energy_balance")
        if energy:
            # the step nearest the resonance (1.5 Hz grid): no noise estimate comes with an FRF,
            # so its interval holds the step's offset only; the value within 3 % of the truth
            assert eb is not None and abs(eb.value / zeta - 1) < 0.03, (P, eb, zeta)
        else:
            assert eb is None
    # the backbone: the resonance falls as the force rises (a softening friction contact), each
    # at the simulator's response amplitude there (|X1/F1| at its peak x the force)
    f_r = [modes[("feed", P)].resonance_Hz for P in LEVELS_N]
    assert f_r == sorted(f_r, reverse=True)
    points = {p["level_N"]: p for p in stepped_points([run_modes(run, model=False)])}
    for P, (_, _, f_peak, _) in masing.items():
        assert abs(points[P]["amplitude_m"] / (abs(_H(P, f_peak)) * P) - 1) < 0.01, (P, points[P])


# ---------------------------------------------------------------------------- files written another way


def _pyuff_file(path, masing, with_force=True):
    return write_uff(path, {P: (f, X) for P, (f, X, _, _) in masing.items()}, force=with_force)




def test_pyuff_accelerance_per_level_and_point_gives_the_simulators_resonance(tmp_path, masing, capsys):
    src = _pyuff_file(tmp_path / "lab.unv", masing)
    (tmp_path / "map.toml").write_text(UFF_MAPPING)
    assert bench_main("import", src, "--out", tmp_path / "run", "--mapping", tmp_path / "map.toml") == 0
    assert "imported from" in capsys.readouterr().out
    _check_against_simulator(tmp_path / "run", masing, energy=True)


def test_without_force_spectra_there_is_no_energy_balance(tmp_path, masing):
    src = _pyuff_file(tmp_path / "lab.uff", masing, with_force=False)
    (tmp_path / "map.toml").write_text(UFF_MAPPING)
    assert bench_main("import", src, "--out", tmp_path / "run", "--mapping", tmp_path / "map.toml") == 0
    _check_against_simulator(tmp_path / "run", masing, energy=False)


def test_a_pandas_csv_of_mobility_in_degrees(tmp_path, masing):
    write_csv(tmp_path / "frf.csv", {P: (f, X) for P, (f, X, _, _) in masing.items()})
    (tmp_path / "map.toml").write_text(CSV_MAPPING)
    assert bench_main("import", tmp_path / "frf.csv", "--out", tmp_path / "run",
                      "--mapping", tmp_path / "map.toml") == 0
    _check_against_simulator(tmp_path / "run", masing, energy=True)


def test_a_savemat_struct_array_response_controlled(tmp_path):
    """A lab's MATLAB tests at held displacement: a linear mode (its FRF is the same at every
    level), whose peak of |X/F| is f_n sqrt(1 - 2 zeta^2) exactly."""
    f_n, zeta = 60.0, 0.03
    f = np.linspace(45.0, 75.0, 31)
    write_mat(tmp_path / "tests.mat", {1e-6: (f, sdof(f, f_n, zeta)), 3e-6: (f, sdof(f, f_n, zeta))})
    (tmp_path / "map.toml").write_text(MAT_MAPPING)
    assert bench_main("import", tmp_path / "tests.mat", "--out", tmp_path / "run",
                      "--mapping", tmp_path / "map.toml") == 0
    run = run_modes(tmp_path / "run", model=False)
    assert run.level_quantity.unit == "m"
    peak = f_n * math.sqrt(1 - 2 * zeta * zeta)
    for level in (1e-6, 3e-6):
        e = next(e for e in run.modes if e.mode == "feed" and math.isclose(e.level_N, level))
        assert e.ok and abs(e.resonance_Hz / peak - 1) < 1e-4, (e.resonance_Hz, peak)
        assert abs(e.damping_ratio / zeta - 1) < 1e-3, e.damping_ratio
        assert e.extra.get("energy_balance") is None          # no force in the file
    # the backbone's amplitude of a held displacement is the displacement held
    assert sorted(p["amplitude_m"] for p in stepped_points([run])) == [1e-6, 3e-6]


# ---------------------------------------------------------------------------- round trip, report, analyze


def test_the_benchs_own_frf_uff_imports_to_the_same_modes(tmp_path, masing, capsys):
    from bench.api import open_run
    src = _pyuff_file(tmp_path / "lab.unv", masing)
    (tmp_path / "map.toml").write_text(UFF_MAPPING)
    assert bench_main("import", src, "--out", tmp_path / "a", "--mapping", tmp_path / "map.toml") == 0
    files = open_run(tmp_path / "a").export(tmp_path / "exp")
    assert not any(p.name == "time.uff" for p in files)          # no time records were imported
    assert bench_main("import", tmp_path / "exp" / "frf.uff", "--out", tmp_path / "b") == 0
    a, b = (run_modes(tmp_path / r, model=False).modes for r in ("a", "b"))
    assert len(a) == len(b) == len(LEVELS_N)
    for x, y in zip(a, b, strict=True):
        assert x.ok and y.ok and x.level_N == y.level_N
        # the printed digits (bench modes: 5 of the resonance, 3 of the damping ratio)
        assert f"{x.resonance_Hz:.5g}" == f"{y.resonance_Hz:.5g}" and f"{x.damping_ratio:.3g}" == f"{y.damping_ratio:.3g}"
        # frf.uff holds 6 digits (E13.5): the intervals move by the fit's response to that rounding
        for u, v in ((x.resonance_low_Hz, y.resonance_low_Hz), (x.resonance_high_Hz, y.resonance_high_Hz)):
            assert abs(u / v - 1) < 2e-4, (u, v)
        # the force spectra are not in frf.uff: the energy balance stays with the first import
        assert x.extra.get("energy_balance") is not None and y.extra.get("energy_balance") is None


def test_a_held_response_survives_the_round_trip_and_load_cases_give_levels(tmp_path):
    """frf.uff's tags carry a response-controlled level's unit (unit=m): the re-import is
    response-controlled at the same levels with the same modes; a file whose levels are its
    load cases, named by [import.levels], reads as well."""
    import pyuff

    from bench.api import open_run
    f = np.linspace(45.0, 75.0, 31)
    write_mat(tmp_path / "tests.mat", {1e-6: (f, sdof(f, 60.0, 0.03)), 3e-6: (f, sdof(f, 58.0, 0.04))})
    (tmp_path / "map.toml").write_text(MAT_MAPPING)
    assert bench_main("import", tmp_path / "tests.mat", "--out", tmp_path / "a", "--mapping", tmp_path / "map.toml") == 0
    open_run(tmp_path / "a").export(tmp_path / "exp")
    assert bench_main("import", tmp_path / "exp" / "frf.uff", "--out", tmp_path / "b") == 0
    a, b = (run_modes(tmp_path / r, model=False) for r in ("a", "b"))
    assert a.level_quantity.unit == b.level_quantity.unit == "m"
    assert [(e.level_N, f"{e.resonance_Hz:.5g}", f"{e.damping_ratio:.3g}") for e in a.modes] == \
        [(e.level_N, f"{e.resonance_Hz:.5g}", f"{e.damping_ratio:.3g}") for e in b.modes]
    sets = [dict(type=58, func_type=4, id1="run", id2="NONE", id3="NONE", id4="NONE", id5="NONE", rsp_node=1,
                 rsp_dir=1, ref_node=1, ref_dir=1, load_case_id=case, abscissa_spacing=0, abscissa_spec_data_type=18,
                 abscissa_axis_units_lab="Hz", ordinate_spec_data_type=8, ordinate_axis_units_lab="m",
                 orddenom_spec_data_type=13, orddenom_axis_units_lab="N", x=f, data=sdof(f, f_n, 0.03))
            for case, f_n in ((11, 61.0), (12, 57.0))]
    pyuff.UFF(str(tmp_path / "cases.uff")).write_sets(sets, mode="add")
    (tmp_path / "cases.toml").write_text('[import]\nlevel_from = "load_case"\n[import.levels]\n"11" = 2.0\n"12" = 5.0\n')
    assert bench_main("import", tmp_path / "cases.uff", "--out", tmp_path / "c", "--mapping", tmp_path / "cases.toml") == 0
    got = {e.level_N: e.resonance_Hz for e in run_modes(tmp_path / "c", model=False).modes}
    assert abs(got[2.0] / (61.0 * math.sqrt(1 - 2 * 0.03 ** 2)) - 1) < 1e-4
    assert abs(got[5.0] / (57.0 * math.sqrt(1 - 2 * 0.03 ** 2)) - 1) < 1e-4


def test_the_report_says_imported_and_identify_refuses(tmp_path, masing, capsys):
    from bench.api import open_run
    src = _pyuff_file(tmp_path / "lab.unv", masing)
    (tmp_path / "map.toml").write_text(UFF_MAPPING)
    assert bench_main("import", src, "--out", tmp_path / "run", "--mapping", tmp_path / "map.toml") == 0
    text = open_run(tmp_path / "run").report().read_text()
    assert "Imported from" in text and "not a bench measurement" in text and str(src.resolve()) in text
    assert "Stepped sine report" not in text and "(backbone.png)" in text
    modes = open_run(tmp_path / "run").modes(model=False)
    assert modes["label"].str.contains("imported from lab.unv").all()
    capsys.readouterr()
    assert bench_main("identify", tmp_path / "run") == 2       # bench analyze fits it: test_analyze_fundamentals
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fundamentals only" in err[0] and "no time records" in err[0]
    assert not (tmp_path / "run" / "analysis").exists()
    with pytest.raises(ConfigurationError, match="no bench rig") as e:    # flip: the refusal dropped: red
        _ = open_run(tmp_path / "run").rig                                # (the URL check's three lines)
    assert len(str(e.value).splitlines()) == 1 and "lab.unv" in str(e.value)


# ---------------------------------------------------------------------------- bad input


def test_every_problem_one_line_exit_2_nothing_written(tmp_path, capsys):
    f = [40.0, 45.0, 50.0, 55.0, 60.0]
    rows = ["level [N],frequency [Hz],amplitude [m/s^2/N],phase [deg]"]
    rows += [f"1,{x},1e-6,-10" for x in f]                               # fine
    rows += [f"2,{x},1e-6,-10" for x in (40.0, 50.0, 45.0, 55.0, 60.0)]  # not increasing
    rows += [f"3,{x},{'nan' if x == 50 else 1e-6},-10" for x in f]      # NaN
    rows += [f"4,{x},1e-6,-10" for x in f[:3]]                          # too few
    (tmp_path / "bad.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "map.toml").write_text('[import]\nresponse = "disp"\n')   # the header's unit is an accelerance's
    capsys.readouterr()
    assert bench_main("import", tmp_path / "bad.csv", "--out", tmp_path / "run",
                      "--mapping", tmp_path / "map.toml") == 2
    err = capsys.readouterr().err
    lines = [line.strip() for line in err.splitlines()[1:]]
    assert all(str(tmp_path / "bad.csv") in line for line in lines), lines
    assert any("m/s^2/N" in line and "compliance" in line for line in lines), lines
    assert not (tmp_path / "run").exists()
    # the unit mismatch stops before the levels are judged: without it, the levels' three
    (tmp_path / "map.toml").write_text('[import]\nresponse = "accel"\n')
    assert bench_main("import", tmp_path / "bad.csv", "--out", tmp_path / "run",
                      "--mapping", tmp_path / "map.toml") == 2
    lines = [line.strip() for line in capsys.readouterr().err.splitlines()[1:]]
    assert len(lines) == 3, lines
    assert any("level 2" in line and "not increasing" in line for line in lines)
    assert any("level 3" in line and "NaN" in line for line in lines)
    assert any("level 4" in line and "3 frequencies" in line for line in lines)
    assert not (tmp_path / "run").exists()


def test_a_field_missing_from_the_mapping_is_named(tmp_path, capsys):
    (tmp_path / "t.csv").write_text("level [N],frequency [Hz],amplitude [m/N]\n" +
                                    "".join(f"1,{x},1e-6\n" for x in (40, 45, 50, 55)))
    assert bench_main("import", tmp_path / "t.csv", "--out", tmp_path / "run") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "t.csv: phase: not in the file and not in the mapping" in err, err
    assert not (tmp_path / "run").exists()


def test_a_column_the_mapping_names_and_the_file_lacks_is_named(tmp_path, capsys):
    (tmp_path / "t.csv").write_text("level [N],f [Hz],re [m/N],im [m/N]\n" +
                                    "".join(f"1,{x},1e-6,0\n" for x in (40, 45, 50, 55)))
    (tmp_path / "map.toml").write_text('[import]\n[import.fields]\nfrequency = "freq"\n')
    assert bench_main("import", tmp_path / "t.csv", "--out", tmp_path / "run", "--mapping", tmp_path / "map.toml") == 2
    err = capsys.readouterr().err
    assert "t.csv: frequency: the mapping names 'freq', which the file lacks" in err, err
    assert not (tmp_path / "run").exists()


def test_a_v73_mat_file_written_by_hdf5storage_imports_to_the_v5_files_modes(tmp_path, capsys):
    """MATLAB's v7.3 (HDF5) layout as hdf5storage writes it: the same tests as the v5 file give
    the same modes; a file with the v7.3 header and no HDF5 behind it is one line, exit 2.
    Flip: a v7.3 file read by scipy.io.loadmat (is_v73 -> False): exit 2, red."""
    f = np.linspace(45.0, 75.0, 31)
    levels = {1e-6: (f, sdof(f, 60.0, 0.03)), 3e-6: (f, sdof(f, 58.0, 0.04))}
    write_mat(tmp_path / "v5.mat", levels)
    write_mat(tmp_path / "v73.mat", levels, version="7.3")
    assert (tmp_path / "v73.mat").read_bytes().startswith(b"MATLAB 7.3")
    (tmp_path / "map.toml").write_text(MAT_MAPPING)
    got = {}
    for v in ("v5", "v73"):
        assert bench_main("import", tmp_path / f"{v}.mat", "--out", tmp_path / v, "--mapping", tmp_path / "map.toml") == 0
        got[v] = sorted((e.level_N, round(e.resonance_Hz, 6), round(e.damping_ratio, 6))
                        for e in run_modes(tmp_path / v, model=False).modes if e.mode == "feed")
    assert got["v73"] == got["v5"] and len(got["v5"]) == 2, got
    capsys.readouterr()
    head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Dec  7 2026 HDF5 schema 1.00 ."
    (tmp_path / "t.mat").write_bytes(head.ljust(512, b" ") + b"\x89HDF\r\n\x1a\n" + bytes(64))
    assert bench_main("import", tmp_path / "t.mat", "--out", tmp_path / "run") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "t.mat: cannot be read" in err[0], err
    assert not (tmp_path / "run").exists()
    # a value that is not numbers: named, exit 2 (flip: NotNumbers not caught: exit 1, red)
    import h5py
    with h5py.File(tmp_path / "odd.mat", "w") as h:
        h["tests"] = np.zeros(3, dtype=[("a", "f8"), ("b", "f8")])
    assert bench_main("import", tmp_path / "odd.mat", "--out", tmp_path / "run") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "odd.mat: tests is a MATLAB" in err[0], err


def test_twelve_levels_of_41_frequencies_and_their_modes_in_a_few_seconds(tmp_path, capsys):
    import pandas as pd
    f = np.linspace(40.0, 80.0, 41)
    rows = []
    for k in range(12):
        H = sdof(f, 65.0 - k, 0.02 + 0.002 * k)
        rows += [{"level [N]": 1.0 + k, "frequency [Hz]": x, "re [m/N]": h.real, "im [m/N]": h.imag}
                 for x, h in zip(f, H, strict=True)]
    pd.DataFrame(rows).to_csv(tmp_path / "big.csv", index=False)
    t0 = time.perf_counter()
    assert bench_main("import", tmp_path / "big.csv", "--out", tmp_path / "run") == 0
    run = run_modes(tmp_path / "run", model=False)
    seconds = time.perf_counter() - t0
    print(f"import of 12 levels x 41 frequencies and their modes: {seconds:.2f} s")
    feed = sorted((e for e in run.modes if e.mode == "feed"), key=lambda e: e.level_N)
    assert len(feed) == 12 and all(e.ok for e in feed)
    for k, e in enumerate(feed):
        assert abs(e.resonance_Hz / ((65.0 - k) * math.sqrt(1 - 2 * (0.02 + 0.002 * k) ** 2)) - 1) < 1e-4
    assert seconds < 5.0


def test_the_howtos_example_files_are_the_generators_and_import(tmp_path, capsys):
    """docs/howto/frf-examples/ is what docs/gen_frf_examples.py writes (with benchtools'
    writers, as the tests' files): each imports, and the mapping files are the writers' own."""
    import runpy

    from benchtools import REPO
    docs = REPO / "docs" / "howto" / "frf-examples"
    gen = runpy.run_path(str(REPO / "docs" / "gen_frf_examples.py"))
    written = gen["write_examples"](tmp_path / "ex")
    assert sorted(p.name for p in written) == sorted(p.name for p in docs.iterdir())
    for p in written:
        if p.suffix in (".toml", ".csv"):
            assert p.read_text() == (docs / p.name).read_text(), p.name
    for name, mapping in gen["EXAMPLES"]:
        for where in (tmp_path / "ex", docs):
            out = tmp_path / f"run-{where.name}-{name}"
            assert bench_main("import", where / name, "--out", out, "--mapping", where / mapping) == 0
            assert all(e.ok for e in run_modes(out, model=False).modes if e.mode == "feed"), name
