"""reports.canvas: every figure of rbcheck is drawn on one canvas (no pyplot, one place that makes figures),
and a PNG is saved whole or not at all."""
import ast
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from reports import canvas

ROOT = Path(__file__).resolve().parents[2]
#: The modules of matplotlib that make figures or attach a canvas to one: only reports.canvas imports them.
FIGURE_MAKERS = ("matplotlib.pyplot", "matplotlib.figure", "matplotlib.backends")


def figure_imports(source: str) -> list:
    """``(line, module)`` of every import (module level or in a function) of a module that makes figures."""
    out = []
    for node in ast.walk(ast.parse(source)):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                 else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
        out += [(node.lineno, n) for n in names if n.startswith(FIGURE_MAKERS)]
    return out


def test_only_the_canvas_makes_figures_and_nothing_draws_through_pyplot():
    """The integrators page, the polhodes, check --plot and the animations draw on canvas.new_figure: a
    module of ``reports`` that imports pyplot or makes its own Figure is found here."""
    bad = [f"{p.relative_to(ROOT)}:{line}: {mod}" for p in sorted((ROOT / "reports").rglob("*.py"))
           if p.name != "canvas.py" for line, mod in figure_imports(p.read_text(encoding="utf-8"))]
    assert not bad, "\n".join(bad)


def test_planted_figure_imports_are_found():
    planted = ("import matplotlib.pyplot as plt\n"
               "def f():\n"
               "    from matplotlib.figure import Figure\n"
               "    from matplotlib.backends.backend_agg import FigureCanvasAgg\n"
               "    from matplotlib.patches import Patch\n")
    assert [m for _, m in figure_imports(planted)] == ["matplotlib.pyplot", "matplotlib.figure",
                                                       "matplotlib.backends.backend_agg"]


def _drawn(fig):
    ax = fig.subplots(1, 2, sharey=True, squeeze=False)[0]
    ax[0].barh([0, 1, 2], [3.0, 1e-3, 40.0], color="#0072B2")
    ax[0].set_xscale("log")
    ax[1].plot(np.linspace(0, 1, 50), np.sin(np.linspace(0, 6, 50)), ls="--", label="a variant")
    ax[1].set_title("δ(t)", fontsize=10)
    fig.legend(loc="lower center", frameon=False)
    fig.tight_layout()
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba()).copy()


def test_a_canvas_figure_has_the_pixels_of_a_pyplot_figure():
    """What the integrators page drew through pyplot it draws on canvas.new_figure: the same pixels."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # the comparison only: pyplot is what the page used to draw with
    fig = plt.figure(figsize=(6.0, 3.0), dpi=100)
    try:
        want = _drawn(fig)
    finally:
        plt.close(fig)
    got = _drawn(canvas.new_figure((6.0, 3.0), dpi=100))
    assert got.shape == want.shape and np.array_equal(got, want)


@pytest.mark.parametrize("palette", [True, False])
def test_a_save_that_fails_midway_leaves_the_old_png_and_no_temporary(tmp_path, monkeypatch, palette):
    fig = canvas.new_figure((2.0, 1.0), dpi=50)
    fig.subplots().plot([0, 1], [1, 0])
    path = tmp_path / "a.png"
    canvas.save_png(fig, path, palette=palette)
    old = path.read_bytes()
    assert Image.open(path).size == (100, 50)

    def half_then_fail(self, fp, *args, **kwargs):   # a full disk, half-way through the file
        Path(fp).write_bytes(old[: len(old) // 2])
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(Image.Image, "save", half_then_fail)
    monkeypatch.setattr(type(fig), "savefig", lambda self, fp, **kw: half_then_fail(None, fp))
    with pytest.raises(OSError, match="No space left on device") as err:
        canvas.save_png(fig, path, palette=palette)
    assert err.value.filename == str(path)                   # said with the file rbcheck was writing
    assert path.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png"]
