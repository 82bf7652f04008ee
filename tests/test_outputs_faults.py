"""Outputs that are whole or absent, inputs that cannot exhaust the machine: kill -9 at random points of a
storyteller run and of a sweep, a full disk (a small tmpfs), read-only folders, device nodes, FIFOs,
planted symbolic links and inputs named as outputs; inputs past their limit and runs whose files would be
larger than a file may be or than the disk holds.

The storyteller's kill loop runs 3 times in the default suite and 20 times with ``-m system``; the sweep's
(a local cluster started each time) 3 and 20 times with ``-m system`` only. The kill times come from a seeded
numpy Generator, spread over the length of a whole run measured first."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from agentsim.written import staged_folder, written
from agentsim.errors import UsageError

ROOT = Path(__file__).resolve().parents[1]
TINY = ("@title Tiny\n[gaze:audience]Long [beat]ago, the [point:left]North Wind and the Sun had a [brows]quarrel. "
        "Each of them\n[beat]said that he was the [beat:both]stronger.\n")
GOOD = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1" characterId="agent">'
        '<gesture id="g1" lexeme="BEAT" start="{start}"/></bml>')


def env() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT))


def cli(*args: str, cwd: Path, stdin=None, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "agentsim", *args], capture_output=True, text=True, cwd=cwd,
                          env=env(), stdin=stdin, timeout=timeout)


def one_line(proc: subprocess.CompletedProcess) -> str:
    lines = [line for line in proc.stderr.splitlines() if line.startswith("agentsim:")]
    assert len(lines) == 1 and "internal error" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    return lines[0]


# ----------------------------------------------------------------------------------------------------
# One way to write: devices, FIFOs, folders, inputs, planted links.


def test_a_device_a_fifo_or_a_folder_is_refused_as_a_file(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    for path, kind in ((Path("/dev/null"), "a character device"), (fifo, "a FIFO"), (tmp_path, "a folder")):
        with pytest.raises(UsageError, match=kind):
            with written(path) as tmp:
                tmp.write_text("never")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode) and stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_the_command_line_refuses_a_device_or_the_input_as_output_before_work(tmp_path):
    bml = tmp_path / "good.xml"
    bml.write_text(GOOD.format(start=0))
    before = bml.read_bytes()
    (tmp_path / "link.bvh").symlink_to(bml)
    for target, said in (("/dev/null", "it is a character device, not a file (name a regular file)"), ("good.xml", "it is one of the run's inputs"),
                         ("link.bvh", "it is one of the run's inputs")):
        proc = cli("realize", "--tts", "builtin", "--bvh", target, "good.xml", cwd=tmp_path)
        assert proc.returncode == 2 and not proc.stdout  # nothing ran
        assert one_line(proc) == f"agentsim: cannot write {target}: {said}"
    assert bml.read_bytes() == before and stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_a_device_where_a_run_folder_is_meant_is_refused_as_not_a_folder(tmp_path):
    os.mkfifo(tmp_path / "pipe")
    for target, kind in (("/dev/null", "a character device"), ("pipe", "a FIFO")):
        proc = cli("run", "storytelling", "--tts", "builtin", "--no-cache", "--out", target, cwd=tmp_path)
        assert proc.returncode == 2 and not proc.stdout
        assert one_line(proc) == f"agentsim: cannot write {target}: it is {kind}, not a folder (name a folder)"
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode) and stat.S_ISFIFO(os.stat(tmp_path / "pipe").st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]


def test_a_planted_link_at_a_temporary_name_is_not_followed(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("mine")
    # the names the old writer used, and a spread of guesses at the new random ones
    for name in [f".metrics.partial-{os.getpid()}.json"] + [f".metrics.partial-{i:08x}.json" for i in range(64)]:
        (tmp_path / name).symlink_to(victim)
    names = set()
    for text in ("one", "two"):
        with written(tmp_path / "metrics.json") as tmp:
            names.add(tmp.name)
            assert not tmp.is_symlink() and tmp.stat().st_size == 0 and tmp.stat().st_nlink == 1
            tmp.write_text(text)
    assert victim.read_text() == "mine" and (tmp_path / "metrics.json").read_text() == "two" and len(names) == 2


def test_a_run_folder_is_never_one_that_holds_someone_elses_files_or_the_input(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("years of work")
    with pytest.raises(UsageError, match="not an agentsim run's"):
        with staged_folder(tmp_path / "mine"):
            pass
    story = tmp_path / "st" / "tiny.story"
    story.parent.mkdir()
    story.write_text(TINY)
    proc = cli("run", "storytelling", "--story", str(story), "--tts", "builtin", "--no-cache", "--out", "st",
               cwd=tmp_path)
    assert proc.returncode == 2 and "holds the run's input" in one_line(proc)
    assert (tmp_path / "mine" / "thesis.tex").read_text() == "years of work" and story.read_text() == TINY


# ----------------------------------------------------------------------------------------------------
# Weigh before reading.


def test_endless_standard_input_is_refused_in_one_line(tmp_path):
    with open("/dev/zero", "rb") as zero:
        proc = cli("realize", "--tts", "builtin", "-", cwd=tmp_path, stdin=zero)
    assert proc.returncode == 2 and not proc.stdout
    assert one_line(proc) == "agentsim: the BML document on standard input is longer than 8 MB: at most 8 MB is read"


def test_a_huge_file_is_refused_from_its_size_without_being_read(tmp_path):
    big = tmp_path / "big.xml"
    with open(big, "wb") as f:
        f.truncate(2 * 1024 ** 3)  # 2 GB, sparse
    proc = cli("realize", "--tts", "builtin", "big.xml", cwd=tmp_path)
    assert proc.returncode == 2
    assert one_line(proc) == "agentsim: the BML document big.xml is 2048.0 MB long: at most 8 MB is read"
    taps = tmp_path / "taps.txt"
    with open(taps, "wb") as f:
        f.truncate(9 * 1024 * 1024)
    from anticipators.tap import read_taps

    with pytest.raises(UsageError, match="9.0 MB long: at most 8 MB is read"):
        read_taps(taps)


def test_a_huge_lexicon_tap_file_or_linear_model_is_refused_unread_in_one_line(tmp_path):
    """Every file a command line names is weighed before it is read: a 2 GB lexicon, tap file, linear model or
    story TextGrid is refused from its size (exit 2), where the lexicon and the model were read whole (4.2 GB;
    the model then ended in an internal error) and the TextGrid parsed for 50 s (7.4 GB); a model that is not
    one is one line too."""
    (tmp_path / "g.xml").write_text(GOOD.format(start=0))
    with open(tmp_path / "big", "wb") as f:
        f.truncate(2 * 1024 ** 3)  # sparse
    (tmp_path / "big.TextGrid").symlink_to(tmp_path / "big")
    for args, said in ((["realize", "--tts", "builtin", "--lexicon", "big", "g.xml"], "the lexicon big"),
                       (["realize", "--tts", "builtin", "--anticipator", "tap:t,taps=big", "g.xml"],
                        "the tap file 'big'"),
                       (["eval", "speech-sync", "--tts", "builtin", "--model", "big"], "the linear model 'big'"),
                       (["run", "storytelling", "--tts", "builtin", "--no-cache", "--story", "big.TextGrid", "--out",
                         "st"], "the TextGrid 'big.TextGrid'")):
        proc = cli(*args, cwd=tmp_path, timeout=60)
        assert proc.returncode == 2 and not proc.stdout, args
        assert one_line(proc) == f"agentsim: {said} is 2048.0 MB long: at most 8 MB is read"
    (tmp_path / "m.json").write_text('{"offset": 0.1}')
    proc = cli("eval", "speech-sync", "--tts", "builtin", "--model", "m.json", cwd=tmp_path)
    assert proc.returncode == 2 and one_line(proc).startswith(
        "agentsim: the linear model 'm.json' is not one 'agentsim speech calibrate' writes (")
    (tmp_path / "lexicon.toml").write_bytes(b"\xff\xfe")
    proc = cli("realize", "--tts", "builtin", "--lexicon", "lexicon.toml", "g.xml", cwd=tmp_path)
    assert proc.returncode == 2 and one_line(proc).startswith(
        "agentsim: cannot read the lexicon lexicon.toml: it is not UTF-8 text")
    proc = cli("realize", "--tts", "builtin", "--anticipator", "tap:t,taps=none.txt", "g.xml", cwd=tmp_path)
    assert proc.returncode == 2 and one_line(proc) == "agentsim: no tap file 'none.txt'"


# ----------------------------------------------------------------------------------------------------
# Writers that do not allocate the whole timeline.


def test_a_behaviour_a_million_seconds_in_is_refused_by_its_projected_size(tmp_path):
    (tmp_path / "far.xml").write_text(GOOD.format(start=999999))
    proc = cli("realize", "--tts", "builtin", "--bvh", "far.bvh", "far.xml", cwd=tmp_path)
    assert proc.returncode == 2
    line = one_line(proc)
    # 1000001 s at 60 fps: 60000061 frames of the body's channels, 10 bytes a value
    from agentsim.animation.body import Body

    size = 60000061 * Body().n_dofs * 10 / 1024 ** 3
    assert line == (f"agentsim: --bvh far.bvh: the run lasts 1000000 s, so the file would take {size:.1f} GiB, more "
                    f"than the 4.0 GiB a run's file may take (a WAV cannot hold more): move what starts that late "
                    f"sooner")
    assert not list(tmp_path.glob("*.bvh")) and not list(tmp_path.glob(".*partial*"))


def test_a_speech_a_million_seconds_in_is_refused_with_wav_and_report_by_their_projected_size(tmp_path):
    """espeak-ng's speech at 999,999 s (the mixer had tried to allocate 82 GiB): --wav and --report are refused
    from their projected sizes, in one line, before anything is written; the feedback of the run was printed."""
    (tmp_path / "far.xml").write_text('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1"><speech '
                                      'id="s" start="999999"><text>Hello there.</text></speech></bml>')
    for flag, name, size in (("--wav", "far.wav", "41.1 GiB"), ("--report", "far.html", "50.5 GiB")):
        proc = cli("realize", "--tts", "espeak", flag, name, "far.xml", cwd=tmp_path)
        assert proc.returncode == 2
        assert one_line(proc) == (f"agentsim: {flag} {name}: the run lasts 1000000 s, so the file would take {size}, "
                                  f"more than the 4.0 GiB a run's file may take (a WAV cannot hold more): move what "
                                  f"starts that late sooner")
        assert '"id": "b1:s:end"' in proc.stdout
        assert sorted(p.name for p in tmp_path.iterdir()) == ["far.xml"]


def test_a_late_gesture_and_a_long_speech_are_evaluated_a_window_at_a_time(tmp_path, monkeypatch):
    """The empty stretch before a gesture at 100 s and a speech of a minute are segments of thousands of frames
    with no event inside: evaluated into files with a window of 50 frames, no tick spans more than 50 frames
    and the arbitrator never holds more than three windows of rows; the poses are those evaluated whole."""
    import agentsim.animation.output as output
    from agentsim.animation import evaluate_poses
    from agentsim.animation.arbitrator import Arbitrator
    from agentsim.realizer import Realizer
    from speech_timing.builtin import BuiltinBackend

    realizer = Realizer(tts=BuiltinBackend())
    realizer.submit('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1"><speech id="s" start="5"><text>'
                    + "Bob met a man, papa. " * 40 + '</text></speech><gesture id="g" lexeme="BEAT" start="100"/></bml>')
    realizer.run()
    assert realizer.recording().sync_times()["b1:s:end"] > 60
    whole = evaluate_poses(realizer, fps=60, seed=1)
    held, spans = [], []
    tick = Arbitrator.tick_segment

    def watched(self, lo, hi, times, drivers):
        spans.append(hi - lo)
        tick(self, lo, hi, times, drivers)
        held.append(len(self.values))

    monkeypatch.setattr(Arbitrator, "tick_segment", watched)
    monkeypatch.setattr(output, "FK_ROWS", 50)
    stored = evaluate_poses(realizer, fps=60, seed=1, folder=tmp_path / "poses")
    assert stored.n_frames == whole.n_frames > 6000
    assert max(spans) == 50 and max(held) <= 150
    assert np.array_equal(stored.values, whole.values) and np.array_equal(stored.positions, whole.positions)


def test_a_long_speech_written_as_bvh_costs_memory_by_its_length_not_its_square(tmp_path):
    """1,500 words (some 7 minutes, 25,000 frames) with --bvh: the speaking mouth's visemes weighed near each
    frame only and the speech ticked a window at a time, the command peaks under 400 MB (it took 1.1 GB when
    every frame weighed every phoneme; 12,000 words took 17 GB and now take 220 MB)."""
    words = "the quick brown fox jumps over a lazy dog and then".split()
    text = " ".join(f'{words[i % 11]}{"." if i % 11 == 10 else ""}' for i in range(1500))
    (tmp_path / "long.xml").write_text('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1"><speech '
                                       f'id="s"><text>{text}</text></speech></bml>')
    measure = ("import resource, subprocess, sys; code = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL)"
               ".returncode; print(code, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
    proc = subprocess.run([sys.executable, "-c", measure, sys.executable, "-m", "agentsim", "realize", "--tts",
                           "builtin", "--bvh", "long.bvh", "long.xml"], capture_output=True, text=True, cwd=tmp_path,
                          env=env(), timeout=300)
    code, peak_kb = map(int, proc.stdout.split())
    assert code == 0, proc.stderr
    frames = int((tmp_path / "long.bvh").read_text().split("Frames: ", 1)[1].split("\n", 1)[0])
    assert frames > 25000
    assert peak_kb < 400 * 1024, peak_kb


@contextlib.contextmanager
def tmpfs(where: Path, size: str, read_only: bool = False):
    where.mkdir()
    options = f"size={size}" + (",ro" if read_only else "")
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)], capture_output=True,
                          text=True)
    if made.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {made.stderr.strip() or made.returncode}")
    try:
        yield where
    finally:
        subprocess.run(["umount", str(where)], check=True)


def test_a_full_disk_is_said_before_writing_and_leaves_nothing(tmp_path):
    (tmp_path / "g.xml").write_text(GOOD.format(start=500))
    with tmpfs(tmp_path / "small", "2m") as small:
        proc = cli("realize", "--tts", "builtin", "--bvh", "small/x.bvh", "g.xml", cwd=tmp_path)
        assert proc.returncode == 1
        line = one_line(proc)
        assert line.startswith("agentsim: not enough disk space for --bvh small/x.bvh: the run lasts 501 s, so "
                               "they would take ") and line.endswith(f"and {small} has 2.0 MiB free")
        assert os.listdir(small) == []
        # a file that does fit, but not beside its temporary copy: the old one stays whole
        (small / "old.txt").write_text("old")
        with pytest.raises(OSError):
            with written(small / "old.txt") as tmp, open(tmp, "wb") as f:
                f.write(b"x" * 4 * 1024 * 1024)
        assert (small / "old.txt").read_text() == "old" and os.listdir(small) == ["old.txt"]


def test_a_read_only_folder_is_said_before_work(tmp_path):
    (tmp_path / "tiny.story").write_text(TINY)
    with tmpfs(tmp_path / "ro", "1m", read_only=True):
        proc = cli("run", "storytelling", "--story", "tiny.story", "--tts", "builtin", "--no-cache",
                   "--out", "ro/st", cwd=tmp_path)
        assert proc.returncode == 2
        assert one_line(proc).startswith("agentsim: cannot make the output folder ro/st: ")


# ----------------------------------------------------------------------------------------------------
# Sweeps.


def test_usage_errors_of_a_sweep_and_a_seed_are_one_line_before_work(tmp_path):
    # a usage error is one line, as every error is (no usage block above it), and nothing runs
    for command in (["eval", "speech-sync"], ["realize", "g.xml"], ["run", "storytelling"]):
        proc = cli(*command, "--tts", "builtin", "--seed", "-1", cwd=tmp_path)
        assert proc.returncode == 2 and proc.stdout == "" and not list(tmp_path.iterdir())
        assert proc.stderr == (f"agentsim {command[0]} {command[1] if command[0] != 'realize' else ''}".rstrip()
                               + ": error: argument --seed: a seed is a whole number from 0, got -1\n")
    negative = tmp_path / "negative.toml"
    negative.write_text('command = ["eval", "speech-sync"]\n[grid]\nseed = [0, -1]\n[fixed]\ntts = "builtin"\n')
    proc = cli("sweep", "negative.toml", "--out", "sw", "--quiet", cwd=tmp_path)
    assert proc.returncode == 2 and not (tmp_path / "sw").exists()
    assert proc.stderr == ("agentsim: sweep spec 'negative.toml': argument --seed: a seed is a whole number from 0, "
                           "got -1 (at seed=-1)\n")
    spec = tmp_path / "big.toml"
    spec.write_text('command = ["eval", "speech-sync"]\n[grid]\nseed = ' + json.dumps(list(range(1000)))
                    + '\njitter = ' + json.dumps([i / 1000 for i in range(11)]) + '\n[fixed]\ntts = "builtin"\n')
    proc = cli("sweep", "big.toml", "--out", "sw", "--quiet", cwd=tmp_path)
    assert proc.returncode == 2 and not (tmp_path / "sw").exists()
    assert one_line(proc) == ("agentsim: sweep spec 'big.toml': the grid makes 11000 points, more than the 10000 a "
                              "sweep runs without --max-points N (give --max-points 11000 to run them all)")
    proc = cli("sweep", "big.toml", "--out", "sw", "--max-points", "100", "--quiet", cwd=tmp_path)
    assert proc.returncode == 2 and "more than the 100 a sweep runs with this --max-points" in one_line(proc)


def test_the_local_cluster_talks_tls_and_refuses_a_client_without_its_credentials():
    distributed = pytest.importorskip("distributed")
    from agentsim.cli.sweep.runner import connect

    with connect(1, None) as client:
        address = client.scheduler.address
        assert address.startswith("tls://127.0.0.1:")
        assert client.submit(os.getpid).result(timeout=30) != os.getpid()  # the credentials work
        with pytest.raises((OSError, TimeoutError, ValueError, TypeError)):
            distributed.Client(address, timeout="3s")  # no certificate: no connection


def test_a_lost_worker_is_said_on_stderr_and_counted_in_the_attempts(tmp_path, monkeypatch, capsys):
    """A sweep of two points whose first task kills its worker's process: the scheduler runs it again on another
    worker, the sweep says so on stderr, and results.csv counts 2 attempts for it and 1 for the other."""
    pytest.importorskip("distributed")
    import pandas as pd

    from agentsim.cli.sweep import runner, spec

    mark = tmp_path / "died-once"

    def dies_once(argv, out_at, keep, path=str(mark)):
        try:  # created at once or not at all: of two tasks that start together, only one dies
            os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            pass
        else:
            os._exit(1)  # the worker's process dies under the task
        from agentsim.cli.sweep.point import run_point

        return run_point(argv, out_at, keep)

    (tmp_path / "spec.toml").write_text('command = ["eval", "speech-sync"]\n[grid]\nseed = [0, 1]\n'
                                        '[fixed]\ntts = "builtin"\n')
    monkeypatch.setattr(runner, "run_point", dies_once)
    outcome = runner.run(spec.load(tmp_path / "spec.toml"), tmp_path / "sw", workers=2, quiet=True)
    assert (outcome.points, outcome.failed) == (2, 0)
    said = [line for line in capsys.readouterr().err.splitlines() if line.startswith("agentsim:")]
    assert said == ["agentsim: a worker was lost under 1 point, run again on another worker (the 'attempts' "
                    "column of results.csv counts the runs)"]
    table = pd.read_csv(tmp_path / "sw" / "results.csv")
    assert list(table["status"]) == ["ok", "ok"] and sorted(table["attempts"]) == [1, 2]


# ----------------------------------------------------------------------------------------------------
# kill -9 at random points.


def digest(folder: Path) -> dict | None:
    """What identifies a complete storyteller run in ``folder``: its seed and the digests of the files that
    depend on it only; None if the folder is missing or any file is not whole."""
    if not folder.is_dir():
        return None
    names = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
    try:
        metrics = json.loads((folder / "metrics.json").read_text())
        for line in (folder / "feedback.jsonl").read_text().splitlines():
            json.loads(line)
        for png in folder.glob("*.png"):
            assert png.read_bytes()[-8:-4] == b"IEND"
        bvh = (folder / "story.bvh").read_text()
        frames = int(bvh.split("Frames: ", 1)[1].split("\n", 1)[0])
        assert len(bvh.split("Frame Time: ", 1)[1].strip().splitlines()) == frames + 1
        assert (folder / "report.html").read_text().rstrip().endswith("</html>")
    except (OSError, ValueError, IndexError, AssertionError, KeyError):
        return None
    return {"names": names, "seed": metrics["seed"],
            **{n: hashlib.sha256((folder / n).read_bytes()).hexdigest() for n in ("story.bvh", "feedback.jsonl",
                                                                                 "gestures.csv", "story.bml")}}


def story_command(seed: int) -> list[str]:
    return [sys.executable, "-m", "agentsim", "run", "storytelling", "--story", "tiny.story", "--tts", "builtin",
            "--no-cache", "--seed", str(seed), "--out", "st"]


def killed_after(command: list[str], cwd: Path, seconds: float) -> int | None:
    """Run ``command`` in a process group of its own and kill -9 the group after ``seconds``; its exit status
    if it ended first, else None."""
    proc = subprocess.Popen(command, cwd=cwd, env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        return proc.wait(timeout=seconds)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        return None


def storyteller_kills(tmp_path: Path, runs: int, seed: int = 28) -> dict:
    """A complete run (seed 1), then ``runs`` runs of seed 2 killed at random times, then one run of seed 2
    to the end; returns what was seen after each kill."""
    (tmp_path / "tiny.story").write_text(TINY)
    started = time.perf_counter()
    assert subprocess.run(story_command(1), cwd=tmp_path, env=env(), capture_output=True).returncode == 0
    whole = time.perf_counter() - started
    first = digest(tmp_path / "st")
    assert first is not None and first["seed"] == 1
    rng = np.random.default_rng(seed)
    seen = []
    for at in rng.uniform(0.0, whole * 1.1, runs):
        before = digest(tmp_path / "st")
        status = killed_after(story_command(2), tmp_path, at)
        seen.append({"at": at, "status": status, "before": before, "digest": digest(tmp_path / "st"),
                     "beside": sorted(p.name for p in tmp_path.iterdir() if p.name not in ("tiny.story", "st")),
                     "inside": sorted(p.name for p in (tmp_path / "st").iterdir() if p.name.startswith("."))})
    assert subprocess.run(story_command(2), cwd=tmp_path, env=env(), capture_output=True).returncode == 0
    second = digest(tmp_path / "st")
    assert second is not None and second["seed"] == 2
    leftovers = sorted(p.name for p in tmp_path.iterdir() if p.name not in ("tiny.story", "st"))
    return {"first": first, "second": second, "seen": seen, "leftovers": leftovers, "whole_s": whole}


def check_storyteller(outcome: dict) -> None:
    for kill in outcome["seen"]:
        assert kill["digest"] in (kill["before"], outcome["second"]), kill  # the old run or the new, whole
        assert kill["status"] in (None, 0), kill
        assert all(name.startswith(".st.staging-") for name in kill["beside"]), kill  # the rest is staged
        assert kill["inside"] == [], kill
    assert outcome["leftovers"] == []  # the next run cleared what the killed ones staged


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_a_killed_storyteller_leaves_the_old_run_or_the_new_whole(tmp_path):
    check_storyteller(storyteller_kills(tmp_path, runs=3))


@pytest.mark.system
def test_twenty_killed_storytellers(tmp_path):
    outcome = storyteller_kills(tmp_path, runs=20)
    check_storyteller(outcome)
    assert any(k["status"] is None for k in outcome["seen"])  # the loop did kill runs midway


SPEC = 'command = ["eval", "speech-sync"]\n[grid]\nseed = [0, 1, 2, 3]\n[fixed]\ntts = "builtin"\n'


def sweep_state(folder: Path) -> dict:
    """What a sweep's folder holds: whether results.csv is whole (all rows) or absent, and its points."""
    import pandas as pd

    state = {"csv": None, "points": 0, "bad_points": 0, "hidden": []}
    if (folder / "results.csv").exists():
        state["csv"] = len(pd.read_csv(folder / "results.csv"))
    for path in (folder / "points").glob("*.json") if (folder / "points").is_dir() else []:
        try:
            assert json.loads(path.read_text())["status"] == "ok"
            state["points"] += 1
        except (ValueError, KeyError, AssertionError):
            state["bad_points"] += 1
    state["hidden"] = sorted(p.name for p in folder.rglob(".*")) if folder.is_dir() else []
    return state


