"""espeak-ng's C library bound with ctypes: one engine per process, each synthesis in a fork of an engine that
has never spoken (so that a text is said the same every time), and the events it reports."""

from __future__ import annotations

import bisect
import ctypes
import io
import itertools
import mmap
import os
import re
import threading
from dataclasses import dataclass

# numpy is imported where audio is made: loading the backend does without it
from speech_timing.backend import Spoken
from agentsim.errors import SpeechBackendUnavailable

#: How many utterances a backend keeps to say again as they were (see :meth:`EspeakBackend.synthesize`),
#: and how many bytes of audio they may hold together (the oldest are forgotten first; one larger than
#: that is not kept at all).
REMEMBERED = 64
REMEMBERED_BYTES = 64 * 2 ** 20


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
RATE_MINIMUM, RATE_MAXIMUM = 80, 450

_EVENT_LIST_TERMINATED = 0
EVENT_WORD = 1
EVENT_SENTENCE = 2
EVENT_MARK = 3
EVENT_PHONEME = 7

_PHONEME_SEPARATOR = "|"
PRIMARY_STRESS = "ˈ"
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
class RawEvent:
    """One espeak event, copied out of the library's memory.

    ``name`` is the mark name for MARK events, the phoneme name for PHONEME events and empty otherwise.
    """

    kind: int
    text_position: int
    length: int
    sample: int
    name: str = ""


def _decode_event(event: _Event) -> RawEvent:
    """Copy the fields of ``event`` that are used here; the library reuses its memory."""
    name = ""
    if event.type == EVENT_MARK and event.id.name:
        name = event.id.name.decode("utf-8", "replace")
    elif event.type == EVENT_PHONEME:
        # char[8], NUL-terminated only when the name is shorter than 8 bytes; a multi-byte
        # character cut off at the end is dropped.
        raw = ctypes.string_at(ctypes.addressof(event.id), _PHONEME_NAME_BYTES).split(b"\0", 1)[0]
        name = raw.decode("utf-8", "ignore")
    return RawEvent(event.type, event.text_position, event.length, event.sample, name)


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
        self._events: list[RawEvent] = []
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

    def synth(self, ssml: str, voice: str, rate: int) -> tuple[_PcmBuffer, list[RawEvent]]:
        """Synthesise SSML; return the int16 audio (in its buffer) and the events in the order espeak
        reported them. The synthesis runs in a fork of an engine that has never synthesised
        (:class:`_Pristine`), so that it comes out as the first synthesis of a fresh process does, whatever
        was said before."""
        with self.lock:
            if self._pristine is None or self._pristine.pid != os.getpid():  # a forked copy starts its own
                self._pristine = _Pristine(self.library)
            return self._pristine.synth(ssml, voice, rate)

    def synth_here(self, ssml: str, voice: str, rate: int) -> tuple[_PcmBuffer, list[RawEvent]]:
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
                symbol = item.replace(PRIMARY_STRESS, "").replace(_SECONDARY_STRESS, "")
                if symbol:  # pauses have empty names
                    stress = next((mark for mark in (PRIMARY_STRESS, _SECONDARY_STRESS) if mark in item), "")
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
    into their buffer (see :func:`serve_pristine`): no process holds them twice.
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
            [sys.executable, "-c", "from speech_timing.espeak.engine import serve_pristine; serve_pristine()", library],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        ready = _receive(self.process.stdout)
        if ready != "ready":
            self.process.kill()
            raise SpeechBackendUnavailable(f"espeak-ng could not be started in a process of its own ({ready}); "
                                           f"install it with: {INSTALL_HINT}")

    def synth(self, ssml: str, voice: str, rate: int) -> tuple[_PcmBuffer, list[RawEvent]]:
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


def _read_reply(stream) -> tuple[_PcmBuffer, list[RawEvent]] | str:
    """A synthesis's reply as :func:`serve_pristine` sends it: the samples, read straight into their buffer,
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


def serve_pristine() -> None:
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


def shared_engine() -> _Engine:
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
