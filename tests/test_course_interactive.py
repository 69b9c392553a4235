"""``lago_cvx.course.interactive``: sliders in a live Jupyter kernel with ipywidgets, one static figure at the
defaults anywhere else (a script, the tests, the rendered notebooks); and each lecture's interactive figure
draws at its defaults, quickly."""

from __future__ import annotations

import time

import matplotlib
import numpy as np
import pytest

from lago_cvx import course
from lago_cvx.errors import OptionError

matplotlib.use("Agg")


def _recorder(calls):
    def draw(ax, *, sigma, n):
        calls.append({"sigma": sigma, "n": n})
        ax.plot(np.arange(n), sigma * np.arange(n))
        return ax
    return draw


def test_static_mode_draws_once_at_the_defaults(tmp_path, monkeypatch):
    monkeypatch.setenv("LAGO_CVX_FIGURES", str(tmp_path))
    course.setup("99_test")
    calls = []
    course.interactive(_recorder(calls), "slider", sigma=(0.0, 1.0, 0.1, 0.3), n=(2, 20, 1, 5))
    assert calls == [{"sigma": 0.3, "n": 5}]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["99_test_slider.png", "99_test_slider.svg"]
    import matplotlib.pyplot as plt

    assert not plt.get_fignums(), "the static figure is closed after it is shown"


def test_static_when_asked_even_in_a_kernel(monkeypatch):
    """``LAGO_CVX_STATIC=1`` (set by lectures/render.py) wins over a live kernel: the rendered notebook stores a
    plain figure; without it, a kernel with ipywidgets gets the sliders."""
    pytest.importorskip("ipywidgets")
    monkeypatch.setattr(course, "_in_notebook", lambda: True)
    monkeypatch.setenv("LAGO_CVX_STATIC", "1")
    assert course._static()
    monkeypatch.setenv("LAGO_CVX_STATIC", "0")
    assert not course._static()
    monkeypatch.setattr(course, "_in_notebook", lambda: False)
    assert course._static()


def test_live_mode_shows_sliders_that_redraw(monkeypatch):
    widgets = pytest.importorskip("ipywidgets")
    monkeypatch.delenv("LAGO_CVX_FIGURES", raising=False)
    monkeypatch.delenv("LAGO_CVX_STATIC", raising=False)
    monkeypatch.setattr(course, "_in_notebook", lambda: False)   # show() neither displays nor writes
    monkeypatch.setattr(course, "_static", lambda: False)
    shown = []
    import IPython.display

    monkeypatch.setattr(IPython.display, "display", lambda obj, **kw: shown.append(obj))
    calls = []
    course.interactive(_recorder(calls), "slider", sigma=(0.0, 1.0, 0.1, 0.3), n=(2, 20, 1, 5))
    assert len(shown) == 1 and isinstance(shown[0], widgets.interactive)
    sliders = {w.description: w for w in shown[0].children if isinstance(w, widgets.widgets.ValueWidget)
               and hasattr(w, "min")}
    assert isinstance(sliders["sigma"], widgets.FloatSlider) and isinstance(sliders["n"], widgets.IntSlider)
    assert (sliders["sigma"].min, sliders["sigma"].max, sliders["sigma"].value) == (0.0, 1.0, 0.3)
    assert (sliders["n"].min, sliders["n"].max, sliders["n"].value) == (2, 20, 5)
    assert calls == [{"sigma": 0.3, "n": 5}]                     # drawn at the defaults on display
    sliders["sigma"].value = 0.7
    sliders["n"].value = 9
    assert calls[-2:] == [{"sigma": 0.7, "n": 5}, {"sigma": 0.7, "n": 9}]


@pytest.mark.parametrize("spec", [(0.0, 1.0, 0.1), (0.0, 1.0, 0.1, 2.0), (1.0, 0.0, 0.1, 0.5), (0.0, 1.0, 0.0, 0.5)])
def test_a_malformed_slider_is_an_option_error(spec):
    with pytest.raises(OptionError, match="slider sigma="):
        course.interactive(lambda ax, sigma: ax, "bad", sigma=spec)