def sweep_kills(tmp_path: Path, runs: int, seed: int = 28) -> dict:
    """A whole sweep (timed), then ``runs`` sweeps into the same folder (emptied first half of the time)
    killed at random times, then one to the end; returns what was seen after each kill."""
    import shutil

    (tmp_path / "spec.toml").write_text(SPEC)
    command = [sys.executable, "-m", "agentsim", "sweep", "spec.toml", "--workers", "1", "--out", "sw", "--quiet"]
    started = time.perf_counter()
    assert subprocess.run(command, cwd=tmp_path, env=env(), capture_output=True).returncode == 0
    whole = time.perf_counter() - started
    rng = np.random.default_rng(seed)
    seen = []
    for at in rng.uniform(0.0, whole, runs):
        if rng.random() < 0.5:
            shutil.rmtree(tmp_path / "sw", ignore_errors=True)  # absent if the last kill came before it
        status = killed_after(command, tmp_path, at)
        seen.append({"at": at, "status": status, **sweep_state(tmp_path / "sw")})
    done = subprocess.run(command, cwd=tmp_path, env=env(), capture_output=True, text=True)
    return {"seen": seen, "final": sweep_state(tmp_path / "sw"), "final_status": done.returncode, "whole_s": whole}


def check_sweep(outcome: dict) -> None:
    for kill in outcome["seen"]:
        assert kill["csv"] in (None, 4) and kill["bad_points"] == 0, kill  # results whole or absent
        assert all(".partial-" in name for name in kill["hidden"]), kill  # hidden: only temporaries
    assert outcome["final_status"] == 0
    assert outcome["final"] == {"csv": 4, "points": 4, "bad_points": 0, "hidden": []}  # cleared, whole


