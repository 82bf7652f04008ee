"""Fixtures the tests share: the BML 1.0 examples, a rendered ensemble with its true beats, and a speech cache of
the test run's own."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from helpers import EXAMPLES, cached_render


@pytest.fixture(scope="session", autouse=True)
def speech_cache(tmp_path_factory) -> Path:
    """The speech cache (``$AGENTSIM_CACHE``) of this test run, in and below its process: a new folder, so that
    no test reads or fills the user's (``~/.cache/agentsim/tts``)."""
    folder = tmp_path_factory.mktemp("speech-cache")
    before = os.environ.get("AGENTSIM_CACHE")
    os.environ["AGENTSIM_CACHE"] = str(folder)
    yield folder
    if before is None:
        os.environ.pop("AGENTSIM_CACHE", None)
    else:
        os.environ["AGENTSIM_CACHE"] = before


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
