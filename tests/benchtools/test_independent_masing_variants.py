"""benchtools.independent_masing.generate_uff_variants (issue 43 item 2's hum benchmark): one
plant integrated once, several probe lines written; each file is the one generate_uff writes
with that line and seed (its own noise and line phase), so a variant's analysis differs from
the clean case's only by its line."""

import hashlib

from benchtools.independent_masing import generate_uff, generate_uff_variants

CASE = dict(F_s_N=2.5, x_s_m=36e-6, n=1.5, mass_kg=4.3, levels_N=[0.25, 2.1], freqs_Hz=[20.0, 50.0])
KW = dict(settle=5, measure=8, seed=7, rtol=1e-9)


def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_each_variant_is_the_file_generate_uff_writes_with_its_line(tmp_path):
    lines = {tmp_path / "clean.uff": (0.0, 0.0), tmp_path / "hum.uff": (50.0, 6e-6)}
    assert generate_uff_variants(lines, **CASE, **KW) == 4
    for path, (hz, m) in lines.items():
        one = tmp_path / f"one_{path.name}"
        generate_uff(one, **CASE, **KW, line_Hz=hz, line_m=m)
        assert _sha(path) == _sha(one), path.name
    assert _sha(tmp_path / "clean.uff") != _sha(tmp_path / "hum.uff")
