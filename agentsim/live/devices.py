"""Audio devices: PortAudio through sounddevice, and which device plays or records, said before a live run
begins (:func:`open_device`), with what to install or start where there is none."""

from __future__ import annotations

from agentsim.errors import Unavailable

def sounddevice_module():
    """The sounddevice module, or Unavailable saying what to install (or what is wrong with ALSA)."""
    from anticipators.audio import alsa_problem

    problem = alsa_problem()
    if problem:
        raise Unavailable(problem)
    try:
        import sounddevice
    except ImportError:
        raise Unavailable("live sound needs the sounddevice package: pip install sounddevice") from None
    except OSError as exc:
        raise Unavailable(f"live sound needs the PortAudio library ({exc}): apt-get install libportaudio2") from None
    return sounddevice


#: How to get a device to play on, where there is none.
GET_A_DEVICE = "plug in a sound card or start PulseAudio (apt-get install pulseaudio libasound2-plugins)"


class NoAudioDevice(Unavailable):
    """There is no audio device of the ``kind`` (``"output"`` or ``"input"``) asked for: none at all here, no
    such device, or one without channels of that kind. ``problem`` says which and what devices there are;
    the message adds how to get one (:data:`GET_A_DEVICE`) and name it."""

    def __init__(self, problem: str, kind: str):
        super().__init__(f"{problem}; {GET_A_DEVICE} and name its device (e.g. 'pulse')")
        self.problem = problem
        self.kind = kind


def device_info(sounddevice, device, kind: str) -> dict:
    """The device's info from PortAudio, or :class:`NoAudioDevice` naming the devices there are."""
    try:
        return dict(sounddevice.query_devices(device, kind))
    except (ValueError, sounddevice.PortAudioError) as exc:
        problem = exc
    try:
        devices = [dict(d) for d in sounddevice.query_devices()]
    except Exception:  # PortAudio itself is broken: say so through the original error
        devices = []
    names = ", ".join(d["name"] for d in devices if d[f"max_{kind}_channels"] > 0)
    found = None
    if device is not None:
        try:
            found = dict(sounddevice.query_devices(device))
        except (ValueError, sounddevice.PortAudioError):
            pass
    if found is not None:  # it is there, but it does not play (or record)
        raise NoAudioDevice(f"audio device {device!r} ({found['name']}) has no {kind} channels; {kind} devices "
                            f"here: {names or 'none'}", kind)
    if device is None and not names:
        other = "input" if kind == "output" else "output"
        only = ", ".join(d["name"] for d in devices if d[f"max_{other}_channels"] > 0)
        besides = f"; only {other} devices: {only}" if only else ""
        raise NoAudioDevice(f"there is no audio {kind} device here (PortAudio finds no sound card and no sound "
                            f"server{besides})", kind)
    which = f"no default audio {kind} device" if device is None else f"no audio {kind} device {device!r}"
    raise NoAudioDevice(f"{which} ({problem}); {kind} devices here: {names or 'none'}", kind)


def open_device(name: str | int | None, kind: str = "output"):
    """The sounddevice spec of the audio ``kind`` device ``name`` ("default" or None: the default one), after
    checking that PortAudio has it: Unavailable says which devices there are and what to install or start,
    before a live run begins."""
    sounddevice = sounddevice_module()
    device = None if name in (None, "default") else name
    if isinstance(device, str) and device.isdigit():
        device = int(device)
    device_info(sounddevice, device, kind)
    return device
