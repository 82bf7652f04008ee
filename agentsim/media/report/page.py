"""Write a run report: one HTML file and a folder of the files it loads, opened from ``file://`` offline.

``write_report("run.html", ...)`` writes ``run.html`` and ``run_files/``:

===================  ====================================================================================
``three.min.js``     three.js with OrbitControls as one classic script (vendored, see ``vendor/``)
``report.js``        the page: player, 3D skeleton, timeline, gesture table, ``window.report``
``report.css``       its style
``data.js``          ``window.REPORT_DATA``: timeline, table, skeleton (:mod:`~agentsim.media.report.data`)
``poses.js``         ``window.REPORT_POSES``: quantized joint positions (only when the run has motion)
``audio.ogg``        the run's track, Ogg Vorbis (``audio.wav`` if Vorbis cannot be written); only with sound
===================  ====================================================================================

Everything is loaded by ``<script src>`` and ``<audio src>`` relative to the HTML file, because a browser
refuses ``fetch()`` and ES modules from ``file://``; nothing is fetched from the network. The HTML itself
holds only the page's structure, the title and notes, and a two-line error catcher: no data.

The page and its folder are whole or absent as a pair: the folder is staged and swapped in, then the page
renamed into place (:func:`~agentsim.written.staged_page`); a killed run leaves the old report or none.
"""

from __future__ import annotations

import concurrent.futures
import html
import shutil
import zlib
from pathlib import Path
from urllib.parse import quote

import numpy as np

from agentsim.written import staged_page, written
from agentsim.media import AXIS
from agentsim.media.files import write_text
from agentsim.media.report.data import (FACE, js_assignment, point_names, run_duration, stroke_times,
                                        timeline_payload, write_poses)

HERE = Path(__file__).resolve().parent
#: The vendored three.js bundle and its licence (``scripts/vendor_three.sh`` makes them).
VENDOR = HERE / "vendor"
#: The page's own script and style.
ASSETS = HERE / "assets"
#: Files of the folder that :func:`write_report` writes or removes (a report written again over an older one).
#: The sound's files (one of them: :func:`write_audio`).
AUDIO_FILES = ("audio.ogg", "audio.wav")
OWN_FILES = ("three.min.js", "LICENSE-three.txt", "report.js", "report.css", "data.js", "poses.js",
             "stage.js", "physics.svg") + AUDIO_FILES
#: Samples handed to the audio encoder at a time.
AUDIO_BLOCK = 65536


def write_audio(folder: Path, track) -> str:
    """Write ``track`` into ``folder`` as ``audio.ogg`` (Ogg Vorbis), or ``audio.wav`` if libsndfile cannot
    write Vorbis; returns the file's name. ``track`` is a :class:`~agentsim.media.audio.Track` or a
    :class:`~agentsim.media.audio.TrackStream` (encoded stretch by stretch, never held whole)."""
    import soundfile

    def blocks():
        # in blocks: libsndfile 1.2 crashes when one write hands its Vorbis encoder more than about 2^20
        # samples; a stretch of a TrackStream is a whole number of blocks, so the blocks are the same
        for stretch in track.stretches():
            samples = np.clip(np.asarray(stretch, dtype=np.float32), -1.0, 1.0)
            for start in range(0, len(samples), AUDIO_BLOCK):
                yield samples[start:start + AUDIO_BLOCK]

    try:
        if not soundfile.check_format("OGG", "VORBIS"):
            raise ValueError("this libsndfile writes no Ogg Vorbis")
        with written(folder / "audio.ogg") as tmp:
            with soundfile.SoundFile(tmp, "w", int(track.rate), 1, format="OGG", subtype="VORBIS") as out:
                for block in blocks():
                    out.write(block)
            steady_ogg_serial(tmp)
        return "audio.ogg"
    except (RuntimeError, ValueError, TypeError):  # libsndfile without Vorbis
        (folder / "audio.ogg").unlink(missing_ok=True)
        with written(folder / "audio.wav") as tmp, soundfile.SoundFile(tmp, "w", int(track.rate), 1, format="WAV",
                                                                      subtype="PCM_16") as out:
            for block in blocks():
                out.write(block)
        return "audio.wav"


