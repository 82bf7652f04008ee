"""``agentsim realize`` keeps espeak-ng's speech in the speech cache: a speech realized again is read from it, as
it was said, and ``--no-cache`` synthesises again and writes no cache."""

from __future__ import annotations

from pathlib import Path

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
