"""How the work of reading and scheduling a block grows with its size, counted (never timed), and what
reading one loads."""

import subprocess
import sys
from collections import Counter
from pathlib import Path


ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_scheduler import make_block  # noqa: E402

from agentsim.realizer import Realizer  # noqa: E402
from speech_timing.builtin import BuiltinBackend  # noqa: E402


def calls_to_submit(n: int) -> Counter:
    """Python and built-in function calls made reading (leniently) and scheduling the benchmark's block of
    ``n`` behaviours and about ``3 n`` constraints."""
    text, _ = make_block(n)
    realizer = Realizer(tts=BuiltinBackend())
    calls: Counter = Counter()

    def count(frame, event, arg):
        if event in ("call", "c_call"):
            calls[event] += 1

    sys.setprofile(count)
    try:
        run = realizer.submit(text)
    finally:
        sys.setprofile(None)
    assert run is not None and len(run.timed) == n
    return calls


def test_reading_and_scheduling_do_work_in_proportion_to_the_block():
    # a look-up, a scan or a sort done per behaviour over all of them would make four times the behaviours
    # cost some sixteen times the calls; in proportion it is at most four times (less: the fixed part)
    small, large = calls_to_submit(100), calls_to_submit(400)
    for event in ("call", "c_call"):
        assert large[event] <= 4.2 * small[event], (event, small[event], large[event])


SCRIPT = """
import sys
from agentsim.animation import lexicon
from agentsim.realizer import Realizer
from speech_timing.builtin import BuiltinBackend

document = '''<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b">
  <gesture id="g1" lexeme="BEAT"/><gesture id="g2" lexeme="WAVE"/><gesture id="g3" lexeme="CONDUCT_3_4"/>
  <faceLexeme id="f1" lexeme="SMILE"/><faceLexeme id="f2" lexeme="GRIN"/><faceFacs id="u1" au="99"/>
  <postureShift id="p1" lexeme="LEAN_BACK"/><postureShift id="p2" lexeme="SLOUCH"/><head id="h1" lexeme="NOD"/>
</bml>'''
realizer = Realizer(tts=BuiltinBackend())
run = realizer.submit(document)
assert run is not None
print(sorted(f["description"] for f in realizer.feedback.warnings()))
print("numpy" in sys.modules, "agentsim.animation.arms" in sys.modules)
print(realizer.lexicon is lexicon.Lexicon.builtin(), sorted(realizer.lexicon.strokes))
"""


def test_reading_lexemes_loads_neither_numpy_nor_the_body():
    # which lexemes have a motion here is told from the lexicon's plain tables: a realizer given none plays
    # the built-in one
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}, timeout=120)
    assert done.returncode == 0, done.stderr
    warnings, loaded, same = done.stdout.splitlines()
    assert "played as a generic gesture: WAVE (g2)" in warnings and "CONDUCT" not in warnings
    assert "played as no motion: GRIN (f2), AU99 (u1)" in warnings
    assert "played as a weight shift: SLOUCH (p2)" in warnings
    assert loaded == "False False"
    assert same == "True ['BEAT', 'CHOP', 'DEFAULT', 'OFFER', 'POINT_DOWN']"
