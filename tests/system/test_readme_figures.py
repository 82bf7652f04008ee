"""The check that the documentation's result tables match a fresh run (``scripts/readme_figures.py --check``)
fails on a stale figure and passes over measured times. The check itself, four minutes of fresh runs on
two cores (its four tables side by side), is a step of CI of its own after the documentation's build (``.ci/run``), not a test of the
system run."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[2]


def test_the_check_fails_on_a_stale_figure(tmp_path, monkeypatch):
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import readme_figures
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    readme = tmp_path / "measured.md"
    readme.write_text("a\n<!-- figures:storyteller-strategies -->\n| stale |\n<!-- /figures:storyteller-strategies -->\n")
    monkeypatch.setattr(readme_figures, "README", readme)
    monkeypatch.setattr(readme_figures, "TABLES", {"storyteller-strategies": lambda: "| fresh |"})
    assert readme_figures.main(["--check"]) == 1
    assert "| stale |" in readme.read_text()
    assert readme_figures.main([]) == 0
    assert readme.read_text() == ("a\n<!-- figures:storyteller-strategies -->\n| fresh |\n"
                                  "<!-- /figures:storyteller-strategies -->\n")


def test_the_check_passes_over_measured_times_but_not_over_other_figures(tmp_path, monkeypatch):
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import readme_figures
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    head = "| backend | voice | speech s | real-time factor | first synthesis s |\n|---|---|---|---|---|\n"
    page = tmp_path / "voices.md"
    page.write_text(f"<!-- figures:voices -->\n{head}| piper | joe | 42.5 | 0.08 | 3.3 |\n<!-- /figures:voices -->\n")
    monkeypatch.setattr(readme_figures, "PAGES", {"voices": page})
    monkeypatch.setattr(readme_figures, "TABLES", {"voices": lambda: f"{head}| piper | joe | 42.5 | 0.31 | 7.7 |"})
    assert readme_figures.main(["--check"]) == 0
    monkeypatch.setattr(readme_figures, "TABLES", {"voices": lambda: f"{head}| piper | joe | 42.6 | 0.08 | 3.3 |"})
    assert readme_figures.main(["--check"]) == 1
    assert readme_figures.main([]) == 0
    assert "| piper | joe | 42.6 | 0.08 | 3.3 |" in page.read_text()
