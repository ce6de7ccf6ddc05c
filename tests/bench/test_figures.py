"""Figures as people read them: log axes with plain tick labels (60, 2e-06, never a mathtext
6x10^1), titles inside the figure (a long one wrapped, not cut at the edges)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from bench.reports._figures import plain_tick, png_bytes, save_png, sparse_tick


def _labels(axis) -> list[str]:
    ticks = axis.get_major_ticks() + axis.get_minor_ticks()
    return [t.label1.get_text() for t in ticks if t.label1.get_visible() and t.label1.get_text()]


def test_log_axes_read_plain_numbers_on_a_short_span():
    fig = Figure(figsize=(6, 4), layout="constrained")
    ax = fig.subplots()
    f = np.geomspace(45, 90, 20)
    ax.loglog(f, 1e-4 / f)                          # y from 1.1e-6 to 2.2e-6: no power of ten in view
    ax.set_xlim(45, 90)
    ax.set_ylim(1.1e-6, 4.5e-6)
    png_bytes(fig)
    x, y = _labels(ax.xaxis), _labels(ax.yaxis)
    assert x and y
    assert not [s for s in x + y if "times" in s or "$" in s or "^" in s], (x, y)
    assert "50" in x and "2e-06" in y and "3e-06" in y, (x, y)
    assert plain_tick(60.0) == "60" and plain_tick(0.3) == "0.3"
    assert sparse_tick(60.0) == "" and sparse_tick(50.0) == "50" and sparse_tick(3e-6) == "3e-06"


def test_wide_log_axes_keep_powers_of_ten_and_no_crowded_minor_labels():
    fig = Figure(figsize=(6, 4), layout="constrained")
    ax = fig.subplots()
    ax.loglog([20, 1000], [1e-8, 1e-5])
    png_bytes(fig)
    y = _labels(ax.yaxis)
    assert y and all("10^" in s for s in y), y                  # 10^-7 ...: decades only
    x = _labels(ax.xaxis)
    assert "100" in x and not [s for s in x if "$" in s], x    # 100, 1000 as plain numbers


def test_a_long_title_is_wrapped_inside_the_figure_and_its_axes(tmp_path):
    words = "Seed Fig. 17 from measurements: resonance frequency and damping ratio of the pitching mode " \
            "against the force amplitude, one colour per run, 95 % intervals, the rig model as lines"
    fig = Figure(figsize=(6, 4), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2)
    fig.suptitle(words)
    ax1.set_title(words[:90], loc="left")
    ax2.set_title(words[90:])
    save_png(fig, tmp_path / "t.png")
    fig.draw_without_rendering()
    sup = fig._suptitle.get_window_extent()
    assert 0 <= sup.x0 and sup.x1 <= fig.bbox.width and "\n" in fig._suptitle.get_text()
    assert " ".join(fig._suptitle.get_text().split()) == words        # every word kept
    for ax, t in ((ax1, ax1._left_title), (ax2, ax2.title)):
        box = t.get_window_extent()
        assert box.width <= ax.bbox.width and 0 <= box.x0 and box.x1 <= fig.bbox.width, (box, ax.bbox)
    short = Figure(figsize=(6, 4), layout="constrained")
    short.suptitle("Compliance: demo")
    png_bytes(short)
    assert short._suptitle.get_text() == "Compliance: demo"          # a title that fits stays as it is


def test_the_saved_png_shows_the_wrapped_title_and_a_figure_that_fits_is_drawn_once(monkeypatch):
    # the figure is saved, its titles fitted to that layout, and saved again when one was
    # rewrapped (decision 0048): the bytes returned are those of the final, wrapped state
    import io

    from PIL import Image

    words = "Seed Fig. 17 from measurements: resonance frequency and damping ratio of the pitching mode " \
            "against the force amplitude, one colour per run, 95 % intervals, the rig model as lines"
    fig = Figure(figsize=(6, 4), layout="constrained")
    fig.subplots(1, 2)
    fig.suptitle(words)
    saves = []
    real = Figure.savefig
    monkeypatch.setattr(Figure, "savefig", lambda self, *a, **k: (saves.append(1), real(self, *a, **k))[1])
    shown = np.asarray(Image.open(io.BytesIO(png_bytes(fig))))
    assert "\n" in fig._suptitle.get_text() and len(saves) == 2
    buf = io.BytesIO()
    real(fig, buf, format="png", dpi=96)                              # the final state, saved again
    final = np.asarray(Image.open(io.BytesIO(buf.getvalue())))
    assert shown.shape == final.shape and (shown != final).any(axis=-1).mean() < 1e-3
    short = Figure(figsize=(6, 4), layout="constrained")
    short.subplots(1, 2)
    short.suptitle("Compliance: demo")
    saves.clear()
    png_bytes(short)
    assert len(saves) == 1                                           # titles that fit: one draw
