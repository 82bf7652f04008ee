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


def test_keys_are_the_hash_of_the_identity_and_the_speech_as_json(tmp_path):
    """A key is the SHA-256 of the JSON of the backend's identity and the speech (keys sorted), however it is
    put together; an identity that changes (another rate) gives other keys from then on."""
    import hashlib
    import json
    from dataclasses import asdict

    from scenarios.storytelling.voice import WholeSpeechCache, _identity
    from speech_timing.backend import Prosody, SpeechText

    backend = EspeakBackend()
    kept = WholeSpeechCache(backend, cache_dir=tmp_path)

    def expected(fields: dict) -> str:
        blob = json.dumps({"backend": _identity(backend), **fields}, sort_keys=True, ensure_ascii=False)
        return hashlib.sha256(blob.encode("utf-8")).hexdigest()[:32]

    speeches = [SpeechText("Le héron \\ \"dit\"."), SpeechText("Wait.", marks=[(0, "m1")]),
                SpeechText("Slowly now.", rate=0.8),
                SpeechText("Now.", prosody=[Prosody("break", 0, 0, (("time", "300ms"),))])]
    for _ in range(2):  # (the identity's JSON once written, then kept)
        assert kept.key(speeches[0].text) == expected({"text": speeches[0].text})
        for speech in speeches[1:]:
            fields = {"text": speech.text, "marks": [list(m) for m in speech.marks], "rate": speech.rate,
                      "prosody": [asdict(p) for p in speech.prosody]}
            assert kept.speech_key(speech) == expected(fields)
    before = kept.key("Wait.")
    backend.rate = backend.rate + 20
    assert kept.key("Wait.") == expected({"text": "Wait."}) != before


def test_an_entry_whose_samples_are_cut_short_is_said_again(tmp_path):
    from scenarios.storytelling.voice import WholeSpeechCache
    from speech_timing.backend import SpeechText

    speech = SpeechText("The heron waits by the water.")
    said = WholeSpeechCache(EspeakBackend(), cache_dir=tmp_path).synthesize(speech)
    (samples,) = tmp_path.glob("*.npy")
    samples.write_bytes(samples.read_bytes()[:-2])
    again = WholeSpeechCache(EspeakBackend(), cache_dir=tmp_path)
    read = again.synthesize(speech)
    assert (again.hits, again.misses) == (0, 1) and np.array_equal(np.asarray(read.audio), np.asarray(said.audio))
