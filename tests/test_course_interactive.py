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


def test_a_kernel_shell_subclass_counts_as_a_notebook(monkeypatch):
    """Colab's shell subclasses ipykernel's ZMQInteractiveShell under another name: still a notebook."""
    zmqshell = pytest.importorskip("ipykernel.zmqshell")
    import IPython

    class Shell(zmqshell.ZMQInteractiveShell):
        pass

    monkeypatch.setattr(IPython, "get_ipython", lambda: object.__new__(Shell))
    assert course._in_notebook()
    monkeypatch.setattr(IPython, "get_ipython", lambda: object.__new__(IPython.core.interactiveshell.InteractiveShell))
    assert not course._in_notebook()
    monkeypatch.setattr(IPython, "get_ipython", lambda: None)
    assert not course._in_notebook()


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


# ----------------------------------------------------------------------------- the lectures' draw functions
def _title(draw, **values) -> str:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    try:
        assert draw(ax, **values) is ax
        assert ax.lines or ax.patches or ax.collections, f"{draw.__name__} drew nothing"
        return ax.get_title()
    finally:
        plt.close(fig)


def _numbers(text: str) -> list[float]:
    import re

    return [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?(?:e[+-]?\d+)?", text)]


@pytest.mark.parametrize("name", __import__("lago_cvx.course_sliders", fromlist=["__all__"]).__all__)
def test_each_draw_function_draws_at_its_defaults_quickly(name):
    from lago_cvx import course_sliders

    draw = getattr(course_sliders, name)
    _title(draw)                                       # warm-up: imports, caches
    start = time.perf_counter()
    _title(draw)
    seconds = time.perf_counter() - start
    # a guard against a pathological redraw, not a speed target: false_closures (GNC with its local moves on a
    # 150-pose world) takes about 3 s, and twice that on a loaded 2-core machine
    assert seconds < 15.0, f"{name} takes {seconds:.1f} s per redraw (a slider wants well under 1 s)"


def test_the_rounding_fails_first_on_the_odometric_tree():
    """Lecture 5's slider: wrong circuits grow with σ_θ, and the BFS tree's short circuits fail later."""
    import matplotlib.pyplot as plt

    from lago_cvx.course_sliders import rounding_failure

    wrong = {}
    for sigma in (0.05, 0.3, 0.5):
        fig, ax = plt.subplots()
        rounding_failure(ax, sigma_theta=sigma)
        wrong[sigma] = [int(_numbers(t.get_text())[0]) for t in ax.get_legend().get_texts()]  # [odometry, bfs]
        plt.close(fig)
    assert wrong[0.05] == [0, 0]
    assert 0 < wrong[0.3][0] < wrong[0.5][0] and wrong[0.3][1] < wrong[0.3][0] and wrong[0.5][1] < wrong[0.5][0]


def test_the_prior_tends_to_the_anchor_and_the_relaxations_loosen_with_noise():
    from lago_cvx import course_sliders as cs

    miss = [_numbers(_title(cs.prior_weight, log10_information=v))[-1] for v in (0.0, 2.0, 6.0)]
    assert miss[0] > miss[1] > miss[2] and miss[2] < 1e-3 and miss[0] > 1.0
    ratio_2d = [_numbers(_title(cs.chordal_tightness, sigma_theta=s))[-1] for s in (0.01, 0.1, 0.3)]
    ratio_3d = [_numbers(_title(cs.chordal_gap_3d, sigma_r=s))[-1] for s in (0.01, 0.1, 0.3)]
    for ratio in (ratio_2d, ratio_3d):
        assert 1.0 <= ratio[0] < 1.05 < ratio[1] < ratio[2], ratio
    gap = [_numbers(_title(cs.anisotropy_gap, log10_ratio=v))[-1] for v in (0.0, 2.0)]
    assert abs(gap[0] - 1.0) < 1e-3 and gap[1] > 1.1, gap


def test_the_rendered_lectures_store_each_interactive_figure_as_a_plain_figure():
    """``lectures/render.py`` runs the kernel with ``LAGO_CVX_STATIC=1``: each lecture's ``course.interactive`` cell
    stores a PNG (what the site shows), never a widget that the site could not draw."""
    import importlib.util
    from pathlib import Path

    nbformat = pytest.importorskip("nbformat")
    lectures = Path(__file__).resolve().parents[1] / "lectures"
    spec = importlib.util.spec_from_file_location("lectures_render", lectures / "render.py")
    render = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(render)
    assert render.kernel_environment()["LAGO_CVX_STATIC"] == "1"
    notebooks = sorted(lectures.glob("[0-9][0-9]*_*.ipynb"))
    assert notebooks
    for path in notebooks:
        nb = nbformat.read(path, as_version=4)
        cells = [c for c in nb.cells if c.cell_type == "code" and "course.interactive(" in c.source]
        assert len(cells) == 1, f"{path.name}: {len(cells)} interactive figures (one per lecture)"
        kinds = [set(o.get("data", {})) for o in cells[0].get("outputs", [])]
        assert any("image/png" in k for k in kinds), f"{path.name}: the interactive cell stores no figure"
        assert not any("application/vnd.jupyter.widget-view+json" in k for k in kinds), f"{path.name}: a widget stored"