@pytest.mark.system  # a local cluster started four times: about a minute
def test_a_killed_sweep_leaves_whole_results_or_none(tmp_path):
    check_sweep(sweep_kills(tmp_path, runs=3))


@pytest.mark.system
def test_twenty_killed_sweeps(tmp_path):
    check_sweep(sweep_kills(tmp_path, runs=20))


# ----------------------------------------------------------------------------------------------------
# realize --report (and --bvh) under kill -9: the page and its folder whole or absent as a pair.


def report_document(gestures: int) -> str:
    beats = "".join(f'<gesture id="g{i}" lexeme="BEAT" start="{i}"/>' for i in range(gestures))
    return f'<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1" characterId="agent">{beats}</bml>'


def report_command(document: str) -> list[str]:
    return [sys.executable, "-m", "agentsim", "realize", "--tts", "builtin", "--report", "out/run.html",
            "--bvh", "out/run.bvh", document]


def report_state(folder: Path) -> dict:
    """What ``folder`` holds of a report: the run its page is of (the page's title, when the page is whole
    and its folder's data, poses and every file it loads are of the same run: else ``"mismatch"``), None
    without a page; the BVH's frames (None if absent, -1 if not whole); the hidden names beside them."""
    import re

    from agentsim.media.report import data as report_data

    state = {"page": None, "bvh": None, "hidden": sorted(p.name for p in folder.iterdir() if p.name.startswith("."))}
    page, files = folder / "run.html", folder / "run_files"
    if page.exists():
        try:
            text = page.read_text()
            assert text.rstrip().endswith("</html>")
            title = re.search(r"<title>(.*)</title>", text).group(1)
            data = report_data.read_js_assignment((files / "data.js").read_text(), "REPORT_DATA")
            poses = report_data.read_js_assignment((files / "poses.js").read_text(), "REPORT_POSES")
            assert data["title"] == title and data["motion"]["sent"] == poses["count"]
            assert all((folder / src).is_file() for src in re.findall(r'src="([^"]+)"', text))
            state["page"] = title
        except (OSError, ValueError, KeyError, TypeError, AttributeError, AssertionError):
            state["page"] = "mismatch"
    if (folder / "run.bvh").exists():
        bvh = (folder / "run.bvh").read_text()
        try:
            frames = int(bvh.split("Frames: ", 1)[1].split("\n", 1)[0])
            whole = len(bvh.split("Frame Time: ", 1)[1].strip().splitlines()) == frames + 1  # its own line too
        except (IndexError, ValueError):
            whole = False
        state["bvh"] = frames if whole else -1
    return state


