"""The one default speech backend, and backends by name: what ``Realizer()``, every command and the live
service speak with when nothing is asked for."""

from __future__ import annotations

import warnings

from speech_timing.backend import TTSBackend

#: Speech backends by name (``--tts NAME``).
NAMES = ("espeak", "festival", "piper", "builtin")


def named(name: str, voice: str | None = None) -> TTSBackend:
    """The backend ``name`` (one of :data:`NAMES`) speaking with ``voice`` (None: the backend's default;
    the built-in one has none); espeak-ng, Festival and Piper raise
    :class:`~agentsim.errors.SpeechBackendUnavailable`, saying what to install, when they cannot run here
    (Piper: :class:`~agentsim.errors.SpeechExtraMissing`, naming its extra), and ValueError (Piper:
    :class:`~agentsim.errors.UsageError`) for a voice they do not have."""
    if name == "espeak":
        from speech_timing.espeak import EspeakBackend

        return EspeakBackend() if voice is None else EspeakBackend(voice=voice)
    if name == "festival":
        from speech_timing.festival import FestivalBackend

        return FestivalBackend(voice=voice)
    if name == "piper":
        from speech_timing.piper import PiperBackend

        return PiperBackend() if voice is None else PiperBackend(voice=voice)
    if name == "builtin":
        from speech_timing.builtin import BuiltinBackend

        if voice is not None:
            raise ValueError("the built-in backend has no voices: --voice needs --tts espeak, festival or piper")
        return BuiltinBackend()
    raise ValueError(f"no speech backend {name!r}; there are {', '.join(NAMES)}")


def default_backend() -> TTSBackend:
    """espeak-ng when its library is here, else the deterministic built-in timing model, with a
    :class:`UserWarning` that says what to install for speech with sound."""
    from agentsim.errors import SpeechBackendUnavailable

    try:
        return named("espeak")
    except SpeechBackendUnavailable as exc:
        warnings.warn(f"speech is timed by the built-in model, without sound: {exc}", UserWarning, stacklevel=2)
        return named("builtin")


def default_name() -> str:
    """The name of :func:`default_backend`'s choice here (with its warning when it is the built-in one)."""
    return default_backend().name
