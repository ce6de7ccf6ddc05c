"""The analysis page (bench.reports.write_analysis_html): one self-contained HTML file that a
browser renders offline, verdict first, every figure loaded, robust to missing parts."""

from __future__ import annotations

import copy
import math
import re
import shutil
import subprocess
from html import unescape
from html.parser import HTMLParser

import numpy as np
import pytest

from bench.reports import write_analysis_html
from bench.reports._analysis import analysis_data
from bench.reports._figures_analysis import plot_analysis_frf, plot_analysis_loops

from .analysis_example import C_TRUE

needs_chromium = pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium not installed")

# after load, the page reports how many images decoded (naturalWidth > 0) into the DOM
RENDER_CHECK = """<script>
window.addEventListener("load", () => {
  const imgs = Array.from(document.images);
  const m = document.createElement("div");
  m.id = "render-check";
  m.dataset.images = imgs.length;
  m.dataset.loaded = imgs.filter(i => i.complete && i.naturalWidth > 0).length;
  m.dataset.widths = imgs.map(i => i.naturalWidth).join(",");
  const v = document.querySelector(".verdict");
  m.dataset.verdict = v ? v.textContent : "";
  document.body.appendChild(m);
});
</script>"""


class _Tags(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags: list[tuple[str, dict]] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))


def _tags(text: str) -> list[tuple[str, dict]]:
    p = _Tags()
    p.feed(text)
    return p.tags