def report_kills(tmp_path: Path, runs: int, seed: int = 28) -> dict:
    """A complete report of a.xml, then ``runs`` reports of b.xml over it killed at random times, then one
    to the end; returns what was seen after each kill."""
    (tmp_path / "a.xml").write_text(report_document(12))
    (tmp_path / "b.xml").write_text(report_document(30))
    started = time.perf_counter()
    assert subprocess.run(report_command("a.xml"), cwd=tmp_path, env=env(), capture_output=True).returncode == 0
    whole = time.perf_counter() - started
    first = report_state(tmp_path / "out")
    assert first["page"] == "a.xml" and first["bvh"] > 0 and first["hidden"] == []
    rng = np.random.default_rng(seed)
    seen = []
    for at in rng.uniform(0.0, whole * 1.1, runs):
        before = report_state(tmp_path / "out")["page"]
        seen.append({"at": at, "before": before, "status": killed_after(report_command("b.xml"), tmp_path, at),
                     **report_state(tmp_path / "out")})
    assert subprocess.run(report_command("b.xml"), cwd=tmp_path, env=env(), capture_output=True).returncode == 0
    return {"first": first, "seen": seen, "final": report_state(tmp_path / "out"), "whole_s": whole}


def check_reports(outcome: dict) -> None:
    frames = {outcome["first"]["bvh"], outcome["final"]["bvh"]}
    for kill in outcome["seen"]:
        assert kill["page"] in (None, kill["before"], "b.xml"), kill  # never a page over another run's files
        assert kill["bvh"] in frames, kill  # the old BVH or the new, whole
        assert all(n.startswith((".run_files.staging-", ".run.partial-")) for n in kill["hidden"]), kill
    assert outcome["final"]["page"] == "b.xml" and outcome["final"]["bvh"] > outcome["first"]["bvh"]
    assert outcome["final"]["hidden"] == []  # the next run cleared the staging folders and temporaries


