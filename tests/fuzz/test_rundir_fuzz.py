"""Fuzzing run directories: mutated step files.

Six steps are written through the storage layer (the same code as a real run); then
random steps get bytes flipped, inserted or cut, files emptied, deleted or swapped.
Properties: the readers never raise, keep every untouched step and reject every changed
one whose content differs (the checksums see a single flipped bit anywhere); `check`
names each rejected step; `set_aside_damaged` moves exactly those, keeping the bytes.
"""

from __future__ import annotations

import json
import shutil
import time

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from bench.config import DEFAULTS, load_plan
from bench.storage import RunStore

from ._settings import TIME_BOUND_S, fuzz

N_STEPS = 6


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    plan = load_plan(DEFAULTS / "demo_plan.toml")
    run = tmp_path_factory.mktemp("rundir") / "run"
    store = RunStore.create(run, {"plan": plan.to_dict()})
    rng = np.random.default_rng(3)
    for spec in plan.schedule()[:N_STEPS]:
        n = int(rng.integers(50, 400))
        fit = dict(amplitude=list(rng.random(3)), phase_rad=list(rng.normal(size=3)), offset=0.0, thd=0.01,
                   noise_rms=1e-3, peak_to_peak=2.0, raw_peak_to_peak=2.0)
        result = dict(key=spec.key, index=spec.index, level_index=spec.level_index, freq_index=spec.freq_index,
                      direction=spec.direction, freq_Hz=spec.freq_Hz, target_force_N=spec.force_N,
                      force_N=spec.force_N, force_error=0.0, drive_Vpp=0.5,
                      compliance_m_per_N=complex(*rng.normal(size=2)) * 1e-7, compliance_abs_m_per_N=1e-7,
                      compliance_phase_rad=-0.5, accelerance_abs_kg_inv=0.1, accelerance_phase_rad=0.1,
                      force=fit, accel=fit, disp=fit, fs_Hz=25600.0, n_samples=n, flags=[True, None, "x"],
                      quality=dict(status="usable", reason="", notes=[], freq_Hz=spec.freq_Hz, level_N=None,
                                   record_s=None, artefacts=[]),
                      harmonics=dict(freq_Hz=spec.freq_Hz, fs_Hz=25600.0, periods=2, samples=n, start=0,
                                     drift_sigma=0.0, drift_detail="", **{ch: dict(re=list(rng.random(3)),
                                     im=list(rng.random(3)), offset=0.0, noise_rms=1e-3, sigma=1e-4)
                                     for ch in ("force", "accel", "disp")}))
        raw = dict(force_N=rng.normal(size=n), accel_m_s2=rng.normal(size=n), disp_m=rng.normal(size=n),
                   fs_Hz=np.array(25600.0))
        store.write_step(spec.key, result, raw)
    return run


damage = st.tuples(st.integers(0, N_STEPS - 1), st.sampled_from([".json", ".npz"]),
                   st.sampled_from(["flip", "insert", "cut", "empty", "delete", "append"]),
                   st.floats(0, 1), st.integers(0, 255))


def apply(path, how, where, byte):
    data = bytearray(path.read_bytes())
    i = min(int(where * len(data)), len(data) - 1)
    if how == "flip":
        data[i] ^= (byte % 255) + 1                 # never a no-op
    elif how == "insert":
        data.insert(i, byte)
    elif how == "cut":
        del data[i:]
    elif how == "empty":
        data = bytearray()
    elif how == "append":
        data += bytes([byte]) * 3
    if how == "delete":
        path.unlink()
    else:
        path.write_bytes(bytes(data))


def json_content_unchanged(before: bytes, path) -> bool:
    """A change that leaves the parsed content equal (e.g. whitespace) is no damage."""
    try:
        return json.loads(path.read_bytes()) == json.loads(before)
    except (ValueError, UnicodeDecodeError, FileNotFoundError):
        return False


@given(st.lists(damage, min_size=1, max_size=4))
@fuzz(80)
def test_readers_keep_intact_steps_and_reject_every_changed_one(pristine, tmp_path_factory, damages):
    run = tmp_path_factory.mktemp("fz") / "run"
    shutil.copytree(pristine, run)
    keys = sorted(p.stem for p in (run / "steps").glob("*.json"))
    original = {p.name: p.read_bytes() for p in (run / "steps").iterdir()}
    for k, ext, how, where, byte in damages:
        p = run / "steps" / f"{keys[k]}{ext}"
        if p.exists():
            apply(p, how, where, byte)
    changed = set()
    for k in keys:
        for ext in (".json", ".npz"):
            p = run / "steps" / f"{k}{ext}"
            now = p.read_bytes() if p.exists() else None
            if now != original[p.name] and not (ext == ".json" and json_content_unchanged(original[p.name], p)):
                changed.add(k)
    t = time.monotonic()
    store = RunStore.open(run)
    good = {r["key"] for r in store.results()}
    assert good == set(keys) - changed
    # a deleted .json is a step not done (resume measures it): not a damaged file
    damaged_files = {k for k in changed if (run / "steps" / f"{k}.json").exists()}
    assert {p.key for p in store.check()} == damaged_files
    for k in good:
        raw = store.raw(k)
        assert raw["force_N"].size == store.verify_step(k)["n_samples"]
    moved = store.set_aside_damaged()
    assert {p.key for p in moved} == damaged_files
    assert store.check() == [] and {r["key"] for r in store.results()} == good
    aside = {p.name: p.read_bytes() for p in (run / "damaged").glob("*/*")}
    for name, data in aside.items():
        assert (run / "steps" / name).exists() is False and name in original
    assert time.monotonic() - t < TIME_BOUND_S