#: The serial number of the Ogg stream of a report's sound (libsndfile draws one from the clock).
OGG_SERIAL = 0x61677374
#: Each byte with its bits in reverse order (Ogg's CRC works from the high bit, zlib's from the low one).
_REVERSED_BITS = bytes(int(f"{k:08b}"[::-1], 2) for k in range(256))


def ogg_page_crc(page: bytes) -> int:
    """The CRC of an Ogg page (its CRC field zero): the CRC-32 of polynomial 0x04C11DB7, from the high bit,
    with no initial or final inversion, by zlib's CRC-32 (the same polynomial from the low bit) over the
    bytes with their bits reversed."""
    low = zlib.crc32(page.translate(_REVERSED_BITS), 0xFFFFFFFF) ^ 0xFFFFFFFF
    return int(f"{low:032b}"[::-1], 2)


def steady_ogg_serial(path: Path, serial: int = OGG_SERIAL) -> None:
    """Give the Ogg stream in the file at ``path`` the serial number ``serial`` (and each page its CRC anew):
    libsndfile numbers a stream from the clock, so that the same sound encoded twice would differ in these
    bytes alone. ValueError if the file is not a sequence of whole Ogg pages."""
    data = bytearray(Path(path).read_bytes())
    at = 0
    while at < len(data):
        if data[at:at + 4] != b"OggS" or at + 27 > len(data):
            raise ValueError(f"{path}: no Ogg page at byte {at}")
        segments = data[at + 26]
        end = at + 27 + segments + sum(data[at + 27:at + 27 + segments])
        if end > len(data):
            raise ValueError(f"{path}: the Ogg page at byte {at} is cut short")
        data[at + 14:at + 18] = serial.to_bytes(4, "little")
        data[at + 22:at + 26] = bytes(4)
        data[at + 22:at + 26] = ogg_page_crc(bytes(data[at:end])).to_bytes(4, "little")
        at = end
    Path(path).write_bytes(bytes(data))


def report_paths(path) -> tuple[Path, Path]:
    """The HTML file a report at ``path`` is written to (``.html`` added if it has no such suffix) and the
    folder of its files beside it."""
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        path = path.with_name(path.name + ".html")
    return path, path.with_name(f"{path.stem}_files")


def start_audio(path, track, executor: concurrent.futures.Executor) -> concurrent.futures.Future:
    """Begin writing the sound of the report at ``path`` (:func:`write_audio` into its folder) on
    ``executor``, so that it is encoded while the run's other files are made; hand the future to
    :func:`write_report` (``audio=``), which waits for it instead of encoding the track itself. A track
    without samples writes nothing (the future gives None)."""
    _, folder = report_paths(path)
    folder.mkdir(parents=True, exist_ok=True)
    for name in AUDIO_FILES:
        (folder / name).unlink(missing_ok=True)
    if track is None or track.length == 0:
        done: concurrent.futures.Future = concurrent.futures.Future()
        done.set_result(None)
        return done
    return executor.submit(write_audio, folder, track)


