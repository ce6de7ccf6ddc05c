"""Packaging: an SPDX licence with its file, only the four packages installed (not
benchmarks/), a py.typed marker in each, ``bench --version`` and ``python -m bench``."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from importlib import metadata

from setuptools import find_packages

import bench
from bench.cli import main
from benchtools import REPO

PACKAGES = ("bench", "drivers", "procedures", "sim")


def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())


def test_licence_is_an_spdx_string_with_its_file():
    project = _pyproject()["project"]
    assert project["license"] == "MIT"
    assert project["license-files"] == ["LICENSE"]
    text = (REPO / "LICENSE").read_text()
    assert text.startswith("MIT License") and "guideway-bench developers" in text


def test_only_the_four_packages_are_installed_each_typed():
    find = _pyproject()["tool"]["setuptools"]["packages"]["find"]
    found = find_packages(where=str(REPO), include=find["include"])
    assert {p.split(".")[0] for p in found} == set(PACKAGES)       # not benchmarks, not tests
    assert {"bench.reports", "bench.studies", "bench.watch", "sim.discrepancy"} <= set(found)
    data = _pyproject()["tool"]["setuptools"]["package-data"]
    for pkg in PACKAGES:
        assert (REPO / pkg / "py.typed").is_file(), pkg
        assert "py.typed" in data[pkg], pkg


def test_version_on_the_command_line(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"bench {metadata.version('guideway-bench')}"
    assert bench.__version__ == metadata.version("guideway-bench")


def test_python_dash_m_bench_is_the_command_line():
    out = subprocess.run([sys.executable, "-m", "bench", "--version"], cwd=REPO, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == f"bench {bench.__version__}", out
    bad = subprocess.run([sys.executable, "-m", "bench", "no-such-command"], cwd=REPO, capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 2 and "invalid choice" in bad.stderr
