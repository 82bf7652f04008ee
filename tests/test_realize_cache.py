"""``agentsim realize`` keeps espeak-ng's speech in the speech cache: a speech realized again is read from it, as
it was said, and ``--no-cache`` synthesises again and writes no cache."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from agentsim.cli import main as cli_main
from speech_timing.espeak import EspeakBackend

DOCUMENT = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1"><speech id="s1"><text>The cache keeps '
            'what the <sync id="m"/>heron said today.</text></speech>'
            '<gesture id="g1" lexeme="BEAT" stroke="s1:m"/></bml>')


def test_a_speech_realized_again_is_read_from_the_cache(tmp_path, monkeypatch, capsys):
    calls = []
    said = EspeakBackend.synthesize

    def counted(self, speech):
        calls.append(speech.text)
        return said(self, speech)

    monkeypatch.setattr(EspeakBackend, "synthesize", counted)
    document = tmp_path / "heron.xml"
    document.write_text(DOCUMENT, encoding="utf-8")

    def realize(cache: Path, name: str, *extra: str) -> tuple[str, bytes, int]:
        monkeypatch.setenv("AGENTSIM_CACHE", str(cache))
        calls.clear()
        wav = tmp_path / f"{name}.wav"
        assert cli_main(["realize", str(document), "--tts", "espeak", "--wav", str(wav), *extra]) == 0
        return capsys.readouterr().out, wav.read_bytes(), len(calls)

    cache = tmp_path / "cache"
    first = realize(cache, "first")
    kept = sorted(p.suffix for p in cache.iterdir())
    again = realize(cache, "again")
    fresh = realize(tmp_path / "none", "fresh", "--no-cache")
    assert (first[2], again[2], fresh[2]) == (1, 0, 1)  # the second run did not synthesise
    assert kept == [".json", ".npy"]
    assert first[:2] == again[:2] == fresh[:2]  # the same feedback and sound, byte for byte
    assert '"stroke"' in first[0] and not (tmp_path / "none").exists()


def test_a_plain_speech_shares_the_storytellers_entry(tmp_path):
    """A speech without marks, prosody or another rate is kept under the storyteller's key of its text, and
    read back as the storyteller reads it."""
    from scenarios.storytelling.voice import CachedBackend, WholeSpeechCache
    from speech_timing.backend import SpeechText

    text = 'Le héron dit "bonjour" \\ aujourd\'hui.'
    kept = WholeSpeechCache(EspeakBackend(), cache_dir=tmp_path)
    said = kept.synthesize(SpeechText(text))
    storyteller = CachedBackend(EspeakBackend(), cache_dir=tmp_path)
    assert kept.key(text) == storyteller.key(text)
    again = storyteller.utterance(text)
    assert (storyteller.hits, storyteller.misses) == (1, 0)
    assert again.words == said.words and again.phonemes == said.phonemes and again.duration == said.duration
    read = WholeSpeechCache(EspeakBackend(), cache_dir=tmp_path).synthesize(SpeechText(text)).audio
    assert read.held_bytes == 0  # its samples are read when first asked for, then held
    assert np.array_equal(np.asarray(read), np.asarray(said.audio)) and read.held_bytes == 2 * len(said.audio)
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".json", ".npy"]


def test_samples_written_anew_meanwhile_are_not_read(tmp_path):
    """A cache file written anew after its entry was read (by another process) is not paired with the timeline
    read before: the run stops with one line saying so."""
    from agentsim.errors import AgentsimError
    from scenarios.storytelling.voice import WholeSpeechCache
    from speech_timing.backend import SpeechText

    speech = SpeechText("The heron waits by the water.")
    WholeSpeechCache(EspeakBackend(), cache_dir=tmp_path).synthesize(speech)
    read = WholeSpeechCache(EspeakBackend(), cache_dir=tmp_path).synthesize(speech).audio
    (samples,) = tmp_path.glob("*.npy")
    fresh = samples.with_suffix(".new")
    fresh.write_bytes(samples.read_bytes())
    fresh.replace(samples)  # the same bytes in another file, put in its place as the cache writes one
    with pytest.raises(AgentsimError, match="written anew while this run used it"):
        read[0:10]
