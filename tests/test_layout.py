"""The design card's layout, as a user meets it: the four packages import from any folder, shipped
configurations and sweep specs are found by their short names, the example plugin is an installed example,
the old import path of the anticipator interface still works with a DeprecationWarning, and nothing large is
tracked."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
AGENTSIM = [sys.executable, "-m", "agentsim"]


def run(args, cwd, timeout=120):
    return subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=timeout)


def test_the_four_packages_import_from_an_empty_folder(tmp_path):
    proc = run([sys.executable, "-c", "import anticipators, speech_timing, scenarios, agentsim\n"
                "from anticipators import Anticipator\nfrom agentsim.core.anticipator import Anticipator as A\n"
                "assert Anticipator is A\nprint(anticipators.__file__, speech_timing.__file__, scenarios.__file__)"],
               tmp_path)
    assert proc.returncode == 0, proc.stderr
    found = proc.stdout.split()
    assert [Path(p).parent.name for p in found] == ["anticipators", "speech_timing", "scenarios"]


def test_no_tracked_file_over_one_megabyte_outside_vendored_assets():
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout.split(b"\0")
    large = [f.decode() for f in files if f and (ROOT / f.decode()).is_file()
             and (ROOT / f.decode()).stat().st_size > 1_000_000 and "/vendor/" not in f.decode()]
    assert large == []


def test_the_old_import_path_of_the_interface_warns_and_gives_the_same_class():
    import anticipators

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        from agentsim.anticipators import Anticipator
    assert Anticipator is anticipators.Anticipator
    assert [w.category for w in caught] == [DeprecationWarning]
    assert "from anticipators import Anticipator" in str(caught[0].message)


def test_conductor_configurations_are_listed_and_found_by_short_name(tmp_path):
    listed = run([*AGENTSIM, "run", "conductor", "--list-configs"], tmp_path)
    assert listed.returncode == 0, listed.stderr
    assert [line.split()[0] for line in listed.stdout.splitlines()] == [
        "default", "falls_apart", "march_2_4", "waltz_3_4"]
    proc = run([*AGENTSIM, "run", "conductor", "--config", "waltz_3_4", "--bars", "4", "--out", "c", "--json"],
               tmp_path)
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads(proc.stdout)
    assert metrics["meter"] == "3/4" and metrics["target_bpm"] == 132.0
    assert metrics["config"].startswith(str(ROOT / "scenarios" / "conductor" / "configs" / "waltz_3_4.toml"))
    missing = run([*AGENTSIM, "run", "conductor", "--config", "nosuch"], tmp_path)
    assert missing.returncode == 2
    assert missing.stderr.strip().endswith("(shipped: default, falls_apart, march_2_4, waltz_3_4; "
                                           "'agentsim run conductor --list-configs')")


def test_sweep_specs_are_listed_and_found_by_short_name(tmp_path):
    listed = run([*AGENTSIM, "sweep", "--list-specs"], tmp_path)
    assert listed.returncode == 0, listed.stderr
    assert [line.split()[0] for line in listed.stdout.splitlines()] == ["conductor", "speech_sync", "trainer"]
    from agentsim.cli.sweep import spec
    from agentsim.cli.sweep.spec import load

    loaded = load("speech_sync")
    assert loaded.path == ROOT / "scenarios" / "sweeps" / "speech_sync.toml"
    points = list(loaded.points)  # every point, each made as it is asked for
    assert len(points) == spec.count(loaded.grid) == 324
    texts = {a for p in points for a in p.argv if a.endswith(".txt")}
    assert texts == {str(ROOT / "speech_timing" / "texts" / f"{n}.txt") for n in ("clocks", "lighthouse", "orchard")}
    missing = run([*AGENTSIM, "sweep", "nosuch", "--out", "x"], tmp_path)
    assert (missing.returncode, missing.stderr.strip()) == (2, "agentsim: no sweep spec 'nosuch'")


def test_the_example_plugin_and_the_live_client_are_installed_examples(tmp_path):
    proc = run([*AGENTSIM, "examples", "copy", "."], tmp_path)
    assert proc.returncode == 0, proc.stderr
    plugin = tmp_path / "examples" / "plugins" / "agentsim-countin"
    assert (plugin / "agentsim_countin.py").is_file() and (tmp_path / "examples" / "live" / "client.py").is_file()
    pyproject = (plugin / "pyproject.toml").read_text()
    assert 'dependencies = ["agentsim>=0.1,<0.2"]' in pyproject
    assert "from anticipators import Anticipator" in (plugin / "agentsim_countin.py").read_text()


def test_the_python_snippet_reads_the_installed_example_from_any_folder(tmp_path):
    proc = run([sys.executable, "-c", "from agentsim import examples\nprint(examples.read('welcome.xml')[:5])\n"
                "print(examples.read('examples/bmla/talk.xml')[:5])"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == [(ROOT / "agentsim/examples/welcome.xml").read_text()[:5].strip(),
                                   (ROOT / "agentsim/examples/bmla/talk.xml").read_text()[:5].strip()]