@pytest.mark.system  # a whole scenario, a real-time wait or a long synthesis: the system run
def test_a_killed_report_leaves_the_old_pair_or_the_new(tmp_path):
    check_reports(report_kills(tmp_path, runs=4))


@pytest.mark.system
def test_twenty_killed_reports(tmp_path):
    outcome = report_kills(tmp_path, runs=20)
    check_reports(outcome)
    assert any(k["status"] is None for k in outcome["seen"])  # the loop did kill runs midway


def test_the_poses_scratch_of_a_killed_realize_is_removed_by_the_next_run_and_a_live_one_is_not(tmp_path,
                                                                                                monkeypatch):
    """realize --bvh evaluates the poses into a scratch folder of the temporary folder (here TMPDIR): killed -9
    while it fills it, the folder stays (hundreds of MB for a long run); the next run that makes one removes
    it and leaves nothing there itself, and a scratch folder whose process lives (it holds its lock) is left
    alone."""
    from agentsim.written import scratch_folder

    temporary = tmp_path / "tmp"
    temporary.mkdir()
    words = "the quick brown fox jumps over a lazy dog and then".split()
    text = " ".join(f'{words[i % 11]}{"." if i % 11 == 10 else ""}' for i in range(3000))
    (tmp_path / "long.xml").write_text('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1"><speech '
                                       f'id="s"><text>{text}</text></speech></bml>')
    (tmp_path / "g.xml").write_text(GOOD.format(start=0))
    run_env = {**env(), "TMPDIR": str(temporary)}
    proc = subprocess.Popen([sys.executable, "-m", "agentsim", "realize", "--tts", "builtin", "--bvh", "long.bvh",
                             "long.xml"], cwd=tmp_path, env=run_env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:  # until its poses are being written
            values = list(temporary.glob("agentsim-scratch-poses-*/values.npy"))
            if values and values[0].stat().st_size > 1_000_000:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be killed"
        os.killpg(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    (left,) = temporary.iterdir()
    assert left.name.startswith("agentsim-scratch-poses-") and (left / "values.npy").stat().st_size > 1_000_000
    assert not (tmp_path / "long.bvh").exists()
    import tempfile

    monkeypatch.setenv("TMPDIR", str(temporary))
    monkeypatch.setattr(tempfile, "tempdir", None)  # read TMPDIR again
    with scratch_folder("agentsim-scratch-poses-") as live:
        again = subprocess.run([sys.executable, "-m", "agentsim", "realize", "--tts", "builtin", "--bvh", "g.bvh",
                                "g.xml"], cwd=tmp_path, env=run_env, capture_output=True, text=True, timeout=120)
        assert again.returncode == 0, again.stderr
        assert list(temporary.iterdir()) == [live]  # the killed run's removed, the live one's kept
    assert list(temporary.iterdir()) == [] and (tmp_path / "g.bvh").is_file()


KILLED_WRITER = """
import os, signal, sys
from agentsim.written import written
with written(sys.argv[1]) as tmp:
    tmp.write_bytes(b"half")
    print(tmp.name, flush=True)
    if sys.argv[2] == "kill":
        os.kill(os.getpid(), signal.SIGKILL)
    sys.stdin.readline()  # alive, writing, until told to go on
"""


def test_the_next_write_removes_the_temporaries_of_killed_writers_only(tmp_path):
    """A writer killed -9 leaves its temporary file; the next write to the same path removes it, and leaves
    the temporary of a writer still going (it holds its lock) and those of other paths."""
    (tmp_path / "out.wav").write_bytes(b"old")
    alive = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, "out.wav", "wait"], cwd=tmp_path, env=env(),
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        going = tmp_path / alive.stdout.readline().strip()
        killed = [subprocess.run([sys.executable, "-c", KILLED_WRITER, "out.wav", "kill"], cwd=tmp_path, env=env(),
                                 capture_output=True, text=True) for _ in range(2)]
        assert [k.returncode for k in killed] == [-signal.SIGKILL] * 2
        stale = [tmp_path / k.stdout.strip() for k in killed]
        other = subprocess.run([sys.executable, "-c", KILLED_WRITER, "other.wav", "kill"], cwd=tmp_path, env=env(),
                               capture_output=True, text=True)
        assert not stale[0].exists()  # the second killed writer removed the first one's
        assert stale[1].is_file() and going.is_file() and (tmp_path / "out.wav").read_bytes() == b"old"
        with written(tmp_path / "out.wav") as tmp:
            tmp.write_bytes(b"new")
        assert not any(p.exists() for p in stale) and going.is_file()  # the live writer's file is its own
        assert (tmp_path / other.stdout.strip()).is_file()  # another path's: left to that path's next write
        alive.communicate("\n", timeout=60)
    finally:
        alive.kill()
    assert alive.returncode == 0 and (tmp_path / "out.wav").read_bytes() == b"half"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["out.wav", other.stdout.strip()])
    assert stat.S_IMODE((tmp_path / "out.wav").stat().st_mode) == 0o666 & ~current_umask()  # as open() makes it


