#!/usr/bin/env python3
"""The pictures of ``docs/howto/emotions.md``: the run report's 3D view at three emotions (joy, fear, anger)
of one BML block, drawn by headless Chromium (Debian's ``chromium``), written small into
``docs/howto/emotions/`` (``joy.png``, ``fear.png``, ``anger.png``; 360 pixels wide, 64 colours).

``python scripts/emotion_pictures.py`` makes them anew (espeak-ng speaks; a few seconds)."""

from __future__ import annotations

import base64
import io
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "howto" / "emotions"
BML = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:ex="urn:agentsim:expression" id="b1">'
       '<speech id="s1"><text>Once <sync id="w1"/>upon a time there <sync id="w2"/>was a girl who <sync id="w3"/>'
       'feared the dark but <sync id="w4"/>loved the stars.</text></speech>'
       '<ex:emotion id="e1" type="joy" intensity="3.2" start="s1:w1" end="s1:w2"/>'
       '<ex:emotion id="e2" type="fear" intensity="6.5" start="s1:w2" end="s1:w3"/>'
       '<ex:emotion id="e3" type="anger" intensity="6" start="s1:w3" end="s1:w4"/></bml>')
WIDTH = 360


def main() -> int:
    sys.path.insert(0, str(ROOT))
    from PIL import Image

    from agentsim.animation import evaluate_poses
    from agentsim.media.audio import run_track
    from agentsim.media.environment import report_environment, run_environment
    from agentsim.media.report import write_report
    from agentsim.media.report.browser import Chromium, open_report
    from agentsim.realizer import Realizer
    from speech_timing.espeak import EspeakBackend

    realizer = Realizer(tts=EspeakBackend())
    realizer.submit(BML)
    realizer.run()
    recording = realizer.recording()
    rows = run_environment(recording)
    stream = evaluate_poses(recording, fps=30)
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp, Chromium(width=1280, height=900) as browser:
        page = write_report(Path(tmp) / "emotions.html", recording=recording, stream=stream,
                            track=run_track(recording), environment=report_environment(rows, stream))
        open_report(page, browser)
        for row, following in zip(rows, rows[1:]):
            if row.channels.emotion == "none":
                continue
            browser.evaluate(f"report.seek({(row.time + following.time) / 2!r})")
            browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))",
                             await_promise=True)
            url = browser.evaluate("document.querySelector('#view canvas').toDataURL('image/png')")
            image = Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB")
            image = image.resize((WIDTH, round(image.height * WIDTH / image.width)), Image.LANCZOS)
            path = OUT / f"{row.channels.emotion}.png"
            image.quantize(64).save(path, optimize=True)
            print(f"{path.relative_to(ROOT)}: {row.channels.emotion} {row.channels.intensity:g}, "
                  f"{row.channels.shot} at {row.channels.angle} angle, key {row.channels.key} "
                  f"attenuation {row.channels.attenuation:g} ({path.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
