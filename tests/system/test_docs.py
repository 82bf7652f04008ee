"""The documentation site: it builds with no warning, every command and nested command has a page that lists
its options, every public module has its API page, and a reader searching for "anticipator" in a real browser
finds the tutorial (the tutorials' code runs in ``test_tutorials.py``)."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.system

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"

sys.path.insert(0, str(DOCS))
try:
    from _generate import command_paths, public_modules
finally:
    sys.path.remove(str(DOCS))


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site built from the checkout, every warning an error."""
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-b", "html", "-q", str(DOCS),
                           str(out)], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-5000:]
    assert "WARNING" not in proc.stderr and "ERROR" not in proc.stderr, proc.stderr[-5000:]
    return out


def _text(page: Path) -> str:
    html = page.read_text(encoding="utf-8")
    html = re.sub(r"<(script|style)\b.*?</\1>", "", html, flags=re.S)
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html)).replace("&#8212;", "—").replace("&#x2014;", "—")


def _options(parser: argparse.ArgumentParser) -> list[str]:
    """The options a reader looks up (``--help`` is every command's, and the page leaves it out)."""
    return [a.option_strings[-1] for a in parser._actions if a.option_strings and a.help is not argparse.SUPPRESS
            and not isinstance(a, argparse._HelpAction)]


def _sub(parser: argparse.ArgumentParser, path: tuple[str, ...]) -> argparse.ArgumentParser:
    for word in path:
        action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = action.choices[word]
    return parser


def test_every_command_and_nested_command_has_a_page_with_its_options(site):
    from agentsim.cli import build_parser

    parser = build_parser()
    paths = command_paths(parser)
    assert ("run", "conductor") in paths and ("eval", "speech-sync") in paths and ("serve",) in paths
    for path in paths:
        page = site / "reference" / "cli" / f"{'-'.join(path)}.html"
        text = _text(page)
        title = "agentsim " + " ".join(path)
        assert f"<title>{title} " in page.read_text(encoding="utf-8"), page
        for option in _options(_sub(parser, path)):
            assert option in text, f"{title}: {option} is not on {page.name}"


def test_every_public_module_has_its_api_page(site):
    modules = public_modules(ROOT)
    assert {"agentsim.realizer", "agentsim.core.pegboard", "speech_timing.espeak", "anticipators.metronome",
            "scenarios.conductor"} <= set(modules)
    for name in modules:
        page = site / "reference" / "api" / f"{name}.html"
        html = page.read_text(encoding="utf-8")
        assert f"<title>{name} " in html, name
        first = (__import__(name, fromlist=["_"]).__doc__ or "").strip().split("\n")[0]
        words = re.findall(r"[A-Za-z]{4,}", first)[:3]
        assert all(w in _text(page) for w in words), f"{name}: its docstring is not on its page"


def test_a_reader_searching_for_anticipator_finds_the_tutorial(site, browser):
    browser.navigate(site / "index.html")
    browser.evaluate("""(() => {
        const box = document.querySelector('form[action*="search"] input[name="q"]');
        box.value = 'anticipator';
        box.form.submit();
    })()""")
    found = browser.wait_for("""(() => {  // the results come in page by page: wait for the summary at the end
        const summary = document.querySelector('#search-results .search-summary');
        if (!summary || !/found/.test(summary.textContent)) return null;
        return [...document.querySelectorAll('#search-results a')].map(a => a.getAttribute('href'));
    })()""", timeout=30)
    assert any("tutorials/anticipator.html" in link for link in found), found
