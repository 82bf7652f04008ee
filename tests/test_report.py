"""The HTML run report without a browser: the files it writes, the data they carry read back in Python, and
a run without sound or motion. The page itself is driven in Chromium by tests/system/test_report_browser.py."""

from __future__ import annotations

import base64
import json
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
import soundfile

from agentsim.animation import evaluate_poses
from agentsim.animation.body import Body
from agentsim.animation.output import PoseStream
from agentsim.media.audio import MIX_CHUNK, Source, Track, mix, mix_stream
from agentsim.media.files import write_wav
from agentsim.media.report import write_report
from agentsim.media.report import data as report_data
from agentsim.media.report import page as report_page
from agentsim.media.tables import gesture_rows
from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'
BML = (f'<bml {NS} id="b1"><speech id="s1"><text>The <sync id="w1"/>lighthouse keeper walked '
       '<sync id="w2"/>slowly up the hill.</text></speech>'
       '<gesture id="g1" lexeme="BEAT" stroke="s1:w1"/>'
       '<gesture id="g2" lexeme="BEAT" mode="LEFT_HAND" stroke="s1:w2"/>'
       '<head id="h1" lexeme="NOD" stroke="s1:end"/></bml>')
#: The largest inline text the HTML may hold (its error catcher is about 250 characters).
INLINE_BOUND = 1000


@pytest.fixture(scope="module")
def run():
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(BML)
    realizer.run()
    recording = realizer.recording()
    stream = evaluate_poses(recording, fps=60)
    rate = 22050
    n = int(recording.now * rate) + rate // 2
    track = Track((0.1 * np.sin(2 * np.pi * 220 * np.arange(n) / rate)).astype(np.float32), rate)
    return recording, stream, track, gesture_rows(recording)


def js_value(path: Path, name: str):
    """The JSON a data file assigns to ``window.<name>``, read without the package's reader."""
    text = path.read_text(encoding="utf-8")
    match = re.search(rf"^window\.{name} = (.*);$", text, re.M)
    assert match, f"{path.name} does not assign window.{name}"
    return json.loads(match.group(1))


class Page(HTMLParser):
    """Script sources, inline scripts and the text of an HTML page."""

    def __init__(self):
        super().__init__()
        self.sources, self.inline, self.text, self.links = [], [], [], []
        self.in_script = False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "script":
            self.in_script = True
            if attrs.get("src"):
                self.sources.append(attrs["src"])
        for key in ("src", "href"):
            if attrs.get(key):
                self.links.append(attrs[key])

    def handle_endtag(self, tag):
        if tag == "script":
            self.in_script = False

    def handle_data(self, data):
        (self.inline if self.in_script else self.text).append(data)


def parse(path: Path) -> Page:
    page = Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


def test_the_page_and_its_files_are_written(run, tmp_path):
    recording, stream, track, rows = run
    path = write_report(tmp_path / "run.html", recording=recording, stream=stream, track=track, gestures=rows,
                        title="Two beats & a nod", notes=["builtin voice", "<60 fps>"])
    assert path == tmp_path / "run.html"
    folder = tmp_path / "run_files"
    for name in ("three.min.js", "LICENSE-three.txt", "report.js", "report.css", "data.js", "poses.js", "audio.ogg"):
        assert (folder / name).stat().st_size > 0, name
    page = parse(path)
    # classic scripts, in order, all in the folder beside the page: nothing from the network
    assert page.sources == [f"run_files/{n}" for n in ("three.min.js", "data.js", "poses.js", "report.js")]
    for link in page.links:
        assert not re.match(r"[a-z]+:", link), link
        assert (tmp_path / link).exists(), link
    text = " ".join(page.text)
    assert "Two beats & a nod" in text and "<60 fps>" in text  # escaped in the HTML, shown as written
    assert "no sound in this run" not in text and "no motion in this run" not in text
    # the vendored bundle is three.js with OrbitControls, version and licence named
    head = (folder / "three.min.js").read_text(encoding="utf-8")[:400]
    assert re.search(r"three\.js \d+\.\d+\.\d+", head) and "OrbitControls" in head and "MIT" in head
    assert "MIT License" in (folder / "LICENSE-three.txt").read_text(encoding="utf-8")
    # the audio is the track, as Ogg Vorbis
    info = soundfile.info(folder / "audio.ogg")
    assert (info.format, info.subtype, info.samplerate) == ("OGG", "VORBIS", track.rate)
    assert abs(info.frames - len(track.samples)) <= 1024


