"""What agentsim writes, hashed: the feedback and files of runs that use no new option or markup.

``python tests/outputs_record.py documents OUT.json [GROUP]`` realizes every shipped example (espeak-ng, with
``--wav --bvh --textgrid --csv``) and every BML test document of every dialect read (``--tts builtin
--bvh``) in one process, in a fixed order, and writes the SHA-256 of each run's stdout and files;
``python tests/outputs_record.py scenarios OUT.json`` does the same for the storyteller's and the
conductor's whole runs (every file of their folders but pictures, report pages and the timing fields of
``metrics.json``). ``tests/test_outputs_unchanged.py`` compares them with ``tests/data/outputs.json``,
recorded on the version before the runs were made fast, so that every later change keeps them.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import re
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
EXAMPLES = ROOT / "agentsim" / "examples"

#: Files of a scenario's folder that are not compared: pictures and report pages (their bytes hold
#: renderer versions and dates), and metrics.json, compared without its timing fields.
SKIPPED_SUFFIXES = {".png", ".svg", ".pdf", ".html", ".js", ".css"}
#: The timing fields of metrics.json (wall-clock measures of the run itself).
TIMING_FIELDS = ("wall_seconds", "wall_fraction_of_story", "simulation_seconds", "synthesis_seconds", "cached",
                 "cache_load_seconds", "stages_seconds")


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _run(argv: list[str], tmp: Path) -> tuple[int, str]:
    """Exit status and stdout of one command, with the checkout's and the scratch folder's paths and the
    wall time a scenario prints replaced by placeholders."""
    from agentsim.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main(argv)
    return status, _placeheld(out.getvalue(), tmp)


def _placeheld(text: str, tmp: Path) -> str:
    text = text.replace(str(tmp), "<out>").replace(str(ROOT), "<root>")
    text = re.sub(r"wall [0-9.]+ s \([0-9.]+ % of [^)]*\)", "wall <s>", text)
    text = re.sub(r", first synthesis [0-9.]+ s", "", text)  # said when the speech cache was cold
    return re.sub(r"(written to \S+) in [0-9.]+ s", r"\1 in <s>", text)


#: The documents, in groups that can be recorded apart: the shipped examples, and each folder of test files.
GROUPS = ("examples", "bml-examples", "bml-examples-asap", "bml", "dialects")


def _document_cases(group: str | None = None) -> list[tuple[str, list[str], bool]]:
    """(name, files, speaks): every document realized alone (of one group, or all), in a fixed order."""
    cases = []
    for path in sorted(EXAMPLES.glob("*.xml")) + sorted((EXAMPLES / "bmla").glob("*.xml")) + sorted(
            (EXAMPLES / "dialects").glob("*.xml")):
        cases.append((f"examples/{path.relative_to(EXAMPLES)}", [str(path)], True))
    cases.append(("examples/bmla/talk+barge_in", [str(EXAMPLES / "bmla" / "talk.xml"),
                                                  str(EXAMPLES / "bmla" / "barge_in.xml"), "--at", "0,2.5"], True))
    for folder in GROUPS[1:]:
        for path in sorted((HERE / folder).rglob("*")):
            if path.suffix in (".xml", ".bml") and path.is_file():
                cases.append((f"{folder}/{path.relative_to(HERE / folder)}", [str(path)], False))
    return [case for case in cases if group is None or case[0].split("/", 1)[0] == group]


def record_documents(group: str | None = None) -> dict[str, str]:
    """The hashes of every document's run (of one of :data:`GROUPS`, or all); the examples' group holds the
    story's ``speech export`` too."""
    hashes: dict[str, str] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, files, speaks in _document_cases(group):
            out = tmp / name.replace("/", "_")
            out.mkdir()
            argv = ["realize", *files, "--bvh", str(out / "run.bvh")]
            if speaks:
                argv += ["--metronome", "100", "--wav", str(out / "run.wav"), "--textgrid",
                         str(out / "run.TextGrid"), "--csv", str(out / "tables")]
            else:
                argv += ["--tts", "builtin"]
            status, stdout = _run(argv, tmp)
            hashes[f"{name}:stdout"] = _sha(f"{status}\n{stdout}".encode())
            for written in sorted(p for p in out.rglob("*") if p.is_file()):
                hashes[f"{name}:{written.relative_to(out)}"] = _sha(written.read_bytes())
        if group not in (None, "examples"):
            return hashes
        status, stdout = _run(["speech", "export", str(EXAMPLES / "story.txt"), "--wav", str(tmp / "story.wav"),
                               "--textgrid", str(tmp / "story.TextGrid")], tmp)
        hashes["speech-export/story.txt:stdout"] = _sha(f"{status}\n{stdout}".encode())
        for suffix in ("wav", "TextGrid"):
            hashes[f"speech-export/story.txt:story.{suffix}"] = _sha((tmp / f"story.{suffix}").read_bytes())
    return hashes


def _folder_hashes(name: str, folder: Path, stdout: str, status: int, tmp: Path) -> dict[str, str]:
    hashes = {f"{name}:stdout": _sha(f"{status}\n{stdout}".encode())}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = path.relative_to(folder)
        if path.suffix in SKIPPED_SUFFIXES or any(part.endswith("_files") for part in rel.parts[:-1]):
            continue
        data = path.read_bytes()
        if path.name == "metrics.json":
            data = _placeheld(json.dumps(_without_timing(json.loads(data)), sort_keys=True), tmp).encode()
        hashes[f"{name}:{rel}"] = _sha(data)
    return hashes


def _without_timing(value):
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items() if k not in TIMING_FIELDS}
    if isinstance(value, list):
        return [_without_timing(v) for v in value]
    return value


def record_scenarios() -> dict[str, str]:
    """The hashes of the storyteller's and the conductor's (seed 0) whole runs."""
    hashes: dict[str, str] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, argv in (("storytelling", ["run", "storytelling"]),
                           ("conductor", ["run", "conductor", "--seed", "0"])):
            status, stdout = _run([*argv, "--out", str(tmp / name)], tmp)
            hashes.update(_folder_hashes(name, tmp / name, stdout, status, tmp))
    return hashes


if __name__ == "__main__":
    kind, target = sys.argv[1], Path(sys.argv[2])
    sys.path.insert(0, str(ROOT))
    os.chdir(ROOT)  # a document's relative paths are also looked for in the current folder
    if kind == "documents":
        recorded = record_documents(sys.argv[3] if len(sys.argv) > 3 else None)
    else:
        recorded = record_scenarios()
    target.write_text(json.dumps(recorded, indent=1, sort_keys=True) + "\n")
