"""How much speech one document sent to ``agentsim serve`` may ask for: :class:`Limits` (a module of its own,
light to import: the command line's help shows its defaults)."""

from __future__ import annotations

import dataclasses
import math

from agentsim.errors import UsageError

#: How many characters of speech text a speech may have, and a block in all its speeches (see :class:`Limits`).
SPEECH_CHARACTERS = 10_000
BLOCK_CHARACTERS = 40_000
#: How many seconds a speech may last, and a block's speeches together: estimated from their characters
#: before they are synthesised, and their audio's length once they are.
SPEECH_SECONDS = 600.0
BLOCK_SECONDS = 1800.0
#: Characters of speech a second at 175 words a minute (English averages some 6 characters a word, with its
#: space); the estimate scales with the backend's rate.
CHARACTERS_PER_SECOND = 17.5


@dataclasses.dataclass(frozen=True)
class Limits:
    """How much speech one document may ask for (``agentsim serve --max-speech-chars ...``): characters of
    text and seconds of speech per speech and per block. A block past any of them is refused whole, with
    one warning to its sender, before its speech costs anything (seconds are estimated from the characters
    at the backend's rate, and checked again against the audio once synthesised)."""

    speech_characters: int = SPEECH_CHARACTERS
    speech_seconds: float = SPEECH_SECONDS
    block_characters: int = BLOCK_CHARACTERS
    block_seconds: float = BLOCK_SECONDS

    def __post_init__(self) -> None:
        for name in ("speech_characters", "speech_seconds", "block_characters", "block_seconds"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise UsageError(f"--max-{name.replace('_characters', '-chars').replace('_', '-')} must be a "
                                 f"positive number, got {value!r}")

    def estimate(self, text: str, rate: float) -> float:
        """The seconds ``text`` is expected to last at ``rate`` words a minute."""
        return len(text) / (CHARACTERS_PER_SECOND * rate / 175.0)

    def check(self, speeches: list[tuple[str, str]], rate: float, durations: dict[str, float] | None = None) \
            -> str | None:
        """Why a block whose speeches are ``(id, text)`` is refused (None: it is not); ``durations``: the
        seconds each speech's audio lasts, once synthesised (else they are estimated)."""
        total_characters, total_seconds = 0, 0.0
        for speech_id, text in speeches:
            seconds = durations[speech_id] if durations is not None else self.estimate(text, rate)
            what = "lasts" if durations is not None else "would last some"
            if len(text) > self.speech_characters:
                return (f"speech {speech_id} has {len(text):,} characters, more than the {self.speech_characters:,} "
                        f"a speech may have here (--max-speech-chars)")
            if seconds > self.speech_seconds:
                return (f"speech {speech_id} {what} {seconds:,.0f} s, longer than the {self.speech_seconds:g} s a "
                        f"speech may last here (--max-speech-seconds)")
            total_characters += len(text)
            total_seconds += seconds
        if total_characters > self.block_characters:
            return (f"its speeches have {total_characters:,} characters, more than the {self.block_characters:,} a "
                    f"block may have here (--max-block-chars)")
        if total_seconds > self.block_seconds:
            return (f"its speeches {'last' if durations is not None else 'would last some'} {total_seconds:,.0f} s, "
                    f"longer than the {self.block_seconds:g} s a block's speech may last here (--max-block-seconds)")
        return None
