"""``--no-pictures`` writes every file a run writes but its pictures, the same bytes; a sweep's point whose
folder is not kept is run with it, one whose folder is kept is not."""

from __future__ import annotations

import json
from pathlib import Path

from agentsim.cli import main
from agentsim.cli.sweep.point import run_point

STORY = "@title Short\nThe [beat]wind and the [point:LEFT]sun were arguing which was the [beat]stronger.\n"
#: Fields of metrics.json that time the run itself, and whether its speech came from the speech cache (the
#: first run fills the test run's cache, the second reads it).
TIMING = {"wall_seconds", "wall_fraction_of_story", "stages_seconds", "cache_load_seconds", "synthesis_seconds",
          "simulation_seconds", "cached"}


def _files(folder: Path) -> dict[str, bytes]:
    out = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        data = path.read_bytes()
        if path.name == "metrics.json":
            data = json.dumps({k: v for k, v in json.loads(data).items() if k not in TIMING}).encode()
        out[str(path.relative_to(folder))] = data
    return out


def test_no_pictures_writes_every_other_file_byte_for_byte(tmp_path, capsys):
    (tmp_path / "short.story").write_text(STORY)
    argv = ["run", "storytelling", "--story", str(tmp_path / "short.story"), "--tts", "builtin"]
    assert main([*argv, "--out", str(tmp_path / "all")]) == 0
    assert main([*argv, "--no-pictures", "--out", str(tmp_path / "some")]) == 0
    every, some = _files(tmp_path / "all"), _files(tmp_path / "some")
    pictures = {name for name in every if name.endswith(".png")}
    assert pictures == {"timeline.png", "sync_errors.png"}
    assert some == {name: data for name, data in every.items() if name not in pictures}
    capsys.readouterr()


def test_a_sweep_point_draws_pictures_only_when_its_folder_is_kept(tmp_path, monkeypatch):
    import scenarios.storytelling.run as story_run

    drawn = []
    monkeypatch.setattr(story_run, "plot_errors", lambda telling, png: drawn.append(png.name))
    (tmp_path / "short.story").write_text(STORY)
    argv = ["run", "storytelling", "--story", str(tmp_path / "short.story"), "--tts", "builtin", "--json"]
    unseen = run_point(argv, out_at=2)
    assert unseen["status"] == "ok" and drawn == []
    kept = run_point(argv, out_at=2, keep=str(tmp_path / "kept"))
    assert kept["status"] == "ok" and drawn == ["sync_errors.png"]
    assert (tmp_path / "kept" / "timeline.png").exists()
    assert unseen["result"]["gestures"] == kept["result"]["gestures"] == 3
