"""analysis.json's stored format (decision 0066): schema 2 names the parameters as the rig
model does (``mass_kg``); a file written as schema 1 (``m_kg``) is read by every reader as
schema 2, nothing lost."""

from __future__ import annotations

import json

import pytest

from bench.reports import analysis_estimate
from bench.reports._analysis import analysis_data
from bench.studies.batch import flatten
from bench.twin import load_analysis

# the head of the analysis.json `bench demo` + `bench analyze` wrote on main at 30ecf9f (schema 1),
# its plots' data ("candidates", "steps", "loops", ...) left out
OLD = """{"schema": "guideway-bench/analysis/1", "source": "/tmp/h4-demo-before", "software_version": "0.9.0",
 "parameters": {"F_s_N": {"value": 10.000005730846297, "low": 9.999864680021682, "high": 10.000146783660472},
                "x_s_m": {"value": 9.999808712947651e-06, "low": 9.99949402713398e-06, "high": 1.0000123408664538e-05},
                "n": {"value": 1.5000295713321705, "low": 1.4999889207909738, "high": 1.5000702218733672},
                "m_kg": {"value": 10.000017715162567, "low": 9.99997592117683, "high": 10.000059509322979}},
 "base": {"parameters": {"F_s_N": {"value": 9.99996854315233, "low": 9.999912685565954, "high": 10.000024401050714},
                         "x_s_m": {"value": 9.999852632184044e-06, "low": 9.999671998819734e-06, "high": 1.0000033268811303e-05},
                         "n": {"value": 1.5000186716452082, "low": 1.4999870681702558, "high": 1.5000502751201605},
                         "m_kg": {"value": 9.999997837980295, "low": 9.999984501068093, "high": 10.000011174910284}},
          "reduced_chi2": 0.88},
 "final": {"reduced_chi2": 0.88}, "causes": [], "unexplained": false,
 "verdict": "The Masing model explains the data within the noise (reduced chi-square 0.88, held-out error 1.66 %)."}"""
NAMES = ["F_s_N", "x_s_m", "n", "mass_kg"]


def test_an_analysis_json_of_schema_1_is_read_as_schema_2_by_every_reader(tmp_path):
    path = tmp_path / "analysis.json"
    path.write_text(OLD)
    twin_side = load_analysis(path)                              # bench twin --analysis
    assert twin_side["schema"] == "guideway-bench/analysis/2"
    assert list(twin_side["parameters"]) == list(twin_side["base"]["parameters"]) == NAMES
    assert twin_side["parameters"]["mass_kg"]["value"] == 10.000017715162567
    page = analysis_data(json.loads(OLD))                        # the analysis page and the run report
    assert page.problems == [] and list(page.parameters) == list(page.base_parameters) == NAMES
    assert page.base_parameters["mass_kg"].value == 9.999997837980295
    est = analysis_estimate(json.loads(OLD))                     # the report's and the watch page's estimate
    assert est["values"]["mass_kg"] == pytest.approx(10.000017715162567, rel=1e-15)
    row = flatten(json.loads(OLD))                               # a study's summary row
    assert row["mass_kg_value"] == 10.000017715162567 and "m_kg_value" not in row
