"""Run report size and load time for a long run: "The lamp on Heron Hill" told by espeak-ng (6.8 minutes,
507 behaviours, poses at 60 fps on the 33-joint body), written with ``write_report`` and opened from
file:// in headless Chromium (software WebGL) three times.

Prints JSON: the size of each file, the time to write them, the time from navigation to
``window.report.ready`` (cold, then warm), and the time of one seek with its redraw. Target: ready within 3 s.

    python benchmarks/bench_report.py [OUT_FOLDER]      (default: a temporary folder)
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

from agentsim.animation import evaluate_poses
from agentsim.media.audio import run_track
from agentsim.media.report import write_report
from agentsim.media.report.browser import Chromium, open_report
from agentsim.media.tables import gesture_rows
from scenarios.storytelling.markup import read_story
from scenarios.storytelling.run import STORIES_DIR
from scenarios.storytelling.telling import make_voice, tell


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="bench-report-"))
    story = read_story(STORIES_DIR / "the_lamp_on_heron_hill.story")
    telling = tell(story, voice=make_voice("espeak", cache_dir=out / "tts-cache"))
    recording = telling.recording
    stream = evaluate_poses(recording, fps=60)
    track = run_track(recording)
    rows = gesture_rows(recording)
    started = time.perf_counter()
    path = write_report(out / "story.html", recording=recording, stream=stream, track=track, gestures=rows,
                        title=story.title, notes=["espeak-ng, best strategy, poses at 60 fps"])
    written = time.perf_counter() - started
    files = [path, *sorted((out / "story_files").iterdir())]
    sizes = {f.name: f.stat().st_size for f in files}
    with Chromium() as browser:
        loads = [open_report(path, browser) for _ in range(3)]
        errors = browser.evaluate("report.errors") + browser.exceptions
        seek_ms = browser.evaluate("(function(){var t=performance.now(); for (var i=0;i<100;i++) "
                                   "report.seek(100+i*0.05); return (performance.now()-t)/100;})()")
    print(json.dumps({
        "benchmark": "report",
        "run_s": round(track.duration, 1),
        "frames": stream.n_frames,
        "joints": len(stream.body.joints),
        "behaviours": len(recording.behaviours),
        "gestures": len(rows),
        "write_s": round(written, 3),
        "bytes": sizes,
        "total_bytes": sum(sizes.values()),
        "ready_s": {"cold": round(loads[0], 3), "warm": [round(x, 3) for x in loads[1:]]},
        "seek_and_redraw_ms": round(seek_ms, 2),
        "errors": errors,
        "target_ready_s": 3.0,
        "meets_target": max(loads) < 3.0 and not errors,
        "page": str(path),
    }, indent=2))


if __name__ == "__main__":
    main()
