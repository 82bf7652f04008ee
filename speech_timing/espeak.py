"""espeak-ng backend: synthesised speech with word, phoneme and mark timing from the synthesiser's events.

The C library ``libespeak-ng.so.1`` is bound with ctypes and run in synchronous mode. Each text is sent
as SSML with a ``<mark/>`` element at every sync mark. espeak-ng reports WORD, PHONEME, MARK and SENTENCE
events at the sample where they occur in the audio it returns, so every time in the resulting
:class:`~speech_timing.backend.Utterance` is a position in that audio, not an estimate. Word onsets
agree with energy onsets in the audio within about 2 ms.

Observed behaviour of espeak-ng 1.51 that the code relies on or works around:

* ``text_position`` is a 1-based position in *characters* (code points, not UTF-8 bytes) of the SSML
  input, markup included. An entity such as ``&amp;`` is reported at its last character. After a full
  stop, or on a `` - `` before a word, the word is sometimes reported a character or two early.
* A written word that espeak expands (``1234``, ``AT&T``, ``Dr.``) gives several WORD events, all
  inside that word; they are merged into one :class:`~speech_timing.backend.Word`. Word pairs that
  espeak's dictionary pronounces as one word ("in the", "of a") give one WORD event for both; their
  phonemes are split between the two written words by each word's own transcription.
* WORD and MARK events come before the silent gap espeak puts in front of a word; the first PHONEME
  event, where the sound starts, follows 0-13 ms later and about 50 ms later before a voiceless stop.
  A MARK in front of the second word of a dictionary pair comes only at the word after the pair.
  Words therefore start at their first phoneme, and a mark gets the onset of the word it stands before.
* Phoneme names are espeak mnemonics by default (``h @ l oU``, pauses ``_`` and ``_:``) and IPA with
  the IPA option used here (``h ə l əʊ``, pauses as empty names). Neither form carries stress marks.
  Stress is read from ``espeak_TextToPhonemes`` on the same text: with a phoneme separator, it writes
  ``ˈ`` (primary) or ``ˌ`` (secondary) in front of the stressed vowel. Its phoneme sequence is aligned
  with the PHONEME events and ``Phoneme.stressed`` marks primary stress.
* The PHONEME event of a vowel after a nasal or liquid comes after the vowel's onset glide, which
  espeak synthesises as part of the vowel, so such a consonant's interval includes that glide.
* The library is initialised once per process: terminating and initialising again hangs the next
  synthesis. One process-wide engine, guarded by a lock, serves every :class:`EspeakBackend`.
* espeak-ng keeps state between syntheses (the phase of its pitch flutter, its gain control), so the
  same text spoken again in one process gives the same words and phonemes but times that differ by
  up to about 20 ms, and different audio samples. The first synthesis in a fresh process is exactly
  reproducible: every synthesis here is one, in a fork of an engine that has never spoken
  (:class:`_Pristine`), so the same text gives the same samples and times in every process, whatever
  was said before.

Prosody spans (:class:`~speech_timing.backend.Prosody`) are sent as espeak-ng's SSML elements, with
the values it reads (``docs/markup.md`` and ``ssml.c`` of espeak-ng; others are left out, see
:func:`_prosody_markup`). Measured with espeak-ng 1.51 at 175 words per minute:

* ``<break time=.../>`` widens the gap between its two words by the time given, within 0.05 s at 120
  to 420 words per minute (500 ms: 0.46-0.51 s). It ends a clause, so the word before it gets 0-50 ms
  longer (up to 0.11 s at 120 words per minute). Strengths: none, x-weak and weak add nothing there;
  medium (also a break without attributes) about 0.15 s, strong 0.3 s, x-strong 0.6 s.
* ``<prosody rate=...>``: the enclosed words last 1.54-1.67 times as long at x-slow (espeak: 60 % of the
  voice's rate), 1.19-1.25 at slow (80 %), 0.81-0.85 at fast (125 %), 0.63-0.71 at x-fast (160 %);
  percentages and factors likewise, within espeak's 80 to 450 words per minute. The words around keep
  their times.
* ``pitch`` and ``volume`` change the enclosed words' length by 2 % at most and no word moves by more
  than 30 ms; ``emphasis`` (moderate and up) makes the words 24-42 % longer, and louder.
* ``say-as interpret-as="characters"`` over a written word gives one WORD event for the whole span, so
  the spelled word stays one :class:`~speech_timing.backend.Word` with all its letters' phonemes.
* An SSML element is set apart from the text around it as if by a space, so an element inside a written
  word would split it in two: span edges inside a word are moved to the word's edges.
"""

from __future__ import annotations

import bisect
import ctypes
import difflib
import functools
import io
import itertools
import mmap
import os
import re
import threading
from dataclasses import dataclass, field
from xml.sax.saxutils import escape

# numpy is imported where audio is made: loading the backend does without it
from speech_timing.backend import (BREAK_STRENGTHS, Mark, Phoneme, Prosody, SpeechText, Spoken, Utterance, Word,
                                     check_prosody, nest_spans, parse_number, parse_time)
from agentsim.errors import SpeechBackendUnavailable

__all__ = ["EspeakBackend", "INSTALL_HINT"]

LIBRARY_NAME = "libespeak-ng.so.1"
INSTALL_HINT = "apt-get install libespeak-ng1 espeak-ng-data"

# Constants from espeak-ng/speak_lib.h.
_AUDIO_OUTPUT_SYNCHRONOUS = 2
_INITIALIZE_PHONEME_EVENTS = 0x0001
_INITIALIZE_PHONEME_IPA = 0x0002
_INITIALIZE_DONT_EXIT = 0x8000
_CHARS_UTF8 = 1
_SSML = 0x10
_POS_CHARACTER = 1
_PARAMETER_RATE = 1
_EE_OK = 0
_PHONEMES_IPA = 0x02
_RATE_MINIMUM, _RATE_MAXIMUM = 80, 450

_EVENT_LIST_TERMINATED = 0
_EVENT_WORD = 1
_EVENT_SENTENCE = 2
_EVENT_MARK = 3
_EVENT_PHONEME = 7

_PHONEME_SEPARATOR = "|"
_PRIMARY_STRESS = "ˈ"
_SECONDARY_STRESS = "ˌ"
_PHONEME_NAME_BYTES = 8