def test_no_data_goes_into_the_html(run, tmp_path):
    recording, stream, track, rows = run
    path = write_report(tmp_path / "run.html", recording=recording, stream=stream, track=track, gestures=rows)
    html = path.read_text(encoding="utf-8")
    page = parse(path)
    assert len(html) < 8000
    assert all(len(s) < INLINE_BOUND for s in page.inline)
    assert max(len(line) for line in html.splitlines()) < INLINE_BOUND
    assert "REPORT_POSES" not in html and "REPORT_DATA" not in html
    assert not re.search(r"[A-Za-z0-9+/]{200,}", html)  # no base64 blob


def test_poses_decode_to_the_streams_joint_positions(run, tmp_path):
    recording, stream, track, rows = run
    write_report(tmp_path / "run.html", recording=recording, stream=stream, track=track, gestures=rows)
    poses = js_value(tmp_path / "run_files" / "poses.js", "REPORT_POSES")
    meta = js_value(tmp_path / "run_files" / "data.js", "REPORT_DATA")["motion"]
    frames = np.frombuffer(base64.b64decode(poses["frames"]), "<u4")
    q = np.frombuffer(base64.b64decode(poses["xyz"]), "<i2").reshape(poses["count"], poses["points"], 3)
    xyz = q * poses["scale"] + np.array(poses["origin"])
    assert poses["scale"] == 0.001 and len(meta["points"]) == poses["points"] == len(meta["parents"])
    # a grid of at most 30 frames per second, the last frame, and the frames either side of every stroke
    assert np.all(np.diff(frames.astype(int)) > 0) and frames[0] == 0 and frames[-1] == stream.n_frames - 1
    grid = set(range(0, stream.n_frames, 2))
    assert grid <= set(frames.tolist())
    strokes = [g.happened_s for g in rows]
    assert {int(np.floor(t * 60 + 1e-9)) for t in strokes} | {int(np.ceil(t * 60 - 1e-9)) for t in strokes} \
        <= set(frames.tolist())
    extra = set(frames.tolist()) - grid - {stream.n_frames - 1}
    assert len(extra) <= 2 * len(report_data.stroke_times(recording, rows))
    # every point of every frame sent is where the body's kinematics put it, within half a millimetre
    names = meta["points"]
    assert names[: len(stream.body.joints)] == [j.name for j in stream.body.joints]
    fk = stream.body.forward_kinematics(stream.values[frames])
    for i, joint in enumerate(stream.body.joints):
        assert np.abs(xyz[:, i] - fk[joint.name][1]).max() <= 0.0005 + 1e-9, joint.name
        parent = meta["parents"][i]
        assert (parent == -1) if joint.parent is None else (names[parent] == joint.parent)
    for joint in stream.joints:  # and the stream's own tracked positions agree
        assert np.abs(xyz[:, names.index(joint)] - stream.position(joint)[frames]).max() <= 0.0005 + 1e-9
    rot, pos = fk["skullbase"]
    top = pos + rot @ np.array(stream.body.joint["skullbase"].end_site)
    assert np.abs(xyz[:, names.index("skullbase.end")] - top).max() <= 0.0005 + 1e-9
    # the package's own reader gives the same
    read = report_data.read_js_assignment((tmp_path / "run_files" / "poses.js").read_text(), "REPORT_POSES")
    f2, xyz2 = report_data.decode_poses(read)
    assert np.array_equal(f2, frames) and np.allclose(xyz2, xyz)


