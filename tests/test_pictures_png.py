"""The PNG pictures :func:`agentsim.written.save_figure` writes: the pixels matplotlib draws (read back with
Pillow), its metadata, and the letters drawn unhinted unless the program chose its own hinting."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from agentsim.written import TEXT_HINTING, png_bytes, save_figure


def _figure() -> Figure:
    fig = Figure(figsize=(3, 2), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.plot([0, 1, 2], [1, 3, 2])
    ax.set_title("stroke 1 of 4")
    return fig


def _pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path))


def test_a_picture_has_the_pixels_matplotlib_draws_unhinted_and_matplotlib_s_metadata(tmp_path):
    path = save_figure(_figure(), tmp_path / "ours.png", dpi=120)
    with matplotlib.rc_context({"text.hinting": TEXT_HINTING}):  # matplotlib's own writer (Pillow's filters)
        _figure().savefig(tmp_path / "pillow.png", dpi=120)
    ours = _pixels(path)
    assert ours.shape == (240, 360, 4) and np.array_equal(ours, _pixels(tmp_path / "pillow.png"))
    info = Image.open(path).info
    assert info["Software"] == f"Matplotlib version{matplotlib.__version__}, https://matplotlib.org/"
    assert info["dpi"] == Image.open(tmp_path / "pillow.png").info["dpi"] == pytest.approx((120, 120), abs=0.02)
    _figure().savefig(tmp_path / "hinted.png", dpi=120)  # the default hinting: other pixels in the letters
    assert not np.array_equal(ours, _pixels(tmp_path / "hinted.png"))


def test_a_program_s_own_hinting_is_kept(tmp_path):
    with matplotlib.rc_context({"text.hinting": "native"}):
        save_figure(_figure(), tmp_path / "ours.png", dpi=120)
        _figure().savefig(tmp_path / "pillow.png", dpi=120)
    assert np.array_equal(_pixels(tmp_path / "ours.png"), _pixels(tmp_path / "pillow.png"))


def test_png_bytes_takes_rgba_pixels_alone():
    with pytest.raises(ValueError, match="RGBA pixels, not 3 channels"):
        png_bytes(np.zeros((2, 2, 3), np.uint8), 100)