class _EventId(ctypes.Union):
    _fields_ = [
        ("number", ctypes.c_int),
        ("name", ctypes.c_char_p),
        ("string", ctypes.c_char * _PHONEME_NAME_BYTES),
    ]


class _Event(ctypes.Structure):
    """``espeak_EVENT``."""

    _fields_ = [
        ("type", ctypes.c_int),
        ("unique_identifier", ctypes.c_uint),
        ("text_position", ctypes.c_int),
        ("length", ctypes.c_int),
        ("audio_position", ctypes.c_int),
        ("sample", ctypes.c_int),
        ("user_data", ctypes.c_void_p),
        ("id", _EventId),
    ]


_SynthCallback = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int,
                                  ctypes.POINTER(_Event))


@dataclass(frozen=True)
class _RawEvent:
    """One espeak event, copied out of the library's memory.

    ``name`` is the mark name for MARK events, the phoneme name for PHONEME events and empty otherwise.
    """

    kind: int
    text_position: int
    length: int
    sample: int
    name: str = ""


def _decode_event(event: _Event) -> _RawEvent:
    """Copy the fields of ``event`` that are used here; the library reuses its memory."""
    name = ""
    if event.type == _EVENT_MARK and event.id.name:
        name = event.id.name.decode("utf-8", "replace")
    elif event.type == _EVENT_PHONEME:
        # char[8], NUL-terminated only when the name is shorter than 8 bytes; a multi-byte
        # character cut off at the end is dropped.
        raw = ctypes.string_at(ctypes.addressof(event.id), _PHONEME_NAME_BYTES).split(b"\0", 1)[0]
        name = raw.decode("utf-8", "ignore")
    return _RawEvent(event.type, event.text_position, event.length, event.sample, name)


def _load_library(name: str = LIBRARY_NAME) -> ctypes.CDLL:
    """Load the espeak-ng shared library and declare the functions used here.

    Raises
    ------
    SpeechBackendUnavailable
        If the library cannot be loaded or lacks a function used here.
    """
    try:
        lib = ctypes.CDLL(name)
    except OSError as exc:
        raise SpeechBackendUnavailable(
            f"the espeak-ng library {name} could not be loaded ({exc}); install it with: {INSTALL_HINT}"
        ) from exc
    try:
        lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
        lib.espeak_Initialize.restype = ctypes.c_int
        lib.espeak_SetSynthCallback.argtypes = [_SynthCallback]
        lib.espeak_SetSynthCallback.restype = None
        lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
        lib.espeak_SetVoiceByName.restype = ctypes.c_int
        lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
        lib.espeak_SetParameter.restype = ctypes.c_int
        lib.espeak_Synth.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_uint, ctypes.c_int,
                                     ctypes.c_uint, ctypes.c_uint, ctypes.POINTER(ctypes.c_uint),
                                     ctypes.c_void_p]
        lib.espeak_Synth.restype = ctypes.c_int
        lib.espeak_TextToPhonemes.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_int, ctypes.c_int]
        lib.espeak_TextToPhonemes.restype = ctypes.c_char_p
    except AttributeError as exc:  # a library without the functions used here
        raise SpeechBackendUnavailable(
            f"{name} lacks a function of the espeak-ng API ({exc}); install it with: {INSTALL_HINT}"
        ) from exc
    return lib


class _PcmBuffer:
    """The 16-bit samples of one synthesis, appended a chunk at a time into one array that doubles as it
    fills: no list of chunks and no joined copy beside it (a long text's chunks would stay behind in the
    allocator's heap). The array is an anonymous mapping: its untouched end is never in memory, and
    :meth:`to_float` gives its pages back to the system as it converts them."""

    #: Samples converted at a time by :meth:`to_float`.
    BLOCK = 1 << 20

    def __init__(self) -> None:
        self._map: mmap.mmap | None = None
        self.array = None
        self.filled = 0

    def append(self, wav, count: int) -> None:
        """Copy ``count`` samples from the C buffer ``wav``."""
        import numpy as np

        size = 0 if self.array is None else len(self.array)
        if self.filled + count > size:
            size = max(2 * size, self.filled + count, 1 << 16)
            grown_map = mmap.mmap(-1, 2 * size)
            grown = np.frombuffer(grown_map, dtype=np.int16)
            if self.filled:
                grown[:self.filled] = self.array[:self.filled]
            self.array, old = grown, self._map  # the old array let go first: then its mapping can close
            self._map = grown_map
            if old is not None:
                old.close()
        ctypes.memmove(self.array.ctypes.data + 2 * self.filled, wav, 2 * count)
        self.filled += count

    @classmethod
    def read_from(cls, stream, count: int) -> "_PcmBuffer":
        """A buffer of the ``count`` 16-bit samples that come next on ``stream``, read straight into it (no
        bytes object of them beside it). Raises EOFError if the stream ends first."""
        import numpy as np

        buffer = cls()
        if count:
            buffer._map = mmap.mmap(-1, 2 * count)
            view = memoryview(buffer._map)
            done = 0
            while done < 2 * count:
                got = stream.readinto(view[done:done + _RELAY_BLOCK])
                if not got:
                    view.release()
                    raise EOFError("a cut reply")
                done += got
            view.release()
            buffer.array = np.frombuffer(buffer._map, dtype=np.int16)
            buffer.filled = count
        return buffer

    def raw(self) -> memoryview:
        """The samples' bytes, as they are in the buffer (no copy)."""
        return memoryview(self._map)[:2 * self.filled] if self.filled else memoryview(b"")

    def samples(self):
        """The samples appended so far (int16, a view of the buffer: valid until :meth:`to_float`)."""
        import numpy as np

        return self.array[:self.filled] if self.array is not None else np.zeros(0, dtype=np.int16)

    def to_float(self):
        """The samples as float32 in [-1, 1) (divided by 32768), the buffer's pages given back to the system
        as they are converted (so the 16-bit samples and their float32 copy are not held whole at once);
        the buffer is empty afterwards."""
        import numpy as np

        from speech_timing.samples import pcm_to_float

        out = np.empty(self.filled, dtype=np.float32)
        released = 0
        for a in range(0, self.filled, self.BLOCK):
            b = min(a + self.BLOCK, self.filled)
            pcm_to_float(self.array[a:b], out=out[a:b])
            done = (2 * b) // mmap.PAGESIZE * mmap.PAGESIZE
            if done > released:
                self._map.madvise(mmap.MADV_DONTNEED, released, done - released)
                released = done
        self.array, self.filled = None, 0
        if self._map is not None:
            self._map.close()
            self._map = None
        return out