def test_the_timeline_data_is_the_runs(run, tmp_path):
    recording, stream, track, rows = run
    write_report(tmp_path / "run.html", recording=recording, stream=stream, track=track, gestures=rows)
    data = js_value(tmp_path / "run_files" / "data.js", "REPORT_DATA")
    assert data["audio"] == {"src": "audio.ogg", "duration": track.duration, "rate": track.rate}
    assert data["duration"] == pytest.approx(max(track.duration, stream.times[-1]), abs=1e-6)
    assert [b["name"] for b in data["behaviours"]] == [r.name for r in recording.behaviours]
    g1 = next(b for b in data["behaviours"] if b["name"] == "b1:g1")
    record = recording.behaviour("b1:g1")
    assert g1["sync"] == list(record.sync_ids) and g1["t"] == pytest.approx(list(record.times), abs=1e-6)
    heard = recording.speech[0]
    speed = 1 + heard.drift_ppm * 1e-6
    assert data["words"]["text"] == [w.text for w in heard.utterance.words]
    assert data["words"]["t"] == pytest.approx([heard.t0 + w.start * speed for w in heard.utterance.words], abs=1e-6)
    table = data["gestures"]
    assert len(table["rows"]) == len(rows) == 3
    by = {(r[0], r[1]): dict(zip(table["columns"], r)) for r in table["rows"]}
    for row in rows:
        got = by[(row.block, row.behaviour)]
        assert got["word"] == row.word and got["happened_s"] == pytest.approx(row.happened_s, abs=1e-6)
    assert len(data["feedback"]["t"]) == sum(1 for f in recording.feedback if "globalTime" in f)


def test_a_run_without_sound_or_motion_says_so(run, tmp_path):
    recording, _, _, rows = run
    path = write_report(tmp_path / "bare.html", recording=recording, gestures=rows)
    folder = tmp_path / "bare_files"
    text = " ".join(parse(path).text)
    assert "no sound in this run" in text and "no motion in this run" in text
    assert not (folder / "poses.js").exists() and not list(folder.glob("audio.*"))
    assert parse(path).sources == [f"bare_files/{n}" for n in ("three.min.js", "data.js", "report.js")]
    data = js_value(folder / "data.js", "REPORT_DATA")
    assert data["audio"] is None and data["motion"] is None and data["gestures"]["rows"]
    # written again over the full report, the stale files go
    write_report(tmp_path / "full.html", recording=recording, stream=run[1], track=run[2])
    write_report(tmp_path / "full.html", recording=recording)
    assert not (tmp_path / "full_files" / "poses.js").exists()
    assert not (tmp_path / "full_files" / "audio.ogg").exists()
    # an empty track is no sound
    write_report(tmp_path / "empty.html", recording=recording, track=Track(np.zeros(0, np.float32), 22050))
    assert "no sound in this run" in (tmp_path / "empty.html").read_text()


def test_audio_falls_back_to_wav(run, tmp_path, monkeypatch):
    recording, _, track, _ = run
    monkeypatch.setattr(soundfile, "check_format", lambda *a, **k: False)
    path = write_report(tmp_path / "run.html", recording=recording, track=track)
    assert 'src="run_files/audio.wav"' in path.read_text()
    info = soundfile.info(tmp_path / "run_files" / "audio.wav")
    assert info.frames == len(track.samples) and info.samplerate == track.rate


def test_a_track_written_stretch_by_stretch_is_the_track_written_whole(run, tmp_path):
    """A mix longer than several stretches, written as a TrackStream (never held whole), gives the WAV and
    the report's audio that the whole track gives."""
    recording, _, _, _ = run
    rng = np.random.default_rng(5)
    rate = 8000
    speech = rng.uniform(-0.9, 0.9, int(2.7 * MIX_CHUNK)).astype(np.float32)
    sources = [Source(speech, rate, 0.0137, 1.0 + 60e-6, None, None, "speech"),
               Source(speech[::3].copy(), rate, 40.0, 1.0, 200.0, lambda t: 1.5, "loud")]
    whole, stream = mix(sources, rate), mix_stream(sources, rate)
    assert stream.length == whole.length and stream.duration == whole.duration and stream.labels == whole.labels
    assert np.array_equal(np.concatenate(list(stream.stretches())), whole.samples)
    assert np.max(np.abs(whole.samples)) == 1.0  # clipped where the two overlap
    write_wav(tmp_path / "whole.wav", whole)
    write_wav(tmp_path / "stream.wav", stream)
    assert (tmp_path / "whole.wav").read_bytes() == (tmp_path / "stream.wav").read_bytes()
    for name, track in (("whole", whole), ("stream", stream)):
        write_report(tmp_path / f"{name}.html", recording=recording, track=track)
    a, _ = soundfile.read(tmp_path / "whole_files" / "audio.ogg", dtype="float32")
    b, _ = soundfile.read(tmp_path / "stream_files" / "audio.ogg", dtype="float32")
    assert len(a) == whole.length and np.array_equal(a, b)
    assert (tmp_path / "whole_files" / "audio.ogg").read_bytes() == (tmp_path / "stream_files" / "audio.ogg").read_bytes()