def write_report(path, *, recording, stream=None, track=None, gestures=(), title: str = "", notes=(),
                 audio: concurrent.futures.Future | None = None, environment: dict | None = None,
                 physics=None) -> Path:
    """Write an HTML report of a run that a researcher watches and hears: its audio, a 3D skeleton driven by
    the poses, a timeline of behaviours, words and feedback with a cursor that follows the audio, and the
    per-gesture error table.

    Parameters
    ----------
    path : str or Path
        The HTML file to write; its files go into ``<stem>_files/`` beside it.
    recording : Recording
        The run (or anything with a ``recording()`` method, such as a realizer after ``run()``).
    stream : PoseStream, optional
        Its poses (:func:`~agentsim.animation.output.evaluate_poses`); None: the run has no motion.
    track : agentsim.media.audio.Track, optional
        Its sound (:func:`~agentsim.media.audio.run_track`, or a
        :class:`~agentsim.media.audio.TrackStream` from :func:`~agentsim.media.audio.run_track_stream`);
        None (or an empty track): the run has no sound.
    gestures : sequence of GestureRow
        The per-gesture table (:func:`~agentsim.media.tables.gesture_rows`).
    title : str
        The page's title (default: the HTML file's stem).
    notes : iterable of str
        Lines shown under the title (what was run, with which settings).
    audio : Future, optional
        The track's sound already being written (:func:`start_audio` with the same ``path`` and
        ``track``): waited for instead of encoding the track here. The report is then written in place,
        for a report inside a run's folder that is staged whole
        (:func:`~agentsim.written.staged_folder`).
    environment : dict, optional
        The camera, lights and music of the run's emotions and the body's segments
        (:func:`~agentsim.media.environment.report_environment`): the 3D view then draws the body as solid
        segments under three-point lighting, filmed as the rows say (``stage.js``).
    physics : PhysicsResult, optional
        The physical body's figures when the run was simulated (``--physics``): the page then shows
        ``physics.svg``, the centre of mass against the support polygon
        (:mod:`~agentsim.media.report.physics`); the 3D skeleton is the ``stream``'s, the physical body's.

    Notes
    -----
    Without ``audio``, the page and its folder are whole or absent as a pair
    (:func:`~agentsim.written.staged_page`): the files are written into a staging folder beside the folder,
    which is swapped in once the report is whole, and the page is renamed into place last (the old page
    removed just before the swap), so that a killed run leaves the old report, or none, and never a page over
    another run's files; the next report there clears what a killed one staged.

    Returns
    -------
    Path
        The HTML file.
    """
    if hasattr(recording, "recording") and callable(recording.recording):
        recording = recording.recording()
    path, folder = report_paths(path)
    if track is not None and track.length == 0:
        track = None
    if stream is not None and stream.n_frames == 0:
        stream = None
    content = (recording, stream, track, list(gestures), title or path.stem, [str(n) for n in notes], environment,
               physics)
    if audio is None:  # the page and its folder staged, swapped in together once whole (staged_page)
        with staged_page(path, folder, marks=OWN_FILES) as (page, staging):
            _write_into(page, staging, folder.name, *content, audio=None)
        return path
    # the sound already being written into the folder itself: a report inside a run's folder, which the run
    # stages whole (staged_folder), written in place
    folder.mkdir(parents=True, exist_ok=True)
    for name in OWN_FILES:
        if name not in AUDIO_FILES:  # the sound being written is kept
            (folder / name).unlink(missing_ok=True)
    with written(path) as page:
        _write_into(page, folder, folder.name, *content, audio=audio)
    return path


def _write_into(page: Path, folder: Path, name: str, recording, stream, track, gestures, title, notes,
                environment, physics, audio) -> None:
    """Write the report's files into ``folder`` and its HTML into ``page``, which loads them from the folder
    ``name`` beside it."""
    for source in (VENDOR / "three.min.js", VENDOR / "LICENSE-three.txt", ASSETS / "report.js",
                   ASSETS / "report.css", *([ASSETS / "stage.js"] if environment else [])):
        with written(folder / source.name) as tmp:  # never through a link planted at the name
            shutil.copyfile(source, tmp)

    # the sound is encoded on a thread of its own (libsndfile does not hold the interpreter) while the
    # timeline and the poses are made
    with concurrent.futures.ThreadPoolExecutor(1) as encoder:
        if audio is None and track is not None:
            audio = encoder.submit(write_audio, folder, track)
        data = _page_data(recording, stream, track, gestures, title, notes, folder)
        src = audio.result() if audio is not None else None
        if src is not None and track is not None:
            data["audio"] = {"src": src, "duration": track.duration, "rate": int(track.rate)}
    if environment:
        data["environment"] = environment
    write_text(folder / "data.js", js_assignment(
        "REPORT_DATA", data, f"agentsim run report: timeline and tables of {title!r}, see "
        "agentsim.media.report.data"))
    picture = None
    if physics is not None:
        from agentsim.media.report.physics import write_physics_svg

        picture = write_physics_svg(folder / "physics.svg", physics.rows).name
    page.write_text(page_html(name, title, notes, data, physics=picture), encoding="utf-8")


