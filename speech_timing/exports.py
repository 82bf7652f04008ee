"""Exports a linguist can open in Praat: the audio as WAV and the timeline as a TextGrid."""

from __future__ import annotations

from pathlib import Path

from agentsim.errors import AgentsimError
from speech_timing.backend import Utterance


def write_wav(path: str | Path, utterance: Utterance) -> Path:
    """Write the utterance's audio (16-bit PCM WAV at its sample rate)."""
    import soundfile

    if utterance.audio is None:
        raise AgentsimError(f"the {utterance.backend or 'chosen'} backend makes no sound: use --tts espeak")
    from agentsim.written import written

    path = Path(path)
    with written(path) as tmp:
        soundfile.write(str(tmp), utterance.audio, utterance.sample_rate, subtype="PCM_16", format="WAV")
    return path


def write_textgrid(path: str | Path, utterance: Utterance, offset: float = 0.0) -> Path:
    """Write the timeline as a Praat TextGrid: tiers ``words`` and ``phones`` (intervals), ``marks`` (points).

    ``offset`` (seconds) shifts every time, e.g. to place the speech where it started in a longer recording.
    """
    from praatio import textgrid
    from praatio.utilities.constants import Interval, Point

    end = offset + utterance.duration

    def intervals(items):
        out, last = [], offset
        for label, a, b in items:
            a, b = max(offset + a, last), min(offset + b, end)
            if b - a > 1e-6 and label:
                out.append(Interval(a, b, label))
                last = b
        return out

    grid = textgrid.Textgrid(offset, end)
    grid.addTier(textgrid.IntervalTier("words", intervals((w.text, w.start, w.end) for w in utterance.words),
                                       offset, end))
    grid.addTier(textgrid.IntervalTier(
        "phones", intervals((p.symbol + ("ˈ" if p.stressed else ""), p.start, p.end) for p in utterance.phonemes),
        offset, end))
    grid.addTier(textgrid.PointTier("marks", [Point(offset + m.time, m.name) for m in utterance.marks], offset, end))
    from agentsim.written import written

    path = Path(path)
    with written(path) as tmp:
        grid.save(str(tmp), format="long_textgrid", includeBlankSpaces=True)
    return path