def ogg_pages(data: bytes) -> list[bytes]:
    pages, at = [], 0
    while at < len(data):
        assert data[at:at + 4] == b"OggS"
        n = data[at + 26]
        end = at + 27 + n + sum(data[at + 27:at + 27 + n])
        pages.append(data[at:end])
        at = end
    return pages


def test_the_reports_sound_is_the_same_bytes_every_time_and_its_pages_check(tmp_path):
    """libsndfile numbers an Ogg stream from the clock: the report's sound gets a fixed serial number, and each
    page the CRC Ogg's own (the one libsndfile writes) for it, so that one track is always the same file."""
    track = Track(np.random.default_rng(3).uniform(-0.5, 0.5, 60000).astype(np.float32), 16000)
    soundfile.write(tmp_path / "plain.ogg", track.samples, 16000, format="OGG", subtype="VORBIS")
    plain = ogg_pages((tmp_path / "plain.ogg").read_bytes())
    for page in plain:  # the CRC libsndfile wrote is the one computed here
        assert report_page.ogg_page_crc(page[:22] + bytes(4) + page[26:]) == int.from_bytes(page[22:26], "little")
    files = []
    for k in range(2):
        (tmp_path / str(k)).mkdir()
        assert report_page.write_audio(tmp_path / str(k), track) == "audio.ogg"
        files.append((tmp_path / str(k) / "audio.ogg").read_bytes())
    assert files[0] == files[1]
    pages = ogg_pages(files[0])
    assert len(pages) == len(plain) >= 3
    for page, before in zip(pages, plain):  # only the serial number and the CRC differ from libsndfile's
        assert int.from_bytes(page[14:18], "little") == report_page.OGG_SERIAL
        assert page[:14] + page[18:22] + page[26:] == before[:14] + before[18:22] + before[26:]
        assert report_page.ogg_page_crc(page[:22] + bytes(4) + page[26:]) == int.from_bytes(page[22:26], "little")
    heard, rate = soundfile.read(tmp_path / "0" / "audio.ogg", dtype="float32")
    assert rate == 16000 and np.array_equal(heard, soundfile.read(tmp_path / "plain.ogg", dtype="float32")[0])


def test_frames_sent_are_at_most_30_per_second():
    body = Body()
    for fps, step in ((60.0, 2), (30.0, 1), (25.0, 1), (100.0, 4), (120.0, 4)):
        n = int(fps * 10)
        stream = PoseStream(np.arange(n) / fps, list(body.dof_names), np.tile(body.rest_pose(), (n, 1)), [],
                            np.zeros((n, 0, 3)), fps, body)
        frames = report_data.report_frames(stream)
        assert np.array_equal(frames[:-1], np.arange(0, n, step)[: len(frames) - 1]), fps
        assert frames[-1] == n - 1
        assert len(frames) / 10.0 <= 30.0 + 0.1
        assert set(report_data.report_frames(stream, keep=[1.2345]).tolist()) - set(frames.tolist()) <= \
            {int(np.floor(1.2345 * fps)), int(np.ceil(1.2345 * fps))}