def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


KILLED_PAGE = """
import os, signal, sys
from agentsim.written import staged_page
with staged_page("run.html", "run_files", marks=("data.js",)) as (page, folder):
    (folder / "data.js").write_text("new")
    page.write_text("new page")
    os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_page_and_its_folder_are_swapped_in_together(tmp_path):
    """staged_page: a writer killed before the swap leaves the old pair; a failing one leaves it too; the
    next one clears what the killed one staged and puts its pair in place."""
    from agentsim.written import staged_page

    (tmp_path / "run_files").mkdir()
    (tmp_path / "run_files" / "data.js").write_text("old")
    (tmp_path / "run.html").write_text("old page")
    killed = subprocess.run([sys.executable, "-c", KILLED_PAGE], cwd=tmp_path, env=env(), capture_output=True)
    assert killed.returncode == -signal.SIGKILL
    left = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("."))
    assert [n.split("-")[0] for n in left] == [".run.partial", ".run_files.staging"]
    assert (tmp_path / "run.html").read_text() == "old page"
    assert (tmp_path / "run_files" / "data.js").read_text() == "old"
    with pytest.raises(RuntimeError), staged_page(tmp_path / "run.html", tmp_path / "run_files",
                                                  marks=("data.js",)) as (page, folder):
        (folder / "data.js").write_text("failed")
        raise RuntimeError("the run failed")
    assert (tmp_path / "run.html").read_text() == "old page"
    assert (tmp_path / "run_files" / "data.js").read_text() == "old"
    with staged_page(tmp_path / "run.html", tmp_path / "run_files", marks=("data.js",)) as (page, folder):
        (folder / "data.js").write_text("new")
        page.write_text("new page")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.html", "run_files"]
    assert (tmp_path / "run.html").read_text() == "new page"
    assert (tmp_path / "run_files" / "data.js").read_text() == "new"


def test_a_report_folder_of_someone_elses_files_is_refused_before_work(tmp_path):
    (tmp_path / "g.xml").write_text(GOOD.format(start=0))
    (tmp_path / "run_files").mkdir()
    (tmp_path / "run_files" / "mine.txt").write_text("mine")
    proc = cli("realize", "--tts", "builtin", "--report", "run.html", "g.xml", cwd=tmp_path)
    assert proc.returncode == 2 and "run_files: it holds files that are not an agentsim run's" in one_line(proc)
    assert proc.stdout == "" and not (tmp_path / "run.html").exists()  # before the run: no feedback
    assert (tmp_path / "run_files" / "mine.txt").read_text() == "mine"