class _Engine:
    """The process-wide espeak-ng instance: initialised once, used under :attr:`lock`."""

    def __init__(self, library: str = LIBRARY_NAME) -> None:
        self.lock = threading.RLock()
        self.library = library
        self._pristine: _Pristine | None = None
        self._lib = _load_library(library)
        options = _INITIALIZE_PHONEME_EVENTS | _INITIALIZE_PHONEME_IPA | _INITIALIZE_DONT_EXIT
        sample_rate = self._lib.espeak_Initialize(_AUDIO_OUTPUT_SYNCHRONOUS, 0, None, options)
        if sample_rate <= 0:
            raise SpeechBackendUnavailable(
                f"espeak-ng could not be initialised (its data files may be missing); "
                f"install it with: {INSTALL_HINT}"
            )
        self.sample_rate = sample_rate
        self._chunks = _PcmBuffer()
        self._events: list[_RawEvent] = []
        #: what was said, by voice and rate (see :meth:`spoken`)
        self._spoken: dict[tuple[str, int], Spoken] = {}
        self._callback_error: BaseException | None = None
        self._callback = _SynthCallback(self._on_synth)  # kept referenced for the library's use
        self._lib.espeak_SetSynthCallback(self._callback)

    def spoken(self, voice: str, rate: int) -> Spoken:
        """What this process's engine said with ``voice`` at ``rate``, kept (the last :data:`REMEMBERED`
        utterances, at most :data:`REMEMBERED_BYTES` of audio): each synthesis is a fresh engine's, so a text
        is said the same every time, and every backend of that voice and rate answers a text said before at
        once (a sweep's points, each with a backend of its own, synthesise a text once per worker)."""
        with self.lock:
            return self._spoken.setdefault((voice, rate), Spoken(REMEMBERED, REMEMBERED_BYTES))

    def _on_synth(self, wav, num_samples: int, events) -> int:
        """Collect one audio chunk and its events; returns 1 (abort) on an error."""
        try:
            if wav and num_samples > 0:
                self._chunks.append(wav, num_samples)
            if events:
                i = 0
                while events[i].type != _EVENT_LIST_TERMINATED:
                    self._events.append(_decode_event(events[i]))
                    i += 1
        except BaseException as exc:  # an exception must not cross into C
            self._callback_error = exc
            return 1
        return 0

    def select(self, voice: str, rate: int) -> None:
        """Select ``voice`` and speaking ``rate`` (words per minute) for what follows."""
        with self.lock:
            if self._lib.espeak_SetVoiceByName(voice.encode("utf-8")) != _EE_OK:
                raise ValueError(f"espeak-ng has no voice named {voice!r}")
            if self._lib.espeak_SetParameter(_PARAMETER_RATE, rate, 0) != _EE_OK:
                raise ValueError(f"espeak-ng refused the rate {rate}")

    def synth(self, ssml: str, voice: str, rate: int) -> tuple[_PcmBuffer, list[_RawEvent]]:
        """Synthesise SSML; return the int16 audio (in its buffer) and the events in the order espeak
        reported them. The synthesis runs in a fork of an engine that has never synthesised
        (:class:`_Pristine`), so that it comes out as the first synthesis of a fresh process does, whatever
        was said before."""
        with self.lock:
            if self._pristine is None or self._pristine.pid != os.getpid():  # a forked copy starts its own
                self._pristine = _Pristine(self.library)
            return self._pristine.synth(ssml, voice, rate)

    def synth_here(self, ssml: str, voice: str, rate: int) -> tuple[_PcmBuffer, list[_RawEvent]]:
        """:meth:`synth` in this process: what it gives depends on what this engine said before."""

        with self.lock:
            self.select(voice, rate)
            self._chunks, self._events, self._callback_error = _PcmBuffer(), [], None
            data = ssml.encode("utf-8")
            status = self._lib.espeak_Synth(data, len(data) + 1, 0, _POS_CHARACTER, 0,
                                            _SSML | _CHARS_UTF8, None, None)
            chunks, events, error = self._chunks, self._events, self._callback_error
            self._chunks, self._events, self._callback_error = _PcmBuffer(), [], None
        if error is not None:
            raise RuntimeError("espeak-ng synthesis callback failed") from error
        if status != _EE_OK:
            raise RuntimeError(f"espeak_Synth failed with status {status}")
        return chunks, events

    def transcribe(self, text: str, voice: str, rate: int) -> list[tuple[str, str]]:
        """IPA phonemes of plain ``text`` with their stress: ``(symbol, "ˈ" | "ˌ" | "")``, pauses left out."""
        return [phoneme for _, phonemes in self.transcribe_clauses(text, voice, rate) for phoneme in phonemes]

    def transcribe_clauses(self, text: str, voice: str, rate: int) -> list[tuple[int, list[tuple[str, str]]]]:
        """:meth:`transcribe` clause by clause, as espeak-ng reads ``text``: for each clause the character
        offset in ``text`` where it ends (before the written word in which espeak-ng stopped reading) and
        its phonemes."""
        mode = _PHONEMES_IPA | (ord(_PHONEME_SEPARATOR) << 8)
        encoded = text.encode("utf-8")
        buffer = ctypes.create_string_buffer(encoded)
        base = ctypes.addressof(buffer)
        pointer = ctypes.c_void_p(base)
        clauses = []
        with self.lock:
            self.select(voice, rate)
            while pointer.value:
                before = pointer.value
                result = self._lib.espeak_TextToPhonemes(ctypes.byref(pointer), _CHARS_UTF8, mode)
                end = len(encoded) if not pointer.value else min(max(pointer.value - base, 0), len(encoded))
                if result:
                    clauses.append((end, result.decode("utf-8", "replace")))
                if pointer.value == before:
                    break
        # byte offsets to character offsets: the characters that start before each byte offset
        starts = list(itertools.accumulate((len(c.encode("utf-8")) for c in text), initial=0))
        out = []
        for end, clause in clauses:
            phonemes = []
            for item in re.split(r"[\s" + re.escape(_PHONEME_SEPARATOR) + "]+", clause):
                symbol = item.replace(_PRIMARY_STRESS, "").replace(_SECONDARY_STRESS, "")
                if symbol:  # pauses have empty names
                    stress = next((mark for mark in (_PRIMARY_STRESS, _SECONDARY_STRESS) if mark in item), "")
                    phonemes.append((_event_name(symbol), stress))
            at = bisect.bisect_left(starts, end)
            # espeak-ng reads on into the next clause's first word ("there, m|y"): the clause ends before it
            while 0 < at < len(text) and not text[at - 1].isspace() and not text[at].isspace():
                at -= 1
            out.append((at, phonemes))
        return out