def test_a_long_run_is_sent_small(tmp_path):
    """6.7 minutes at 60 fps on the 63-joint body (hands of 15 joints each): the positions go as base64 of two
    bytes a coordinate (about 7.6 MB), 30 frames a second, and the page's data file stays out of the HTML."""
    body = Body()
    fps, seconds = 60.0, 402.0
    n = int(seconds * fps)
    t = np.arange(n) / fps
    values = np.tile(body.rest_pose(), (n, 1))
    for k, dof in enumerate(("r_shoulder.pitch", "r_elbow.pitch", "l_shoulder.pitch", "skullbase.pitch")):
        values[:, body.dof_index[dof]] += 20 * np.sin(2 * np.pi * (0.3 + 0.1 * k) * t)
    stream = PoseStream(t, list(body.dof_names), values, [], np.zeros((n, 0, 3)), fps, body)
    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit(BML)
    realizer.run()
    path = write_report(tmp_path / "long.html", recording=realizer.recording(), stream=stream)
    poses = (tmp_path / "long_files" / "poses.js").stat().st_size
    points = len(report_data.point_names(body)[0])
    expected = (n // 2 + 1) * points * 3 * 2 * 4 / 3
    assert len(body.joints) == 63 and poses < expected * 1.02 + 100_000
    assert path.stat().st_size < 8000
    frames, xyz = report_data.decode_poses(report_data.read_js_assignment(
        (tmp_path / "long_files" / "poses.js").read_text(), "REPORT_POSES"))
    wrist = report_data.point_positions(stream, frames)[:, [j.name for j in body.joints].index("r_wrist")]
    assert np.abs(xyz[:, [j.name for j in body.joints].index("r_wrist")] - wrist).max() <= 0.0005 + 1e-9


def test_the_vendored_files_are_package_data():
    """pip installs the page's files with the package: pyproject's package-data names them."""
    import tomllib

    root = Path(__file__).resolve().parent.parent
    config = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    patterns = config.get("agentsim.media.report", [])
    here = report_page.HERE
    for name in ("vendor/three.min.js", "vendor/LICENSE-three.txt", "assets/report.js", "assets/report.css"):
        assert (here / name).exists(), name
        assert any(Path(name).match(p) for p in patterns), name


def test_poses_written_a_stretch_at_a_time_are_the_payload_written_whole(run, tmp_path, monkeypatch):
    """poses.js written a stretch of frames at a time (here 7 frames a stretch) is the text of the whole
    payload, and its stream evaluated into files gives the same text."""
    import agentsim.animation.body as body_module

    recording, stream, _, gestures = run
    keep = report_data.stroke_times(recording, gestures)
    whole = report_data.js_assignment("REPORT_POSES", report_data.pose_payload(stream, keep=keep), "poses")
    monkeypatch.setattr(body_module, "FK_ROWS", 7)
    payload = report_data.write_poses(tmp_path / "poses.js", stream, "poses", keep=keep)
    assert (tmp_path / "poses.js").read_text(encoding="utf-8") == whole
    assert "xyz" not in payload and payload["count"] > 7 * 3
    stored = evaluate_poses(recording, fps=60, folder=tmp_path / "frames")
    report_data.write_poses(tmp_path / "stored.js", stored, "poses", keep=keep)
    assert (tmp_path / "stored.js").read_text(encoding="utf-8") == whole


def test_a_report_whose_sound_was_started_before_is_the_report_written_at_once(run, tmp_path):
    """The sound begun beforehand (start_audio, on an executor of the caller's) gives the same page, data and
    sound as the report that encodes its track itself; an old sound in the folder is replaced."""
    import concurrent.futures

    from agentsim.media.report.page import start_audio

    recording, stream, track, gestures = run
    write_report(tmp_path / "a.html", recording=recording, stream=stream, track=track, gestures=gestures, title="t")
    (tmp_path / "b_files").mkdir()
    (tmp_path / "b_files" / "audio.wav").write_bytes(b"old")
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        audio = start_audio(tmp_path / "b", track, pool)
        write_report(tmp_path / "b", recording=recording, stream=stream, track=track, gestures=gestures, title="t",
                     audio=audio)
    a, b = tmp_path / "a_files", tmp_path / "b_files"
    assert sorted(p.name for p in a.iterdir()) == sorted(p.name for p in b.iterdir())
    assert (a / "data.js").read_text() == (b / "data.js").read_text()
    assert (a / "poses.js").read_text().replace("'t'", "") == (b / "poses.js").read_text().replace("'t'", "")
    sound = next(p.name for p in a.iterdir() if p.name.startswith("audio."))
    assert np.array_equal(soundfile.read(a / sound)[0], soundfile.read(b / sound)[0])
    assert (tmp_path / "a.html").read_text().replace("a_files", "") == (tmp_path / "b.html").read_text().replace(
        "b_files", "")
