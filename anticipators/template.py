"""A new anticipator plugin, written out as a complete installable folder (``agentsim anticipators new``).

The folder holds a ``pyproject.toml`` that registers the class in the ``anticipators`` entry-point
group, the module with the class (a pulse every ``period`` seconds from ``start``, moved while the plan plays
when ``drift`` is set: the two things an anticipator does), a test of it that pytest runs, and a README.
``pip install -e FOLDER`` makes ``agentsim anticipators list`` show it at once.
"""

from __future__ import annotations

import keyword
import re
from pathlib import Path

from agentsim.errors import UsageError

PYPROJECT = '''[build-system]
requires = ["setuptools>=68"]
build-backend = "setuptools.build_meta"

[project]
name = "agentsim-{dist}"
version = "0.1.0"
description = "An anticipator for agentsim: {name}."
requires-python = ">=3.11"
# the agentsim BML realizer (its own checkout: the project called "agentsim" on the public package index is
# another one, so install this agentsim first; pip then finds the requirement met)
dependencies = ["agentsim>=0.1,<0.2"]

[project.optional-dependencies]
test = ["pytest"]

[project.entry-points."agentsim.anticipators"]
{name} = "{module}:{cls}"

[tool.setuptools]
py-modules = ["{module}"]
'''

MODULE = '''"""The {name} anticipator: ``pulse1``, ``pulse2``, ... every ``period`` seconds from ``start``.

BML pegs behaviours to it as ``anticipators:{name}:pulseN`` (``<head lexeme="NOD" stroke="anticipators:{name}:pulse3"/>``).
With ``drift`` set, every pulse not yet passed moves by ``drift`` seconds each ``period`` while the plan plays,
and everything pegged to them is re-timed.
"""

from __future__ import annotations

import re

from anticipators import Anticipator

PULSE = re.compile(r"pulse(\\d+)")


class {cls}(Anticipator):
    """Pulses every ``period`` seconds from ``start``; ``drift`` seconds later each period while playing."""

    def __init__(self, anticipator_id: str = "{name}", period: float = 0.5, start: float = 0.0,
                 drift: float = 0.0):
        super().__init__(anticipator_id)
        if not period > 0:
            raise ValueError(f"period must be positive, got {{period!r}} s")
        self.period, self.start, self.drift = period, start, drift

    def make_peg(self, sync_id: str):
        """The predicted time of a new peg, or False if there is no such sync point."""
        match = PULSE.fullmatch(sync_id)
        if match is None or int(match.group(1)) < 1:
            return False
        return self.start + (int(match.group(1)) - 1) * self.period

    def run(self):
        """A SimPy process that moves the pulses while the plan plays (None: nothing to move)."""
        return self.move() if self.drift else None

    def move(self):
        while True:
            yield self.env.timeout(self.period)
            for peg in list(self.pegs.values()):
                if peg.time > self.env.now:
                    peg.set(peg.time + self.drift)
'''

TEST = '''"""The {name} anticipator, realized from BML: pegs where it predicts them, moved when it moves them."""

from anticipators import registry
from agentsim.realizer import Realizer

from {module} import {cls}

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0"'


def realize(anticipator):
    realizer = Realizer(anticipators=[anticipator])
    realizer.submit(f'<bml {{NS}} id="b"><head id="n" lexeme="NOD" stroke="anticipators:{name}:pulse3"/></bml>')
    realizer.run()
    return {{f["id"]: f["globalTime"] for f in realizer.feedback.items if f["type"] == "syncPointProgress"}}


def test_a_nod_strokes_on_the_third_pulse():
    assert realize({cls}(period=0.5, start=1.0))["b:n:stroke"] == 2.0


def test_drift_moves_the_pulse_and_the_nod_with_it():
    # the third pulse, first at 2.0 s, moves by 0.1 s at 0.5, 1.0, 1.5 and 2.0 s (still ahead each time)
    assert abs(realize({cls}(period=0.5, start=1.0, drift=0.1))["b:n:stroke"] - 2.4) < 1e-9


def test_it_is_registered():
    assert registry.available()["{name}"] == "{module}:{cls}"
'''

README = '''# agentsim-{dist}

An anticipator for [agentsim](https://pypi.org/project/agentsim/): `pulse1`, `pulse2`, ... every `period`
seconds from `start`, each moved by `drift` seconds every period while the plan plays.

```sh
pip install -e .
agentsim anticipators list          # shows {name} with its parameters
agentsim realize nod.xml --anticipator {name}:p,period=0.5,start=1
python -m pytest -q                 # its tests
```

In BML: `<head id="n" lexeme="NOD" stroke="anticipators:p:pulse3"/>` (the id after `{name}:` in
`--anticipator`; without one it is `{name}`).

Parameters (declared by the constructor's signature; `--anticipator` reads them with these types):
`period: float = 0.5`, `start: float = 0.0`, `drift: float = 0.0`. Edit `{module}.py` to make it predict
what your world does: `make_peg(sync_id)` gives a new peg's first time, `run()` the process that moves
them (`self.peg(sync_id).set(t)`).
'''

NAME = re.compile(r"[a-z][a-z0-9_]*")


def write_plugin(name: str, parent: Path) -> Path:
    """Write the plugin folder ``agentsim-NAME`` under ``parent``; its path. ``name`` is what BML and
    ``--anticipator`` call it: lower case letters, digits and underscores, starting with a letter."""
    if not NAME.fullmatch(name) or keyword.iskeyword(name):
        raise UsageError(f"anticipator name {name!r}: use lower case letters, digits and underscores, starting "
                         "with a letter (it is the name BML and --anticipator use)")
    module = f"agentsim_{name}"
    cls = "".join(part.capitalize() for part in name.split("_") if part) or name
    dist = name.replace("_", "-")
    folder = Path(parent) / f"agentsim-{dist}"
    if folder.exists():
        raise UsageError(f"{folder} exists already: choose another name or folder (--dir)")
    fields = {"name": name, "module": module, "cls": cls, "dist": dist}
    files = {"pyproject.toml": PYPROJECT, f"{module}.py": MODULE, f"tests/test_{name}.py": TEST,
             "README.md": README}
    try:
        for relative, text in files.items():
            path = folder / relative
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text.format(**fields), encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"cannot write the plugin into {folder}: {exc.strerror or exc}") from None
    return folder
