"""Fixtures the tests share: the BML 1.0 examples and a rendered ensemble with its true beats."""

from __future__ import annotations

from pathlib import Path

import pytest

from helpers import EXAMPLES, cached_render


@pytest.fixture
def examples() -> Path:
    assert EXAMPLES.is_dir(), f"the BML examples are expected in {EXAMPLES}"
    return EXAMPLES


@pytest.fixture(scope="module")
def ensemble(tmp_path_factory):
    """20 bars at 120 BPM speeding up 10 % over bars 4-12, with rubato: audio file and true beats."""
    import numpy as np
    import soundfile

    from agentsim.music.ensemble import render_ensemble, write_beats

    audio, sr, beats = cached_render(render_ensemble, bpm=120, meter="4/4", bars=20, ramp=(4, 8, 0.10), rubato=0.02,
                                     seed=11, sample_rate=22050)
    folder = tmp_path_factory.mktemp("ensemble")
    soundfile.write(folder / "ensemble.wav", audio, sr)
    write_beats(folder / "beats.txt", beats)
    return folder, audio, sr, np.asarray(beats)
