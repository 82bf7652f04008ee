"""The storyteller's voice: a disk cache of synthesised utterances and phoneme-level sync marks.

Two text-to-speech backends that wrap another one (both follow
:class:`speech_timing.backend.TTSBackend`):

:class:`CachedBackend`
    Synthesises a text once and keeps the utterance (timeline and audio) on disk, keyed by a hash of
    the backend, its voice, its rate and the text. Sync marks do not change the sound, so the text is
    synthesised without them and the marks are placed afterwards on the cached words, the way the
    espeak-ng backend places them: at the onset of the first word that starts at or after the mark.
:class:`PhonemeMarks`
    Moves marks from the onset of their word to a phoneme of it, after the named timestamps of de
    Melo's EML (``<tm event="onStart|onEnd|onPhone">``). The event is written as a suffix of the BML
    sync id, so that any realizer planner that takes mark times from the backend gets phoneme-level
    sync points without knowing about phonemes:

    ================================  =========================================================
    ``<sync id="w12"/>``              onset of the next word (onStart, the plain BML meaning)
    ``<sync id="w12.stress"/>``       onset of the next word's vowel with primary stress (the
                                      word's onset when it has no stressed vowel)
    ``<sync id="w12.end"/>``          end of the next word (onEnd)
    ``<sync id="w12.ph2"/>``          onset of the next word's phoneme 2, counted from 0 (onPhone)
    ``<sync id="w12.stress.d500"/>``  500 ms of speech after that (any of the above, ``.d<ms>``)
    ================================  =========================================================

The delayed form lets a behaviour tie a later sync point (a gesture's ``end``) to the speech's own
timeline instead of to an offset after a speech sync point.

Times are seconds from the start of the utterance's audio.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import time
import zlib
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING

from speech_timing.backend import ColumnUtterance, Mark, Phoneme, SpeechText, Utterance, Word
from speech_timing.samples import BLOCK, Pcm, Pcm16, PcmFile
from agentsim.errors import AgentsimError
from agentsim.written import user_cache, written

if TYPE_CHECKING:  # numpy is imported where samples are written or read: a speech read from the cache does without
    import numpy as np

#: 16-bit samples read from (and written to) a cache file at a time.
READ_BLOCK = BLOCK

__all__ = ["CachedBackend", "WholeSpeechCache", "KeptSamples", "PhonemeMarks", "default_cache_dir", "word_after", "stressed_onset",
           "mark_event", "place_mark", "CACHE_FORMAT", "ReadUtterance"]

#: Version of the cache files; bump it when their layout or the meaning of their contents changes.
CACHE_FORMAT = 3

#: The header of a cache file's samples (numpy's format 1.0, as ``write_array_header_1_0`` writes 16-bit mono).
_SAMPLES_HEADER = re.compile(rb"\{'descr': '<i2', 'fortran_order': False, 'shape': \((\d+),\), \} *\n")
_DELAY = re.compile(r"\.d\d+$")
_EVENT = re.compile(r"^(?P<base>.+?)(?:\.(?P<event>stress|end|ph(?P<k>\d+)))?(?:\.d(?P<ms>\d+))?$")


def default_cache_dir() -> Path:
    """Where synthesised utterances are kept: ``$AGENTSIM_CACHE`` or ``$XDG_CACHE_HOME/agentsim/tts``
    (``~/.cache/agentsim/tts``)."""
    if os.environ.get("AGENTSIM_CACHE"):
        return Path(os.environ["AGENTSIM_CACHE"]).expanduser()
    return user_cache("tts")


# ----------------------------------------------------------------------------------------------------
# Marks on a timeline.


def word_after(utterance: Utterance, offset: int) -> int | None:
    """Index of the first word of ``utterance`` starting at or after character ``offset`` (None: none)."""
    return utterance.word_after(offset)


def _phonemes_of(utterance: Utterance, k: int) -> list[Phoneme]:
    return utterance.phonemes_of(k)


def stressed_onset(utterance: Utterance, k: int) -> tuple[float, bool]:
    """Onset (s) of word ``k``'s first vowel with primary stress, and whether it has one.

    A word without a stressed phoneme gives its own onset and False.
    """
    for p in _phonemes_of(utterance, k):
        if p.stressed:
            return p.start, True
    return utterance.words[k].start, False


def mark_event(name: str) -> tuple[str, str, int | None, float]:
    """``(base, event, phone, delay)`` of a sync id: event ``"start"``, ``"stress"``, ``"end"`` or
    ``"phone"`` (then ``phone`` is the phoneme's index in its word), and the delay in seconds."""
    match = _EVENT.match(name)
    if not match:
        return name, "start", None, 0.0
    delay = int(match.group("ms")) / 1000.0 if match.group("ms") else 0.0
    event = match.group("event") or "start"
    if match.group("k") is not None:
        return match.group("base"), "phone", int(match.group("k")), delay
    return match.group("base"), event, None, delay


def place_mark(utterance: Utterance, offset: int, name: str) -> float:
    """Time (s) of the mark ``name`` at character ``offset``: the event its suffix names
    (:func:`mark_event`) in the first word starting at or after ``offset``, plus its delay; after the
    last word, the end of the last word."""
    k = word_after(utterance, offset)
    if k is None:
        return utterance.words[-1].end if utterance.words else utterance.duration
    word = utterance.words[k]
    _, event, phone, delay = mark_event(name)
    if event == "stress":
        time = stressed_onset(utterance, k)[0]
    elif event == "end":
        time = word.end
    elif event == "phone":
        phonemes = _phonemes_of(utterance, k)
        time = phonemes[min(phone, len(phonemes) - 1)].start if phonemes else word.start
    else:
        time = word.start
    return time + delay


class PhonemeMarks:
    """A backend whose marks may stand for a phoneme of their word (see the module docstring).

    Parameters
    ----------
    backend : TTSBackend
        The backend that speaks; its words and phonemes are kept as they are.
    """

    def __init__(self, backend) -> None:
        self.backend = backend
        self.name = getattr(backend, "name", "")

    def synthesize(self, speech: SpeechText) -> Utterance:
        """Speak ``speech``; every mark is placed at the event its name asks for.

        A delayed mark (``w12.stress.d500``) whose undelayed name (``w12.stress``) is also a mark of
        ``speech`` is timed from that mark's word, wherever it stands in the text.
        """
        utterance = self.backend.synthesize(speech)
        offsets = dict((name, offset) for offset, name in speech.marks)
        marks = []
        for offset, name in speech.marks:
            undelayed = _DELAY.sub("", name)
            marks.append(Mark(name, place_mark(utterance, offsets.get(undelayed, offset), name)))
        return replace(utterance, marks=marks)


# ----------------------------------------------------------------------------------------------------
# The disk cache.


def _identity(backend) -> dict:
    """What, besides the text, decides what a backend says: its class, name, voice and rate, and what else it
    names in its ``cache_identity`` (Piper: its model's digest and its noise and silence settings)."""
    identity = {"class": f"{type(backend).__module__}.{type(backend).__qualname__}",
                "name": getattr(backend, "name", ""), "voice": getattr(backend, "voice", None),
                "rate": getattr(backend, "rate", None), "format": CACHE_FORMAT}
    if getattr(backend, "cache_identity", None) is not None:
        identity["settings"] = backend.cache_identity
    return identity


_WORD_FIELDS = ("index", "text", "start", "end", "char_start", "char_end")
_PHONEME_FIELDS = ("symbol", "start", "end", "word_index", "stressed")
assert _WORD_FIELDS == tuple(Word.__dataclass_fields__) and _PHONEME_FIELDS == tuple(Phoneme.__dataclass_fields__)


def _in_samples(times: list[float], rate: int) -> list[int] | None:
    """``times`` (s) as whole numbers of samples at ``rate``, if each is a float that is exactly such a number
    divided by ``rate`` (as reading divides it again); else None."""
    samples = []
    for t in times:
        if type(t) is not float or not math.isfinite(t):
            return None
        n = round(t * rate)
        if n / rate != t:
            return None
        samples.append(n)
    return samples


def _columns(items: list, fields: tuple[str, ...], rate: int) -> dict | None:
    """The items' fields as columns (one list a field), start and end in samples at ``rate`` (None if not every
    time of them is a whole number of samples)."""
    columns = {name: [getattr(item, name) for item in items] for name in fields}
    if not (isinstance(rate, int) and rate > 0):
        return None
    for name in ("start", "end"):
        columns[name] = _in_samples(columns[name], rate)
        if columns[name] is None:
            return None
    return columns


def _timeline(columns: dict, fields: tuple[str, ...], rate: int | None) -> list:
    """The columns' start and end in seconds (divided by ``rate``, the sample rate, unless it is None), and the
    columns in ``fields``' order; TypeError or ValueError for columns that are not those fields, all as long."""
    if columns.keys() != set(fields):
        raise TypeError(f"cached columns {sorted(columns)}")
    ordered = [columns[name] for name in fields]
    if any(len(column) != len(ordered[0]) for column in ordered):
        raise ValueError("cached columns of different lengths")
    if rate is not None:
        start, end = fields.index("start"), fields.index("end")
        ordered[start] = [n / rate for n in ordered[start]]
        ordered[end] = [n / rate for n in ordered[end]]
    return ordered


class ReadUtterance(ColumnUtterance):
    """An utterance read from the cache, whose ``words`` and ``phonemes`` are read from the entry's timeline
    (the second line of its file, checked by its length and CRC-32 when the entry was read) the first time
    they are asked for (see :class:`~speech_timing.backend.ColumnUtterance`)."""

    def _rows(self) -> tuple[list, list]:
        """The words' and the phonemes' columns (times in seconds), read from the timeline once."""
        state = self.__dict__
        rows = state.get("_timeline_rows")
        if rows is None:
            line, rate, path = state["_timeline"]
            try:
                columns = json.loads(line)
                rows = (_timeline(columns["words"], _WORD_FIELDS, rate),
                        _timeline(columns["phonemes"], _PHONEME_FIELDS, rate))
            except (ValueError, KeyError, TypeError, AttributeError, ZeroDivisionError) as exc:
                raise AgentsimError(f"the speech cache entry {path} is damaged ({exc}): delete it, or run with "
                                    "--no-cache") from None
            state["_timeline_rows"] = rows
            del state["_timeline"]
        return rows


#: ``json.dumps(value, sort_keys=True, ensure_ascii=False)``, with one encoder made once (a key is made for each
#: speech of a block).
_key_json = json.JSONEncoder(sort_keys=True, ensure_ascii=False).encode


class CachedBackend:
    """A backend that synthesises each text once and keeps the utterance on disk and in memory.

    Parameters
    ----------
    backend : TTSBackend
        The backend that speaks (espeak-ng, or the built-in timing model).
    cache_dir : str or Path, optional
        Directory of the cache files (default :func:`default_cache_dir`); None with ``enabled=False``
        keeps utterances in memory only.
    enabled : bool
        Whether to read and write the disk cache.

    Attributes
    ----------
    synthesis_seconds : float
        Wall time spent synthesising (cache misses only).
    load_seconds : float
        Wall time spent reading cache files.
    hits, misses : int
        Texts found in the cache, and texts synthesised.

    Notes
    -----
    A cache entry is ``<key>.json`` and, when the backend makes sound, ``<key>.npy`` (the audio as 16-bit
    samples, exactly as espeak-ng produced them). The key is the SHA-256 of the backend's identity and the text.
    The JSON file has two lines. The first holds ``format`` (:data:`CACHE_FORMAT`), ``backend`` (that identity),
    ``text``, ``duration`` (s), ``sample_rate``, ``backend_name``, ``sentences`` (their onsets, s), ``audio``
    (whether there is a ``.npy``), ``samples`` (where its samples start, and how many), ``marks`` when the backend
    placed its own (``[name, s]`` pairs), ``times`` and ``timeline`` (the second line's length and CRC-32). The
    second holds the timeline in columns, one list a field, read when first asked for (:class:`ReadUtterance`):
    ``words`` (``index``, ``text``, ``start``, ``end``, ``char_start``, ``char_end``) and
    ``phonemes`` (``symbol``, ``start``, ``end``, ``word_index``, ``stressed``). ``times`` says what their
    ``start`` and ``end`` count: ``"samples"`` at ``sample_rate`` (each time divided by it gives back exactly
    the seconds the backend gave, as for espeak-ng), else ``"seconds"``. espeak-ng is only exactly
    reproducible on the first synthesis in a process; the cache makes every later run identical.
    """

    def __init__(self, backend, cache_dir: str | Path | None = None, enabled: bool = True) -> None:
        self.backend = backend
        self.name = getattr(backend, "name", "")
        self.enabled = enabled
        self.cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        self.synthesis_seconds = 0.0
        self.load_seconds = 0.0
        self.hits = 0
        self.misses = 0
        #: keys of the texts synthesised (not found in the cache) by this backend
        self.synthesised: set[str] = set()
        self._memory: dict[str, Utterance] = {}
        self._identity_json: tuple[dict | None, str] = (None, "")  # the backend's identity, and its JSON

    def key(self, text: str) -> str:
        """Cache key of ``text`` spoken by this backend."""
        return self._hashed({"text": text})

    def _hashed(self, fields: dict) -> str:
        """The key of ``fields`` with the backend's identity (the hash of their JSON, keys sorted)."""
        identity = _identity(self.backend)
        if not fields or min(fields) <= "backend":  # (else the identity's JSON leads: written once, not per text)
            blob = _key_json({"backend": identity, **fields})
        else:
            if self._identity_json[0] != identity:
                self._identity_json = (identity, _key_json(identity))
            blob = '{"backend": ' + self._identity_json[1] + ", " + _key_json(fields)[1:]
        return hashlib.sha256(blob.encode("utf-8")).hexdigest()[:32]

    def utterance(self, text: str) -> Utterance:
        """The utterance of ``text`` without marks: from memory, from disk, or synthesised now."""
        return self._kept(self.key(text), SpeechText(text))

    def _kept(self, key: str, speech: SpeechText) -> Utterance:
        """What the backend says for ``speech`` (kept under ``key``): from memory, from disk, or synthesised now."""
        text = speech.text
        utt = self._memory.get(key)
        if utt is not None:
            return utt
        if self.enabled:
            started = time.perf_counter()
            utt = self._load(key, text)
            if utt is not None:
                self.load_seconds += time.perf_counter() - started
                self.hits += 1
        if utt is None:
            started = time.perf_counter()
            utt = self.backend.synthesize(speech)
            self.synthesis_seconds += time.perf_counter() - started
            self.misses += 1
            self.synthesised.add(key)
            if self.enabled:
                utt = self._save(key, utt)
                forget = getattr(self.backend, "forget", None)
                if forget is not None and isinstance(utt.audio, PcmFile):  # its samples in memory: let go
                    forget(speech)
        self._memory[key] = utt
        return utt

    def synthesize(self, speech: SpeechText) -> Utterance:
        """Speak ``speech``: the cached utterance of its text with its marks placed on word onsets (a speech
        at another rate is not cached)."""
        if speech.rate != 1.0:
            return self.backend.synthesize(speech)
        utt = self.utterance(speech.text)
        marks = [Mark(name, place_mark(utt, offset, "")) for offset, name in speech.marks]
        return replace(utt, marks=marks)

    # -- files ---------------------------------------------------------------------------------------
    def _paths(self, key: str) -> tuple[str, str]:
        base = os.path.join(self.cache_dir, key)
        return f"{base}.json", f"{base}.npy"

    def _save(self, key: str, utt: Utterance) -> Utterance:
        """Write ``utt`` into the cache; returns it with its audio read from the cache file from now on
        (not held in memory) when the file gives back exactly its samples."""
        import numpy as np

        meta_path, audio_path = self._paths(key)
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        has_audio = utt.audio is not None
        if has_audio:
            audio = utt.audio if isinstance(utt.audio, Pcm16) else np.asarray(utt.audio)
            # processes that write at once: a temporary file each (written)
            with written(audio_path) as tmp, open(tmp, "wb") as f:  # the file np.save writes, a block at a time
                # (no 16-bit copy held whole)
                np.lib.format.write_array_header_1_0(f, {"descr": "<i2", "fortran_order": False,
                                                         "shape": (len(audio),)})
                samples = [f.tell(), len(audio)]
                for a in range(0, len(audio), READ_BLOCK):  # no float64 copy of a long narration either
                    block = np.round(np.asarray(audio[a:a + READ_BLOCK], dtype=np.float64) * 32768.0)
                    f.write(np.clip(block, -32768, 32767).astype("<i2").tobytes())
        meta = {"format": CACHE_FORMAT, "backend": _identity(self.backend), "text": utt.text,
                "duration": utt.duration, "sample_rate": utt.sample_rate, "backend_name": utt.backend,
                "sentences": list(utt.sentences), "audio": has_audio, "times": "samples"}
        timeline = {"words": _columns(utt.words, _WORD_FIELDS, utt.sample_rate),
                    "phonemes": _columns(utt.phonemes, _PHONEME_FIELDS, utt.sample_rate)}
        if timeline["words"] is None or timeline["phonemes"] is None:  # times between samples: kept in seconds
            meta["times"] = "seconds"
            timeline = {"words": {name: [getattr(w, name) for w in utt.words] for name in _WORD_FIELDS},
                        "phonemes": {name: [getattr(p, name) for p in utt.phonemes] for name in _PHONEME_FIELDS}}
        if has_audio:
            meta["samples"] = samples
        if utt.marks:  # the backend's own marks (WholeSpeechCache)
            meta["marks"] = [[m.name, m.time] for m in utt.marks]
        line = json.dumps(timeline, ensure_ascii=False).encode("utf-8")
        meta["timeline"] = [len(line), zlib.crc32(line)]
        with written(meta_path) as tmp:  # (JSON written with no line break: the timeline is the second line)
            tmp.write_bytes(json.dumps(meta, ensure_ascii=False).encode("utf-8") + b"\n" + line)
        if has_audio:
            try:
                stored = PcmFile(audio_path)
            except (OSError, ValueError):
                return utt
            if len(stored) == len(audio) and all(
                    np.array_equal(stored.read(a, a + READ_BLOCK), audio[a:a + READ_BLOCK])
                    for a in range(0, len(audio), READ_BLOCK)):
                return replace(utt, audio=stored)
            stored.close()
        return utt

    def _load(self, key: str, text: str) -> Utterance | None:
        meta_path, audio_path = self._paths(key)
        try:
            with open(meta_path, "rb") as file:  # (as Path.read_bytes reads it, without pathlib's steps)
                data = file.read()
            cut = data.find(b"\n")
            meta = json.loads(data[:cut]) if cut > 0 else None
            if type(meta) is not dict or meta.get("format") != CACHE_FORMAT or meta.get("text") != text:
                return None
            if meta["times"] not in ("samples", "seconds"):
                return None
            rate = int(meta["sample_rate"]) if meta["times"] == "samples" else None
            timeline = data[cut + 1:]  # (read when the words or phonemes are first asked for, as it was written)
            if [len(timeline), zlib.crc32(timeline)] != meta["timeline"]:
                return None
            audio = self._samples(audio_path, meta.get("samples")) if meta["audio"] else None
            utt = ReadUtterance.of({"text": text, "duration": float(meta["duration"]),
                                    "marks": [Mark(name, float(t)) for name, t in meta.get("marks", [])],
                                    "sentences": [float(s) for s in meta["sentences"]],
                                    "sample_rate": int(meta["sample_rate"]), "audio": audio,
                                    "backend": meta.get("backend_name", "")})
            utt.__dict__["_timeline"] = (timeline, rate, meta_path)  # (what ReadUtterance._rows reads)
        except (OSError, ValueError, KeyError, TypeError, AttributeError, ZeroDivisionError):
            return None
        return utt

    def _samples(self, path: Path, where: list | None = None) -> Pcm16:
        """The samples of the cache file ``path``: read from the file as they are mixed, never held whole.
        (``where``: the byte they start at and how many there are, as the entry says.)"""
        return PcmFile(path)


class WholeSpeechCache(CachedBackend):
    """A :class:`CachedBackend` that keeps the backend's whole answer to each speech, as ``agentsim realize``
    speaks: its marks as the backend placed them, and a speech at another rate or with prosody spans too.

    The key is that of the text (:meth:`CachedBackend.key`, so a plain speech shares the storyteller's entry)
    with the marks, the rate and the prosody spans added when the speech has them. The samples of an entry are
    read into memory when they are first asked for (:class:`KeptSamples`), and audio that 16-bit samples do not
    give back exactly is not kept: a speech read from the cache is, sample for sample and time for time, what
    the backend said.
    """

    def speech_key(self, speech: SpeechText) -> str:
        """Cache key of ``speech`` spoken by this backend."""
        if not speech.marks and speech.rate == 1.0 and not speech.prosody:
            return self.key(speech.text)
        return self._hashed({"text": speech.text, "marks": [list(mark) for mark in speech.marks], "rate": speech.rate,
                             "prosody": [asdict(span) for span in speech.prosody]})

    def synthesize(self, speech: SpeechText) -> Utterance:
        """What the backend says for ``speech``: from memory, from the cache, or synthesised now (and kept)."""
        return self._kept(self.speech_key(speech), speech)

    def _save(self, key: str, utt: Utterance) -> Utterance:
        if utt.audio is not None and not isinstance(utt.audio, Pcm16):
            import numpy as np

            audio = np.asarray(utt.audio)
            samples = np.clip(np.round(audio.astype(np.float64) * 32768.0), -32768, 32767)
            if audio.dtype != np.float32 or not np.array_equal(samples / 32768.0, audio):
                return utt  # not 16-bit samples: the cache would not give them back exactly
        stored = super()._save(key, utt).audio
        if isinstance(stored, PcmFile):
            stored.close()
        return utt  # the samples stay in memory

    def _samples(self, path: Path, where: list | None = None) -> Pcm16:
        """The samples of the cache file ``path``, read into memory when they are first asked for (no file is
        held open meanwhile: a run may keep thousands of speeches, and most runs never hear them). ``where``:
        the byte they start at and how many there are, as the entry says (else read from the file's header)."""
        if where is not None:
            offset, length = where
            offset, length = int(offset), int(length)
            status = os.stat(path)
            if offset <= 0 or length < 0 or status.st_size < offset + 2 * length:
                raise ValueError(f"{path}: cut short")
            return KeptSamples(path, offset, length, (status.st_ino, status.st_size, status.st_mtime_ns))
        descriptor = os.open(path, os.O_RDONLY)  # (read as a file object reads it, without making one)
        try:
            start = os.read(descriptor, 10)  # numpy's magic, format 1.0 (as _save writes it), the header's length
            if len(start) != 10 or start[:8] != b"\x93NUMPY\x01\x00":
                raise ValueError(f"{path}: not a cache file")
            text = os.read(descriptor, int.from_bytes(start[8:], "little"))
            header = _SAMPLES_HEADER.fullmatch(text)
            if header is None:
                raise ValueError(f"{path}: not 16-bit mono samples as the cache writes them")
            offset, length = 10 + len(text), int(header.group(1))
            status = os.fstat(descriptor)
        finally:
            os.close(descriptor)
        if status.st_size < offset + 2 * length:
            raise ValueError(f"{path}: cut short")
        return KeptSamples(path, offset, length, (status.st_ino, status.st_size, status.st_mtime_ns))


class KeptSamples(Pcm16):
    """The 16-bit samples of a cache file (from byte ``offset``, ``length`` of them), read whole into memory the
    first time any is asked for; ``seen``: the file's inode, size and time of change when its entry was read (a
    file written anew since, by another process, is not read: an :class:`~agentsim.errors.AgentsimError` says
    so)."""

    def __init__(self, path: str | Path, offset: int, length: int, seen: tuple[int, int, int] | None = None) -> None:
        self.path, self.offset, self.length, self.seen = path, offset, length, seen  # (the path as given)
        self._samples: Pcm | None = None

    @property
    def held_bytes(self) -> int:
        return self._samples.held_bytes if self._samples is not None else 0

    def read(self, first: int, last: int) -> np.ndarray:
        if self._samples is None:
            import numpy as np

            with open(self.path, "rb") as file:
                status = os.fstat(file.fileno())
                if self.seen is not None and (status.st_ino, status.st_size, status.st_mtime_ns) != self.seen:
                    raise AgentsimError(f"the speech cache file {self.path} was written anew while this run used it: "
                                        "run again (or with --no-cache)")
                file.seek(self.offset)
                pcm = np.fromfile(file, dtype="<i2", count=self.length)
            if len(pcm) != self.length:
                raise ValueError(f"{self.path}: cut short")
            self._samples = Pcm(pcm.astype(np.int16, copy=False))
        return self._samples.read(first, last)