def _page_data(recording, stream, track, gestures, title, notes, folder: Path) -> dict:
    """The page's timeline and tables, and its poses written into ``folder`` (the audio is added by the caller)."""
    duration = run_duration(recording, stream, track)
    data = timeline_payload(recording, gestures, duration)
    data.update(title=title, notes=notes, axis=AXIS, audio=None, motion=None)
    if stream is not None:
        names, parents = point_names(stream.body)
        poses = write_poses(folder / "poses.js", stream, f"agentsim run report: joint positions of {title!r}, see "
                            "agentsim.media.report.data", keep=stroke_times(recording, gestures))
        data["motion"] = {
            "fps": float(stream.fps), "frames": int(stream.n_frames), "sent": poses["count"],
            "start": float(stream.times[0]), "end": float(stream.times[-1]),
            "points": names, "parents": parents,
            "face": [i for i, n in enumerate(names) if n.split(".")[0] in FACE],
            "ends": [i for i, n in enumerate(names) if n.endswith(".end")],
        }
    return data


def page_html(folder: str, title: str, notes: list[str], data: dict, physics: str | None = None) -> str:
    """The HTML of a report whose files are in the folder named ``folder`` beside it (``physics``: the name of
    its picture of the centre of mass, when the body was simulated)."""
    base = quote(folder)
    esc = html.escape
    audio = data["audio"]
    if audio is not None:
        sound = (f'<audio id="audio" controls preload="auto" src="{base}/{quote(audio["src"])}"></audio>')
    else:
        sound = '<p id="nosound" class="missing">no sound in this run</p>'
    motion = "" if data["motion"] is not None else '<p id="nomotion" class="missing">no motion in this run</p>'
    note_items = "".join(f"<li>{esc(n)}</li>" for n in notes)
    scripts = ["three.min.js", "data.js"] + (["poses.js"] if data["motion"] is not None else [])
    scripts += (["stage.js"] if data.get("environment") else []) + ["report.js"]
    script_tags = "\n".join(f'<script src="{base}/{s}"></script>' for s in scripts)
    balance = "" if physics is None else (
        '<section id="physics-section">\n<h2>Centre of mass and support polygon (the physical body)</h2>\n'
        f'<img id="physics" src="{base}/{quote(physics)}" alt="the centre of mass against the support polygon">'
        '\n</section>\n')
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="agentsim.media.report">
<title>{esc(title)}</title>
<script>window.reportErrors=[];window.onerror=function(m,s,l){{window.reportErrors.push(m+" ("+String(s).split("/").pop()+":"+l+")")}};
window.addEventListener("unhandledrejection",function(e){{window.reportErrors.push("unhandled rejection: "+e.reason)}});</script>
<link rel="stylesheet" href="{base}/report.css">
</head>
<body>
<header>
<h1>{esc(title)}</h1>
<ul class="notes">{note_items}</ul>
<p id="summary"></p>
</header>
<main>
<section id="stage">
<div id="view">{motion}</div>
<div id="side">
<div id="transport">
{sound}
<div class="controls"><button id="play" type="button">&#9654; play</button>
<span id="clock">0.000 s</span></div>
<input id="scrub" type="range" min="0" max="1" step="0.001" value="0" aria-label="time">
</div>
<div id="now"></div>
<div id="legend"></div>
</div>
</section>
<section id="timeline-section">
<canvas id="timeline"></canvas>
<canvas id="overview"></canvas>
<div id="hover">&nbsp;</div>
</section>
{balance}<section id="table-section">
<h2>Gestures pegged to words and beats</h2>
<p class="hint">Click a row to go to its stroke; click a heading to sort.</p>
<div id="table-wrap"><table id="gestures"><thead></thead><tbody></tbody></table></div>
</section>
<footer>Time axis: {esc(AXIS)}. three.js under the MIT licence (<a href="{base}/LICENSE-three.txt">LICENSE</a>).</footer>
</main>
<noscript>This report needs JavaScript.</noscript>
{script_tags}
</body>
</html>
"""