def _chromium(*args: str) -> str:
    out = subprocess.run(["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                          "--virtual-time-budget=5000", *args], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def _render_check(page, tmp_path) -> dict:
    """Open a copy of ``page`` with the check script in headless Chromium; the marker's data."""
    probe = tmp_path / "probe.html"
    probe.write_text(page.read_text().replace("</body>", RENDER_CHECK + "</body>"))
    dom = _chromium("--dump-dom", probe.as_uri())
    marks = [a for t, a in _tags(dom) if a.get("id") == "render-check"]
    assert marks, "the page did not finish loading in Chromium (no render marker in the DOM)"
    return marks[0]


@pytest.fixture(scope="module")
def page(analysis_example, tmp_path_factory):
    return write_analysis_html(analysis_example, tmp_path_factory.mktemp("page") / "analysis.html")


def test_example_analysis_finds_the_viscous_damping_the_plant_had(analysis_example):
    """The fixture is physics, not typed-in numbers: the damping put into the plant is what it names."""
    (cause,) = analysis_example["causes"]
    assert cause["id"] == "viscous_damping"
    c = cause["parameters"]["c"]["value"]
    assert c == pytest.approx(C_TRUE, rel=0.25)
    assert cause["gain"]["heldout_error_after"] < 0.5 * cause["gain"]["heldout_error_before"]


def test_page_is_self_contained(page):
    text = page.read_text()
    tags = _tags(text)
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:|//|file:)""", text)
    assert not [t for t, _ in tags if t in ("link", "script", "iframe", "object")]
    imgs = [a for t, a in tags if t == "img"]
    assert len(imgs) == 5            # overview, compliance, accelerance, loops, residuals (no restoring force here)
    for a in imgs:
        assert a["src"].startswith("data:image/png;base64,")
        assert len(a.get("alt", "")) > 40, "every figure needs a description for screen readers"


def test_page_leads_with_the_verdict_and_names_the_cause(page, analysis_example):
    text = page.read_text()
    verdict = analysis_example["verdict"]
    assert text.index(verdict) < text.index("Causes named</h2>") < text.index("Candidates tried</h2>")
    headings = [t for t, _ in _tags(text) if t in ("h1", "h2")]
    assert headings[0] == "h1" and headings.count("h1") == 1
    assert ("Unexplained" in text) == analysis_example["unexplained"]
    c = analysis_example["causes"][0]["parameters"]["c"]
    # each figure to the digit its interval supports: the last digit shown is where the
    # interval's half-width has its first or second significant digit, no further
    row = re.search(r"c = ([^ ]+) N s/m \(95 %: ([^ ]+) to ([^ )]+)\)", text)
    value, low, high = row.groups()
    step = 10.0 ** -(len(value.split(".")[1]) if "." in value else 0)
    assert step <= (c["high"] - c["low"]) / 2 < 100 * step, (row.groups(), c)
    for shown, exact in zip((value, low, high), (c["value"], c["low"], c["high"])):
        assert abs(float(shown) - exact) <= step / 2 * (1 + 1e-9)
    # the details come after the causes, collapsed
    assert text.index("Causes named</h2>") < text.index('<details id="details">') < text.index("Candidates tried</h2>")


def test_page_lists_every_candidate_and_rejected_step(page, analysis_example):
    text = page.read_text()
    section = text.split("Candidates tried</h2>")[1].split("</table>")[0]
    rows = re.findall(r"<tr><td><code>(\w+)</code></td>.*?<td>(<strong>yes</strong>|no)</td></tr>", section)
    assert len(rows) == len(analysis_example["candidates"])
    assert {r[0] for r in rows} == {c["id"] for c in analysis_example["candidates"]}
    assert {r[0] for r in rows if r[1] != "no"} == {c["id"] for c in analysis_example["candidates"] if c["named"]}
    for r in analysis_example["steps_rejected"]:
        assert f"<td>{r['step']}</td><td>{r['reason']}</td>" in text


def test_frf_figure_draws_the_measured_and_model_values_of_the_dict(analysis_example):
    a = analysis_data(analysis_example)
    fig = plot_analysis_frf(a.steps, "compliance")
    drawn = [line.get_ydata() for ax in fig.axes for line in ax.get_lines()]
    for s in analysis_example["steps"]:
        for part in ("measured", "base", "final"):
            v = abs(complex(*s[part]["compliance"]))
            assert any(np.isclose(y, v, rtol=1e-12).any() for y in drawn), (s["key"], part)


def test_loop_figure_draws_each_chosen_step(analysis_example):
    a = analysis_data(analysis_example)
    fig = plot_analysis_loops(a.loops)
    titles = [ax.get_title() for ax in fig.axes if ax.get_lines()]
    assert titles == [f"{lp['key']} ({lp['level_N']:.3g} N, {lp['freq_Hz']:.3g} Hz)"
                      for lp in analysis_example["loops"]]
    meas = fig.axes[0].get_lines()[0]
    assert np.allclose(meas.get_xdata()[:-1], 1e6 * np.array(analysis_example["loops"][0]["disp_m"]))


def test_final_model_equal_to_the_base_is_not_drawn_twice(analysis_example):
    d = _variant(analysis_example, causes=[],
                 steps=[dict(s, final=s["base"]) for s in analysis_example["steps"]],
                 loops=[dict(lp, friction_final_N=lp["friction_base_N"]) for lp in analysis_example["loops"]])
    a = analysis_data(d)
    for fig in (plot_analysis_frf(a.steps, "accelerance"), plot_analysis_loops(a.loops)):
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert labels[-1] == "base model (Masing)", labels


@needs_chromium
def test_chromium_renders_the_page_with_every_figure_and_the_verdict(page, analysis_example, tmp_path):
    mark = _render_check(page, tmp_path)
    assert int(mark["data-images"]) == 5
    assert int(mark["data-loaded"]) == 5, f"image widths: {mark['data-widths']}"
    assert all(int(w) > 500 for w in mark["data-widths"].split(","))
    assert analysis_example["verdict"] in mark["data-verdict"]
    shot = tmp_path / "page.png"
    _chromium("--window-size=1200,2400", f"--screenshot={shot}", page.as_uri())
    from matplotlib.image import imread
    img = imread(shot)
    assert img.shape[:2] == (2400, 1200)
    ink = np.any(img[..., :3] < 0.9, axis=-1).mean()
    assert 0.02 < ink < 0.6


def _variant(example, **changes) -> dict:
    d = copy.deepcopy(example)
    d.update(changes)
    return d


def test_no_cause_and_unexplained_is_said_in_words_without_a_final_model(analysis_example, tmp_path):
    d = _variant(analysis_example, causes=[], unexplained=True,
                 verdict="Structure remains that no candidate explains.",
                 candidates=[dict(c, named=False) for c in analysis_example["candidates"]],
                 steps=[{k: v for k, v in s.items() if k != "final"} for s in analysis_example["steps"]],
                 loops=[{k: v for k, v in lp.items() if k != "friction_final_N"} for lp in analysis_example["loops"]])
    text = write_analysis_html(d, tmp_path / "a.html").read_text()
    assert 'class="verdict unexplained"' in text
    assert "No cause named." in text and "no candidate explains what remains" in text
    assert "<strong>yes</strong>" not in text
    assert text.count("<img ") == 5
    fig = plot_analysis_frf(analysis_data(d).steps, "compliance")
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["measured", "base model (Masing)"]


def test_clean_bill_of_health_names_no_cause(analysis_example, tmp_path):
    d = _variant(analysis_example, causes=[], unexplained=False, verdict="The Masing model explains the data.",
                 steps=[], loops=[])
    text = write_analysis_html(d, tmp_path / "a.html").read_text()
    assert 'class="verdict"' in text and "Unexplained" not in text
    assert "the base model explains the data within the noise" in text


@needs_chromium
def test_minimal_analysis_gives_a_page_that_says_what_is_missing(tmp_path):
    page = write_analysis_html({"verdict": "Too few steps to analyse."}, tmp_path / "a.html")
    text = page.read_text()
    for words in ("Too few steps to analyse.", "No cause named.", "No per-step data", "No hysteresis loops",
                  "No candidate scores", "No parameters in the analysis", "0 steps used, 0 rejected"):
        assert words in text, words
    mark = _render_check(page, tmp_path)
    assert mark["data-images"] == "0" and "Too few steps" in mark["data-verdict"]


def test_malformed_parts_are_named_on_the_page_and_the_rest_is_shown(analysis_example, tmp_path):
    d = _variant(analysis_example, schema="guideway-bench/analysis/9",
                 causes=[{"label": "no id"}] + analysis_example["causes"],
                 loops=[{"key": "bad", "disp_m": [0, 1, 2], "friction_meas_N": [0, 1]}],
                 steps_rejected="everything", steps=analysis_example["steps"][:3])
    text = write_analysis_html(d, tmp_path / "a.html").read_text()
    problems = unescape(text.split("could not be shown</h2>")[1].split("</section>")[0])
    assert "'causes' entry 0" in problems and "'loops' entry 0" in problems
    assert "'steps_rejected' is not a list" in problems and "analysis/9" in problems
    assert "viscous damping" in text.split("Causes named</h2>")[1]
    assert text.count("<img ") == 4          # no loop figure, the others (with the overview) still there


def test_not_a_dict_is_a_clear_error(tmp_path):
    with pytest.raises(TypeError, match="must be a dict"):
        write_analysis_html(["verdict"], tmp_path / "a.html")
    assert not (tmp_path / "a.html").exists()


def test_non_finite_values_show_as_not_available(analysis_example, tmp_path):
    d = _variant(analysis_example, steps=[], loops=[])
    d["causes"][0]["gain"]["delta_bic"] = math.nan
    d["parameters"]["n"] = {"value": 0.46, "low": None, "high": "?"}
    text = write_analysis_html(d, tmp_path / "a.html").read_text()
    assert "&Delta;BIC = n/a" in text
    assert '<td>n</td><td>-</td><td class="num">0.46</td><td class="num">n/a</td><td class="num">n/a</td>' in text


def test_candidates_of_several_selection_rounds_are_shown_by_round(analysis_example, tmp_path):
    first = [dict(c, round=1, heldout_error=c["heldout_error"] if c["named"] else None)
             for c in analysis_example["candidates"]]
    second = [dict(c, round=2, named=False) for c in analysis_example["candidates"] if not c["named"]]
    d = _variant(analysis_example, candidates=first + second, steps=[], loops=[])
    text = write_analysis_html(d, tmp_path / "a.html").read_text()
    section = text.split("Candidates tried</h2>")[1].split("</table>")[0]
    rows = re.findall(r"<tr><td>(\d)</td><td><code>(\w+)</code></td><td[^>]*>[^<]*</td><td[^>]*>([^<]*)</td>", section)
    assert [r[0] for r in rows] == ["1"] * len(first) + ["2"] * len(second)
    assert rows[0][1] == analysis_example["causes"][0]["id"]        # the named one leads its round
    assert sum(r[2] == "not computed" for r in rows) == len(first) - 1
