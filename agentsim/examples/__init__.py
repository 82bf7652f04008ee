"""The example documents and programs the README and the documentation use, installed with the package.

``agentsim examples`` lists them and ``agentsim examples copy DIR`` copies them into ``DIR/examples``; a
command given ``examples/NAME`` that does not exist where it runs reads the installed one
(:func:`resolve`), so that the documented commands work from any folder.
"""

from __future__ import annotations

from pathlib import Path

#: Where the examples are installed.
HOME = Path(__file__).resolve().parent


def names() -> list[str]:
    """Every example file, as ``examples/...`` paths, sorted."""
    return sorted(f"examples/{p.relative_to(HOME).as_posix()}" for p in HOME.rglob("*")
                  if p.is_file() and p.name != "__init__.py" and "__pycache__" not in p.parts)


def resolve(path: str | Path) -> Path:
    """``path`` itself if it exists; else, for ``examples/NAME``, the installed example of that name if there
    is one; else ``path`` unchanged (for the caller to report as missing)."""
    path = Path(path)
    if path.exists():
        return path
    parts = path.parts
    if "examples" in parts:
        installed = HOME.joinpath(*parts[parts.index("examples") + 1:])
        if installed.is_file():
            return installed
    return path


def read(name: str) -> str:
    """The text of an example by its name (``"welcome.xml"``, ``"examples/bmla/talk.xml"``): the file of that
    name under ``examples/`` where the program runs if there is one, else the installed example."""
    name = name.removeprefix("examples/")
    path = resolve(Path("examples") / name)
    if not path.is_file():
        raise FileNotFoundError(f"no example named {name!r} (agentsim examples lists them)")
    return path.read_text(encoding="utf-8")


def describe(name: str) -> str:
    """A line about an example: its first comment or docstring line, if it has one."""
    path = HOME / name.removeprefix("examples/")
    try:
        text = path.read_text(encoding="utf-8")
    except (UnicodeDecodeError, OSError):
        return "a sound file" if path.suffix in (".wav", ".flac", ".ogg") else ""
    for marker, end in (("<!--", "-->"), ('"""', '"""')):
        start = text.find(marker)
        if start != -1:
            body = text[start + len(marker):text.find(end, start + len(marker))].strip()
            if body:
                return body.splitlines()[0].strip()
    return ""
