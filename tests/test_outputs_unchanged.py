"""Runs that use no new option or markup write what they wrote before the runs were made fast, byte for byte.

``tests/data/outputs-documents.json`` and ``outputs-scenarios.json`` hold the SHA-256 of the feedback and
files of those runs (``tests/outputs_record.py`` says which), recorded on the version before; each group is
recorded again here in a process of its own and compared name by name.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.outputs_record import GROUPS, HERE

RECORDED = HERE / "data"


def _recorded_again(tmp_path: Path, *args: str) -> dict[str, str]:
    out = tmp_path / "hashes.json"
    subprocess.run([sys.executable, str(HERE / "outputs_record.py"), args[0], str(out), *args[1:]], check=True,
                   cwd=tmp_path)
    return json.loads(out.read_text())


def _differences(now: dict[str, str], before: dict[str, str]) -> list[str]:
    return sorted(name for name in set(now) | set(before) if now.get(name) != before.get(name))


@pytest.mark.parametrize("group", GROUPS)
def test_documents_write_what_they_wrote_before(tmp_path, group):
    before = {k: v for k, v in json.loads((RECORDED / "outputs-documents.json").read_text()).items()
              if k.split("/", 1)[0] == group or (group == "examples" and k.startswith("speech-export/"))}
    assert before
    assert _differences(_recorded_again(tmp_path, "documents", group), before) == []


@pytest.mark.system
def test_scenarios_write_what_they_wrote_before(tmp_path):
    before = json.loads((RECORDED / "outputs-scenarios.json").read_text())
    assert _differences(_recorded_again(tmp_path, "scenarios"), before) == []
