#!/usr/bin/env python3
"""The picture of the physics how-to (``docs/howto/physics-push.png``): the centre of mass during a push.

``python scripts/physics_figure.py`` realizes a standing body with a nod on the physical body
(``agentsim realize --physics``) with a forward push of 150 N for 0.2 s at 2 s and a sideways one at 5 s,
reads the ``--physics-csv`` file and draws the centre of mass's ground projection (forward and sideways,
over time) against the support polygon's bounding box. ``--out FILE`` writes elsewhere.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "howto" / "physics-push.png"
BML = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1"><head id="h1" lexeme="NOD" start="3" '
       'end="4"/><head id="h2" lexeme="NOD" start="7.5" end="8"/></bml>')
PUSHES = ((2.0, "forward (+Z)"), (5.0, "sideways (+X)"))


def rows() -> np.ndarray:
    """The physics CSV of the run, as numbers."""
    from agentsim.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "stand.xml").write_text(BML)
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            status = main(["realize", str(folder / "stand.xml"), "--tts", "builtin", "--physics",
                           "--physics-csv", str(folder / "p.csv"), "--push", "2:0,0,150:0.2",
                           "--push", "5:150,0,0:0.2"])
        assert status == 0
        with open(folder / "p.csv", newline="") as f:
            return np.array([[float(x) for x in r] for r in list(csv.reader(f))[1:]])


def draw(data: np.ndarray, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = data[:, 0]
    fig, axes = plt.subplots(2, 1, figsize=(7.0, 4.2), sharex=True)
    for ax, (com, lo, hi, label) in zip(axes, ((3, 6, 7, "forward, cm"), (1, 4, 5, "sideways, cm"))):
        ax.fill_between(t, 100 * data[:, lo], 100 * data[:, hi], color="#cfe3f7", label="support polygon")
        ax.plot(t, 100 * data[:, com], color="#c0392b", lw=1.4, label="centre of mass")
        for when, what in PUSHES:
            ax.axvspan(when, when + 0.2, color="0.6", alpha=0.5)
        ax.set_ylabel(label)
        ax.set_ylim(100 * data[:, lo].min() - 2, 100 * data[:, hi].max() + 2)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title("150 N pushes for 0.2 s (grey): forward at 2 s, sideways at 5 s", fontsize=10)
    axes[1].set_xlabel("time, s")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help=f"where to write the picture ({OUT.relative_to(ROOT)})")
    args = parser.parse_args()
    draw(rows(), args.out)
    print(f"wrote {args.out} ({args.out.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