def _event_name(symbol: str) -> str:
    """``symbol`` as a PHONEME event would carry it: at most 8 UTF-8 bytes, whole characters only."""
    return symbol.encode("utf-8")[:_PHONEME_NAME_BYTES].decode("utf-8", "ignore")


_ENGINE: _Engine | None = None
_ENGINE_ERROR: SpeechBackendUnavailable | None = None
_ENGINE_LOCK = threading.Lock()


class _Pristine:
    """espeak-ng as it is before its first synthesis, kept in a process of its own that forks for every
    synthesis: the fork synthesises and exits, and the engine it came from stays as it was.

    espeak-ng keeps state from one synthesis to the next (the phase of its pitch flutter, its gain
    control): spoken again in one process, the same text keeps its words and phonemes but its times move
    by samples to milliseconds, and its audio differs. The first synthesis of a fresh process is exactly
    reproducible, and so every synthesis is, made this way: the same text gives the same samples and
    times in every process, whatever was spoken before (a fork costs about a millisecond). Messages on
    the pipes are pickles behind their length; the samples are raw bytes between two messages, read straight
    into their buffer (see :func:`_serve_pristine`): no process holds them twice.
    """

    def __init__(self, library: str) -> None:
        import subprocess
        import sys
        from pathlib import Path

        self.pid = os.getpid()
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[1])  # where speech_timing (and agentsim) are
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
        self.process = subprocess.Popen(
            [sys.executable, "-c", "from speech_timing.espeak import _serve_pristine; _serve_pristine()", library],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        ready = _receive(self.process.stdout)
        if ready != "ready":
            self.process.kill()
            raise SpeechBackendUnavailable(f"espeak-ng could not be started in a process of its own ({ready}); "
                                           f"install it with: {INSTALL_HINT}")

    def synth(self, ssml: str, voice: str, rate: int) -> tuple[_PcmBuffer, list[_RawEvent]]:
        """The samples (read from the pipe straight into their buffer) and the events of one synthesis."""
        try:
            _send(self.process.stdin, (ssml, voice, rate))
            reply = _read_reply(self.process.stdout)
        except (OSError, EOFError) as exc:
            reply = f"its process ended ({exc})"
        if isinstance(reply, str):
            raise RuntimeError(f"espeak-ng synthesis failed: {reply}")
        return reply

    def __del__(self) -> None:
        process = getattr(self, "process", None)
        if process is not None and self.pid == os.getpid():
            process.kill()


def _send(stream, value) -> None:
    import pickle

    data = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(len(data).to_bytes(8, "little") + data)
    stream.flush()


def _receive(stream):
    import pickle

    return pickle.loads(_receive_raw(stream)[8:])


def _read_reply(stream) -> tuple[_PcmBuffer, list[_RawEvent]] | str:
    """A synthesis's reply as :func:`_serve_pristine` sends it: the samples, read straight into their buffer,
    and the events; or what went wrong."""
    reply = _receive(stream)
    if isinstance(reply, str):
        return reply
    count, events = reply
    buffer = _PcmBuffer.read_from(stream, count)
    end = _receive(stream)
    return (buffer, events) if end == "whole" else end


def _receive_raw(stream) -> bytes:
    """One message as it came: its length and its pickle."""
    head = stream.read(8)
    if len(head) < 8:
        raise EOFError("no reply")
    size = int.from_bytes(head, "little")
    data = stream.read(size)
    if len(data) < size:
        raise EOFError("a cut reply")
    return head + data


#: Bytes of samples passed on at a time from the synthesising fork to the process that asked.
_RELAY_BLOCK = 1 << 20


def _serve_pristine() -> None:
    """The loop of :class:`_Pristine`'s process: for each request on stdin, fork; the fork synthesises and
    hands its samples and events back through a pipe; the reply goes to stdout as it comes.

    A reply is a message ``(count, events)`` (or the error as a string), then the ``count`` 16-bit samples
    as raw bytes, streamed from the fork's buffer through this process a block at a time (no process holds
    a second copy of them), then the message ``"whole"``, or what went wrong if the fork died on the way
    (the samples it did not send are sent as zeros, so that the next reply starts where it should). Ends
    when stdin closes."""
    import sys

    requests, replies = sys.stdin.buffer, sys.stdout.buffer
    try:
        engine = _Engine(sys.argv[1])
    except BaseException as exc:  # said to the parent, which raises it there
        _send(replies, f"{type(exc).__name__}: {exc}")
        return
    _send(replies, "ready")
    while True:
        try:
            ssml, voice, rate = _receive(requests)
        except EOFError:
            return
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:  # the fork: synthesise once, reply, and go
            os.close(read)
            with os.fdopen(write, "wb") as out:
                try:
                    buffer, events = engine.synth_here(ssml, voice, rate)  # which selects the voice and rate
                except BaseException as exc:
                    _send(out, f"{type(exc).__name__}: {exc}")
                else:
                    _send(out, (buffer.filled, events))
                    out.write(buffer.raw())
            os._exit(0)
        os.close(write)
        with os.fdopen(read, "rb") as reply_stream:
            try:
                head = _receive_raw(reply_stream)
            except EOFError:
                head = None
            if head is None:
                _send(replies, "the synthesising process died")
            else:
                replies.write(head)
                reply = _receive(io.BytesIO(head))
                if not isinstance(reply, str):
                    _relay(reply_stream, replies, 2 * reply[0])
        os.waitpid(pid, 0)
        replies.flush()


def _relay(source, target, size: int) -> None:
    """Pass ``size`` bytes from ``source`` to ``target`` a block at a time, then ``"whole"``; if ``source``
    ends first, zeros for the rest, then that the synthesising process died."""
    left = size
    while left:
        block = source.read(min(left, _RELAY_BLOCK))
        if not block:
            break
        target.write(block)
        left -= len(block)
    if left:
        zeros = bytes(min(left, _RELAY_BLOCK))
        while left:
            target.write(zeros[:min(left, _RELAY_BLOCK)])
            left -= min(left, _RELAY_BLOCK)
        _send(target, "the synthesising process died")
    else:
        _send(target, "whole")


def _engine() -> _Engine:
    """The process-wide engine, created on first use; a failure to create it is remembered."""
    global _ENGINE, _ENGINE_ERROR
    with _ENGINE_LOCK:
        if _ENGINE is None:
            if _ENGINE_ERROR is not None:
                raise _ENGINE_ERROR
            try:
                _ENGINE = _Engine()
            except SpeechBackendUnavailable as exc:
                _ENGINE_ERROR = exc
                raise
        return _ENGINE


# ----------------------------------------------------------------------------------------------------
# Text: SSML construction and the mapping from espeak's positions back to the plain text.

_MARK_NAME = "m{}"
_MARK_ELEMENT = '<mark name="' + _MARK_NAME + '"/>'

_WRITTEN_WORD = re.compile(r"[^\s\x00\u2012-\u2015\u2026/]+")  # not space, NUL, figure/en/em dash, bar, ellipsis, slash

# Characters at the edges of a written word that are not part of the word as spoken.
_SILENT_EDGE = frozenset('.,;:!?"\'()[]{}<>«»“”„‘’‚‹›…–—¡¿*_-')


def _to_ssml(text: str, marks: tuple[tuple[int, str], ...], prosody: tuple[Prosody, ...] = ()
             ) -> tuple[str, list[int]]:
    """SSML for ``text`` with a mark element ``m<i>`` for ``marks[i]`` at its offset and an element for
    each prosody span espeak-ng can apply (see :func:`_prosody_markup`).

    Returns the SSML and, for each of its characters, the offset in ``text`` it stands for (a character
    of an escaped entity stands for the escaped character, markup for the character that follows it).
    Marks get generated names so that any name survives the round trip. At one offset, the elements
    that close come first (the inner before the outer), then breaks, marks, and the elements that open
    (the outer before the inner).
    """
    for offset, name in marks:
        if not 0 <= offset <= len(text):
            raise ValueError(f"mark {name!r} at offset {offset} is outside the text (length {len(text)})")
    order = sorted(range(len(marks)), key=lambda i: (marks[i][0], i))
    opens: dict[int, list[str]] = {}
    closes: dict[int, list[str]] = {}
    breaks: dict[int, list[str]] = {}
    for span, (opening, closing) in _prosody_markup(text, prosody):
        if span.kind == "break":
            breaks.setdefault(span.start, []).append(opening)
        else:
            opens.setdefault(span.start, []).append(opening)
            closes.setdefault(span.end, []).insert(0, closing)  # opened later: inner, closes first
    pieces: list[str] = []
    origin: list[int] = []

    def emit(piece: str, offset: int) -> None:
        pieces.append(piece)
        origin.extend([offset] * len(piece))

    k = 0
    for offset in range(len(text) + 1):
        for piece in closes.get(offset, []) + breaks.get(offset, []):
            emit(piece, offset)
        while k < len(order) and marks[order[k]][0] == offset:
            emit(_MARK_ELEMENT.format(order[k]), offset)
            k += 1
        for piece in opens.get(offset, ()):
            emit(piece, offset)
        if offset < len(text):
            emit(escape(text[offset]) if text[offset] != "\0" else " ", offset)  # NUL would end the C string
    return "".join(pieces), origin


# What espeak-ng 1.51 reads (its ssml.c). A value it does not know is worse than left out: an unknown
# emphasis level is looked up at index -1 of a table, an unknown say-as makes it read the text as
# something else and report words inside the markup, and "0.3s" is read as 0 ms (it reads the digits
# before the first other character, then "s" for seconds).
_EMPHASIS_LEVELS = frozenset({"none", "reduced", "moderate", "strong", "x-strong"})
_PROSODY_LABELS = {
    "rate": frozenset({"x-slow", "slow", "medium", "fast", "x-fast", "default"}),
    "pitch": frozenset({"x-low", "low", "medium", "high", "x-high", "default"}),
    "range": frozenset({"x-low", "low", "medium", "high", "x-high", "default"}),
    "volume": frozenset({"silent", "x-soft", "soft", "medium", "loud", "x-loud", "default"}),
}
#: Units espeak reads in each prosody attribute ("st" and "db" only as a signed change).
_PROSODY_UNITS = {"rate": ("", "%"), "pitch": ("", "%", "st"), "range": ("", "%", "st"),
                  "volume": ("", "%", "db")}
#: say-as interpretations espeak reads, by the name given; SSML's "digits" is espeak's "tts:digits"
#: (digit by digit). Others ("cardinal", "date", ...) are left out: espeak reads numbers as cardinals.
_SAY_AS = {"characters": "characters", "tts:char": "tts:char", "tts:key": "tts:key",
           "tts:digits": "tts:digits", "digits": "tts:digits", "telephone": "telephone"}


def _prosody_value(name: str, value: str) -> str | None:
    """``value`` of prosody attribute ``name`` as espeak reads it, or None if espeak cannot read it.

    A label, a percentage (``"80%"``, ``"+20%"``), a number (for ``rate`` a factor: ``"1.5"``, ``"+0.5"``;
    for pitch, range and volume espeak's own 0-100 scale, or a change on it: ``"75"``, ``"+10"``), a signed
    number of semitones for pitch and range (``"+2st"``), of espeak's volume units for volume (``"+6dB"``).
    Values in Hz, unsigned semitones or decibels, rates below 1 % and percentages below zero are left
    out.
    """
    label = value.strip().lower()
    if label in _PROSODY_LABELS[name]:
        return label
    number = parse_number(value)
    if number is None:
        return None
    sign, magnitude, unit = number
    if unit not in _PROSODY_UNITS[name] or (unit in ("st", "db") and not sign):
        return None
    if unit == "%" or name == "rate":
        percent = magnitude * (1.0 if unit == "%" else 100.0)
        percent = percent if not sign else 100.0 + (percent if sign == "+" else -percent)
        if percent < (1.0 if name == "rate" else 0.0):
            return None
    return f"{sign}{magnitude:g}{'dB' if unit == 'db' else unit}"


def _attribute(name: str, value: str) -> str:
    """`` name="value"``, the value escaped for a double-quoted attribute."""
    return f' {name}="{escape(value, {chr(34): "&quot;"})}"'


def _markup(span: Prosody) -> tuple[str, str] | None:
    """The opening and closing markup of one span (a break: its empty element and ""), or None when
    espeak-ng can apply nothing of it."""
    if span.kind == "break":
        seconds = parse_time(span.attr("time")) if span.attr("time") else None
        strength = span.attr("strength").strip().lower()
        if seconds is not None:
            return "<break" + _attribute("time", f"{round(seconds * 1000)}ms") + "/>", ""
        if strength in BREAK_STRENGTHS:
            return "<break" + _attribute("strength", strength) + "/>", ""
        return ("<break/>", "") if not span.attrs else None
    if span.kind == "emphasis":
        level = span.attr("level").strip().lower()
        return "<emphasis" + (_attribute("level", level) if level in _EMPHASIS_LEVELS else "") + ">", "</emphasis>"
    if span.kind == "prosody":
        attributes = ""
        for name in ("rate", "pitch", "range", "volume"):
            value = _prosody_value(name, span.attr(name)) if span.attr(name) else None
            attributes += _attribute(name, value) if value is not None else ""
        return ("<prosody" + attributes + ">", "</prosody>") if attributes else None
    if span.kind == "say-as":
        interpret = _SAY_AS.get(span.attr("interpret-as").strip().lower())
        if interpret is None:
            return None
        attributes = _attribute("interpret-as", interpret)
        if interpret == "characters" and span.attr("format").strip().lower() == "glyphs":
            attributes += _attribute("format", "glyphs")
        if interpret == "tts:digits" and span.attr("detail").strip().isdigit():
            attributes += _attribute("detail", span.attr("detail").strip())
        return "<say-as" + attributes + ">", "</say-as>"
    return None


def _prosody_markup(text: str, prosody: tuple[Prosody, ...]) -> list[tuple[Prosody, tuple[str, str]]]:
    """The spans espeak-ng can apply, with their markup, on offsets moved to the edges of written words.

    espeak separates an SSML element from the text around it as if by a space, so an element inside a
    written word would split it: an offset strictly inside a word's spoken core moves out of it, to the
    core's start for a span's start and to its end for a span's end or a break. Spans the move makes
    cross are left out (the one opened later). In the order they open.
    """
    cores = [(token.core_start, token.core_end) for token in _tokens(text)]
    starts = [start for start, _ in cores]

    def snap(offset: int, outward_to_end: bool) -> int:
        i = bisect.bisect_right(starts, offset) - 1
        if i >= 0 and cores[i][0] < offset < cores[i][1]:
            return cores[i][1] if outward_to_end else cores[i][0]
        return offset

    markup: dict[int, tuple[str, str]] = {}
    moved = []
    for span in check_prosody(SpeechText(text, prosody=tuple(prosody))):
        found = _markup(span)
        if found is None:
            continue
        if span.kind == "break":
            start = end = snap(span.start, True)
        else:
            start, end = snap(span.start, False), snap(span.end, True)
        span = Prosody(span.kind, start, end, span.attrs)
        markup[id(span)] = found
        moved.append(span)
    return [(span, markup[id(span)]) for span in nest_spans(moved)]


@dataclass(frozen=True)
class _Token:
    """A written word: its run of ``text`` (``start``, ``end``) and its spoken core (``core_*``)."""

    start: int
    end: int
    core_start: int
    core_end: int


def _tokens(text: str) -> list[_Token]:
    """Written words of ``text``: runs between whitespace, dashes and slashes, trimmed of punctuation.

    A hyphen does not separate words: espeak reads "well-known" under one WORD event. Punctuation
    alone ("-", "...") is not a word.
    """
    tokens = []
    for match in _WRITTEN_WORD.finditer(text):
        start, end = match.span()
        core_start, core_end = core_span(text, start, end)
        if core_start < core_end:  # punctuation alone is not spoken
            tokens.append(_Token(start, end, core_start, core_end))
    return tokens


def core_span(text: str, start: int, end: int) -> tuple[int, int]:
    """``text[start:end]`` without the punctuation at its edges (:data:`_SILENT_EDGE`): the written word as
    spoken (an empty span at the end of punctuation alone)."""
    while start < end and text[start] in _SILENT_EDGE:
        start += 1
    while end > start and text[end - 1] in _SILENT_EDGE:
        end -= 1
    return start, end


def _token_index(tokens: list[_Token], starts: list[int], offset: int) -> int | None:
    """Index of the token a word event at ``offset`` belongs to (None past the last token).

    An offset in whitespace or in a token's trailing punctuation belongs to the next token: espeak
    sometimes reports a word one character early after a full stop.
    """
    i = bisect.bisect_right(starts, offset) - 1
    if i >= 0 and offset < tokens[i].core_end:
        return i
    return i + 1 if i + 1 < len(tokens) else None


# ----------------------------------------------------------------------------------------------------
# Events to timeline.


@dataclass
class _PhonemeDraft:
    """A sounding phoneme, in samples."""

    symbol: str
    start: int
    end: int
    stressed: bool = False


@dataclass
class _Group:
    """The sounding phonemes reported under one WORD event.

    ``token`` is the written word the event points to. espeak pronounces some word pairs from its
    dictionary as one word ("in the", "of a"); then the group also holds the next written word.
    """

    token: int
    phonemes: list[_PhonemeDraft] = field(default_factory=list)


def _phoneme_ends(events: list[_RawEvent], total_samples: int) -> dict[int, int]:
    """End sample of each PHONEME event, keyed by its index in ``events``.

    A phoneme ends at the next PHONEME event, or earlier at a WORD event in between: espeak puts the
    silent gap before a word (up to about 50 ms before a voiceless stop) after the WORD event. A WORD
    event at the phoneme's own sample does not end it: a nasal or liquid before a vowel is sounded
    after that WORD event, as the start of the vowel.
    """
    ends: dict[int, int] = {}
    next_phoneme = total_samples
    word_between: int | None = None
    for i in range(len(events) - 1, -1, -1):
        event = events[i]
        if event.kind == _EVENT_PHONEME:
            end = next_phoneme
            if word_between is not None and event.sample < word_between < next_phoneme:
                end = word_between
            ends[i] = max(event.sample, min(end, total_samples))
            next_phoneme, word_between = event.sample, None
        elif event.kind == _EVENT_WORD:
            word_between = event.sample
    return ends


def _read_events(text: str, origin: list[int], tokens: list[_Token], events: list[_RawEvent],
                 total_samples: int) -> list[_Group]:
    """Group the sounding phonemes (pauses left out) by the written word espeak reports them under.

    Several WORD events inside one written word ("1234", "AT&T", "Dr.") make one group.
    """
    starts = [token.start for token in tokens]
    ends = _phoneme_ends(events, total_samples)
    groups: list[_Group] = []
    for i, event in enumerate(events):
        if event.kind == _EVENT_WORD:
            position = event.text_position - 1
            offset = origin[position] if 0 <= position < len(origin) else len(text)
            token = _token_index(tokens, starts, offset)
            if token is not None and (not groups or token > groups[-1].token):
                groups.append(_Group(token))
        elif event.kind == _EVENT_PHONEME and event.name and groups:
            groups[-1].phonemes.append(_PhonemeDraft(event.name, event.sample, ends[i]))
    return groups


def _is_spoken(text: str, token: _Token) -> bool:
    """Whether a written word has a letter or digit, so that espeak says something for it."""
    return any(ch.isalnum() for ch in text[token.start:token.end])


def _split_counts(symbols: list[str], parts: list[list[str]]) -> list[int]:
    """How many of a group's phoneme ``symbols`` belong to each of its written words.

    ``parts`` are the words' own transcriptions. When their lengths add up, they are used as they are;
    otherwise each phoneme goes to the word of the transcription phoneme it aligns with (a phoneme
    that aligns with none goes with the one before).
    """
    if sum(len(part) for part in parts) == len(symbols):
        return [len(part) for part in parts]
    flat = [symbol for part in parts for symbol in part]
    owner = [k for k, part in enumerate(parts) for _ in part]
    labels: list[int | None] = [None] * len(symbols)
    for block in difflib.SequenceMatcher(None, symbols, flat, autojunk=False).get_matching_blocks():
        for d in range(block.size):
            labels[block.a + d] = owner[block.b + d]
    counts = [0] * len(parts)
    current = 0
    for label in labels:
        current = max(current, label if label is not None else current)
        counts[current] += 1
    return counts


def _word_spans(text: str, tokens: list[_Token], groups: list[_Group], transcribe
                ) -> list[tuple[int, int, list[_PhonemeDraft]]]:
    """``(char_start, char_end, phonemes)`` for each word as spoken, in order.

    A group covering several written words is split between them by their own transcriptions
    (``transcribe(word) -> list of symbols``); a written word that gets no phoneme of its own is
    joined to its neighbour in the group.
    """
    spans: list[tuple[int, int, list[_PhonemeDraft]]] = []
    for g, group in enumerate(groups):
        if not group.phonemes:
            continue  # a word event with no sound
        following = groups[g + 1].token if g + 1 < len(groups) else len(tokens)
        members = [group.token] + [k for k in range(group.token + 1, following) if _is_spoken(text, tokens[k])]
        if len(members) == 1:
            counts = [len(group.phonemes)]
        else:
            parts = [transcribe(text[tokens[k].core_start:tokens[k].core_end]) for k in members]
            counts = _split_counts([p.symbol for p in group.phonemes], parts)
        position, first_of_group = 0, len(spans)
        pending_start: int | None = None
        for k, count in zip(members, counts):
            token = tokens[k]
            if count == 0:
                if len(spans) > first_of_group:  # join the previous word of this group
                    start, _, phonemes = spans[-1]
                    spans[-1] = (start, token.core_end, phonemes)
                elif pending_start is None:  # join the next one
                    pending_start = token.core_start
                continue
            start = token.core_start if pending_start is None else pending_start
            spans.append((start, token.core_end, group.phonemes[position:position + count]))
            position += count
            pending_start = None
    return spans


def _mark_stress_by_clause(groups: list[_Group], tokens: list[_Token],
                           clauses: list[tuple[int, list[tuple[str, str]]]]) -> None:
    """:func:`_mark_stress` clause by clause: the phonemes of the words that start in a clause of the
    transcription (``(end, phonemes)`` as :meth:`_Engine.transcribe_clauses` gives them) aligned with its
    phonemes, so that a long text costs in proportion to its length."""
    if not clauses:
        return
    ends = [end for end, _ in clauses]
    spoken: list[list[_PhonemeDraft]] = [[] for _ in clauses]
    for group in groups:
        if group.phonemes:
            start = tokens[group.token].core_start if group.token < len(tokens) else ends[-1]
            spoken[min(bisect.bisect_right(ends, start), len(clauses) - 1)].extend(group.phonemes)
    for phonemes, (_, transcription) in zip(spoken, clauses):
        _mark_stress(phonemes, transcription)


def _mark_stress(phonemes: list[_PhonemeDraft], transcription: list[tuple[str, str]]) -> None:
    """Set ``stressed`` on phonemes aligned with a primary-stressed phoneme of the transcription."""
    matcher = difflib.SequenceMatcher(None, [p.symbol for p in phonemes],
                                      [symbol for symbol, _ in transcription], autojunk=False)
    for block in matcher.get_matching_blocks():
        for k in range(block.size):
            phonemes[block.a + k].stressed = transcription[block.b + k][1] == _PRIMARY_STRESS


def _first_sound_after(events: list[_RawEvent], index: int) -> int | None:
    """Sample of the first sounding PHONEME event after ``events[index]`` (None if there is none)."""
    for event in events[index + 1:]:
        if event.kind == _EVENT_PHONEME and event.name:
            return event.sample
    return None


#: How many utterances a backend keeps to say again as they were (see :meth:`EspeakBackend.synthesize`),
#: and how many bytes of audio they may hold together (the oldest are forgotten first; one larger than
#: that is not kept at all).
REMEMBERED = 64
REMEMBERED_BYTES = 64 * 2 ** 20


class EspeakBackend:
    """Text-to-speech with espeak-ng, timed by the synthesiser's own word, phoneme and mark events.

    Parameters
    ----------
    voice : str
        espeak-ng voice name, e.g. ``"en"``, ``"en-us"``, ``"de"``.
    rate : int
        Speaking rate in words per minute (80 to 450).

    Raises
    ------
    SpeechBackendUnavailable
        If the espeak-ng library or its data is not installed.
    ValueError
        For an unknown voice or a rate out of range.

    Notes
    -----
    A word starts with its first phoneme, where its sound starts, and ends where its last phoneme
    ends. espeak's WORD and MARK events come earlier, before the silent gap in front of the word (about
    12 ms, and about 50 ms before a voiceless stop), and a MARK in front of the second word of a pair
    espeak pronounces as one ("in <mark/>the") comes only at the word after the pair. So a mark is
    placed at the onset of the first word starting at or after its offset; a mark after the last word
    keeps the time of its MARK event (the end of the speech before the final pause).

    Phoneme names are IPA as espeak writes them (``ð ə k ˈa t`` without the stress marks); pauses are
    not listed. ``stressed`` marks the vowel of a syllable with primary stress.
    """

    name = "espeak"
    #: it says a text it was asked for before as it said it then (see :meth:`synthesize`)
    remembers = True

    def __init__(self, voice: str = "en", rate: int = 175) -> None:
        if not _RATE_MINIMUM <= rate <= _RATE_MAXIMUM:
            raise ValueError(f"rate must be {_RATE_MINIMUM} to {_RATE_MAXIMUM} words per minute, not {rate}")
        self._engine = _engine()
        self._engine.select(voice, int(rate))
        self.voice = voice
        self.rate = int(rate)
        # what was said, kept: the same text is said the same every time (each synthesis is a fresh
        # engine's, see _Pristine), and asked for again, of this backend or another of its voice and rate,
        # it is not synthesised again
        self._spoken = self._engine.spoken(voice, self.rate)

    @property
    def sample_rate(self) -> int:
        """Sample rate of the audio, in Hz."""
        return self._engine.sample_rate

    def synthesize(self, speech: SpeechText) -> Utterance:
        """Speak ``speech`` and return its audio with word, phoneme, mark and sentence times.

        Parameters
        ----------
        speech : SpeechText
            Plain text, marks at character offsets (0 to ``len(text)``) and prosody spans.

        Returns
        -------
        Utterance
            Times in seconds from the start of ``audio`` (float32 mono in [-1, 1]). The same ``speech``
            asked for again gets the same utterance (the last :data:`REMEMBERED` are kept, up to
            :data:`REMEMBERED_BYTES` of audio).
        """
        spoken = self._spoken.get(speech)  # what it said is looked up without waiting for the engine
        if spoken is not None:
            return spoken
        return self._spoken.keep(speech, self._synthesize(speech))  # under the engine's lock: one for all threads

    @property
    def remembered_bytes(self) -> int:
        """Bytes of audio the remembered utterances hold."""
        return self._spoken.bytes

    def forget(self, speech: SpeechText) -> None:
        """Stop remembering what ``speech`` was (whoever asked keeps it, in a form of its own: the speech
        cache reads its samples from its file); asked for again, it is synthesised again."""
        self._spoken.forget(speech)

    def _synthesize(self, speech: SpeechText) -> Utterance:
        text = speech.text
        ssml, origin = _to_ssml(text, speech.marks, speech.prosody)
        tokens = _tokens(text)
        engine = self._engine
        words_per_minute = min(max(round(self.rate * speech.rate), _RATE_MINIMUM), _RATE_MAXIMUM)
        with engine.lock:
            buffer, events = engine.synth(ssml, self.voice, words_per_minute)
            pcm = buffer.samples()
            groups = _read_events(text, origin, tokens, events, len(pcm))
            _mark_stress_by_clause(groups, tokens, engine.transcribe_clauses(text, self.voice, words_per_minute))
            spans = _word_spans(text, tokens, groups, functools.lru_cache(maxsize=None)(self._symbols))
        rate = self.sample_rate
        duration = len(pcm) / rate

        words, phonemes = [], []
        for index, (char_start, char_end, drafts) in enumerate(spans):
            words.append(Word(index, text[char_start:char_end], drafts[0].start / rate, drafts[-1].end / rate,
                              char_start, char_end))
            phonemes.extend(Phoneme(p.symbol, p.start / rate, p.end / rate, index, p.stressed) for p in drafts)

        mark_events = {event.name: event.sample for event in events if event.kind == _EVENT_MARK}
        word_starts = [word.char_start for word in words]
        times = [0.0] * len(speech.marks)
        latest = 0.0
        # in text order: a mark is never before one that stands before it (espeak-ng's MARK events after the
        # last word can come a few samples out of order when many follow one another)
        for k in sorted(range(len(speech.marks)), key=lambda k: (speech.marks[k][0], k)):
            following = bisect.bisect_left(word_starts, speech.marks[k][0])
            if following < len(words):
                time = words[following].start
            else:  # after the last word
                time = mark_events.get(_MARK_NAME.format(k), len(pcm)) / rate
            latest = times[k] = max(time, latest)
        marks = [Mark(name, t) for (_, name), t in zip(speech.marks, times)]

        sentences = []
        for i, event in enumerate(events):
            if event.kind == _EVENT_SENTENCE:
                onset = _first_sound_after(events, i)
                sentences.append((event.sample if onset is None else onset) / rate)

        # the 16-bit samples kept as they are (half the memory of their float32 array), read as float32 a
        # stretch at a time by whoever mixes them
        from speech_timing.samples import Pcm

        audio = Pcm(pcm)
        return Utterance(text=text, duration=duration, words=words, phonemes=phonemes, marks=marks,
                         sentences=sentences, sample_rate=rate, audio=audio, backend=self.name)

    def ssml(self, speech: SpeechText) -> str:
        """The SSML sent to espeak-ng for ``speech``: ``marks[i]`` as ``<mark name="m<i>"/>``, and the
        prosody spans espeak-ng can apply as its elements (see :func:`_prosody_markup`)."""
        return _to_ssml(speech.text, speech.marks, speech.prosody)[0]

    def _symbols(self, word: str) -> list[str]:
        """Phoneme symbols of one written word on its own."""
        return [symbol for symbol, _ in self._engine.transcribe(word, self.voice, self.rate)]
