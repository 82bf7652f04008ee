"""The conductor's ears: the audio beat anticipator, plus a recording, a loudness meter and beat onsets.

:class:`Ears` is an :class:`~anticipators.audio.AudioBeatAnticipator` (pegs ``beat1``, ``beat2``, ... of the
beats it predicts, numbered from ``origin``) that also keeps what it heard (for ``ensemble.wav`` and the
loudness meter) and reports every onset its tracker accepted as a beat, numbered like the pegs, to its
listeners. Whatever the conductor knows about the ensemble comes through here.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from anticipators.audio import AudioBeatAnticipator


class Ears(AudioBeatAnticipator):
    """A beat anticipator that records, meters and reports observed beats.

    Parameters are those of :class:`~anticipators.audio.AudioBeatAnticipator`, plus ``record`` (keep the
    audio heard).

    Attributes
    ----------
    observed : dict
        Beat number -> onset time (s) of the beats the tracker heard (accepted onsets).
    confidence_log : list of (float, float)
        (time heard up to, tracker confidence) after every block.
    """

    def __init__(self, anticipator_id: str = "band", record: bool = True, **kwargs):
        super().__init__(anticipator_id, **kwargs)
        self.record = record
        self.blocks: list[np.ndarray] = []
        self._block_end: list[float] = []
        self._block_ms: list[float] = []
        self._heard = 0
        self.observed: dict[int, float] = {}
        self._last_observed = -np.inf
        self.confidence_log: list[tuple[float, float]] = []
        self._listeners: list[Callable[[int, float], None]] = []
        self._block_listeners: list[Callable[[], None]] = []

    def on_beat(self, listener: Callable[[int, float], None]) -> None:
        """Call ``listener(beat_number, onset_time)`` for each beat onset the tracker accepts."""
        self._listeners.append(listener)

    def on_block(self, listener: Callable[[], None]) -> None:
        """Call ``listener()`` after every block heard."""
        self._block_listeners.append(listener)

    def push(self, block: np.ndarray) -> None:
        block = np.asarray(block, np.float32).reshape(-1)
        super().push(block)
        self._heard += block.size
        if self.record:
            self.blocks.append(block)
        if block.size:
            self._block_end.append(self.start + self._heard / self.sample_rate)
            self._block_ms.append(float(np.mean(np.square(block, dtype=np.float64))))
        self.confidence_log.append((self.now, self.confidence))
        self._collect_beats()
        for listener in self._block_listeners:
            listener()

    def _collect_beats(self) -> None:
        fresh = [self.start + z for z in self.tracker.beats_observed if self.start + z > self._last_observed + 1e-9]
        if not fresh or len(self.beats) < 2:
            return
        numbers = np.array(sorted(self.beats))
        times = np.array([self.beats[k] for k in numbers])
        period = float(np.median(np.diff(times))) if times.size > 1 else 0.5
        for z in fresh:
            self._last_observed = z
            i = int(np.argmin(np.abs(times - z)))
            if abs(times[i] - z) > 0.35 * period:
                continue
            beat = int(numbers[i])
            if beat in self.observed:
                continue
            self.observed[beat] = z
            for listener in self._listeners:
                listener(beat, z)

    def recording(self) -> np.ndarray:
        """Everything heard so far (mono float32)."""
        return np.concatenate(self.blocks) if self.blocks else np.zeros(0, np.float32)

    def level_db(self, t0: float, t1: float) -> float:
        """RMS level (dBFS) of the audio heard between ``t0`` and ``t1`` (-inf if silent or not heard)."""
        if not self._block_end:
            return float("-inf")
        ends = np.asarray(self._block_end)
        ms = np.asarray(self._block_ms)
        keep = (ends > t0) & (ends <= t1 + 1e-9)
        if not keep.any():
            return float("-inf")
        value = float(ms[keep].mean())
        return 10.0 * np.log10(value) if value > 0 else float("-inf")
