"""The storyteller with emotions (The Boy Who Cried Wolf, espeak-ng): its figures are those of the same story
without its emotion tags; ``environment.csv`` and ``music.wav`` are written, the music in ``narration.wav`` is
exactly ``music.wav`` at least 12 dB under the speech, each piece's tempo as librosa measures it from
``music.wav`` is in its valence's range, and a change of piece is a one-second linear cross-fade. The library's
pieces each have a beat librosa reads at their own tempo."""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest
import soundfile

from agentsim.expression.library import BY_NAME, PIECES, looped, rendered
from agentsim.media.audio import run_track
from scenarios.storytelling import run as story_run
from scenarios.storytelling.markup import parse_story, read_story
from scenarios.storytelling.telling import DEFAULT_DELIVERY, make_voice, tell

pytestmark = pytest.mark.system

RANGES = {"positive": (120.0, 1e9), "neutral": (90.0, 110.0), "negative": (0.0, 70.0)}


def tempo(samples: np.ndarray, rate: int) -> float:
    import librosa

    return float(librosa.feature.tempo(y=np.asarray(samples, np.float32), sr=rate)[0])


def sounding_rms(samples: np.ndarray, rate: int) -> float:
    """RMS of the 50 ms frames within 30 dB of the loudest (the test's own measure)."""
    hop = rate // 20
    frames = samples[:len(samples) // hop * hop].reshape(-1, hop).astype(float)
    power = (frames ** 2).mean(axis=1)
    return float(np.sqrt(power[power > power.max() * 1e-3].mean()))


@pytest.fixture(scope="module")
def told(tmp_path_factory):
    out = tmp_path_factory.mktemp("wolf")
    voice = make_voice("espeak")
    path = story_run.STORIES_DIR / "the_boy_who_cried_wolf.story"
    story = read_story(path)
    telling = tell(story, "best", DEFAULT_DELIVERY, seed=0, voice=voice)
    story_run.write_outputs(telling, out, fps=30, plots=False)
    plain = parse_story(re.sub(r"\[emotion:[^\]]*\]", "", path.read_text()), name=str(path))
    return out, telling, tell(plain, "best", DEFAULT_DELIVERY, seed=0, voice=voice)


def test_the_figures_are_those_of_the_story_without_emotions(told):
    out, telling, plain = told
    m, p = telling.metrics(), plain.metrics()
    assert m["gestures"] == p["gestures"] == 78 and m["missed"] == p["missed"] == 0
    assert m["sync_error_ms"] == p["sync_error_ms"]
    assert np.array_equal(telling.passed, plain.passed)
    with open(out / "environment.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows[0]["emotion"] == "none" and rows[-1]["emotion"] == "none" and len(rows) == 12


def test_the_music_under_the_speech(told):
    out, telling, _ = told
    music, rate = soundfile.read(out / "music.wav")
    narration, rate_n = soundfile.read(out / "narration.wav")
    speech = run_track(telling.recording).samples  # the speech alone, as the listener heard it
    assert rate == rate_n == 22050 and len(narration) == len(music) >= len(speech)
    speech = np.pad(speech, (0, len(narration) - len(speech)))
    # the narration is the speech plus exactly music.wav (each rounded to 16 bits)
    assert np.abs(narration - np.clip(speech + music, -1, 1)).max() <= 2.5 / 32768
    under = 20 * np.log10(sounding_rms(speech, rate) / sounding_rms(music, rate))
    print(f"music {under:.1f} dB under the speech")
    assert under >= 12.0
    with open(out / "environment.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    spans, measured = [], {}
    for row in rows:
        if spans and spans[-1][2] == row["music"]:
            continue
        if spans:
            spans[-1][1] = float(row["time"])
        spans.append([float(row["time"]), None, row["music"], row["valence"]])
    spans[-1][1] = len(music) / rate
    for start, stop, name, valence in spans:
        if name and stop - start >= 8.0:  # long enough to measure, from after its cross-fade
            bpm = measured[f"{name}@{start:.1f}"] = tempo(music[int((start + 1.2) * rate):int(stop * rate)], rate)
            assert RANGES[valence][0] <= bpm <= RANGES[valence][1], (name, bpm)
    print(measured)
    assert {v for _, _, _, v in spans if v != "none"} == set(RANGES) and len(measured) >= 3
    # each change from one piece to another: the old piece fades out and the new one in, linearly over 1 s
    changes = [(a, b) for a, b in zip(spans, spans[1:]) if a[2] and b[2]]
    assert changes
    for (old_start, t, old, _), (_, _, new, _) in changes:
        i, n = round(t * rate), rate
        first = looped(BY_NAME[old], rate, i - round(old_start * rate) + n)[-n:]
        second = looped(BY_NAME[new], rate, n)
        ramp = np.arange(n) / n
        basis = np.column_stack([(1 - ramp) * first, ramp * second])
        gains, *_ = np.linalg.lstsq(basis, music[i:i + n], rcond=None)
        residual = music[i:i + n] - basis @ gains
        assert gains.min() > 0 and np.sqrt((residual ** 2).mean()) < 0.02 * np.sqrt((music[i:i + n] ** 2).mean())


def test_every_piece_has_the_beat_of_its_tempo():
    for piece in PIECES:
        samples = rendered(piece, 22050)
        bpm = tempo(looped(piece, 22050, int(24 * 22050)), 22050)
        print(piece.name, piece.bpm, round(bpm, 1))
        assert len(samples) and abs(bpm / piece.bpm - 1) < 0.05
        assert RANGES[piece.valence][0] <= piece.bpm <= RANGES[piece.valence][1]
    assert sorted(p.valence for p in PIECES) == ["negative"] * 3 + ["neutral"] * 3 + ["positive"] * 3
