"""Which lexemes this realizer has a motion for, and what plays for one it has not.

A ``<gesture lexeme="WAVE">`` whose lexeme no motion here is made for still plays, as the type's default
motion (a generic gesture, a nod, a weight shift, or no motion of the face); the reader says so in a
warning, naming each lexeme and behaviour (``lexeme="WAVE"`` is not accepted silently).
"""

from __future__ import annotations

from typing import Iterable, Mapping

# the lexicon's tables are read without numpy (the modules that move the body to them import it)
from agentsim.animation.lexicon import Lexicon

#: The lexemes of ``<head>`` (BML 1.0's).
HEAD_LEXEMES = ("NOD", "SHAKE", "TILT")
#: Gestures that are signals to the world rather than forms of their own: the conductor's ensemble plays
#: louder at a ``LOUDER`` and stops at a ``STOP``; they move as the generic gesture, by design.
SIGNALS = ("LOUDER", "STOP")


def fallback(tag: str, attrs: Mapping[str, str], lexicon: Lexicon | None = None) -> tuple[str, str] | None:
    """(the lexeme as written, what plays instead) if a behaviour's lexeme has no motion of its own in
    ``lexicon`` (default: the built-in one); None if it has one, names none, or its type has no lexemes."""
    lexeme = str(attrs.get("lexeme", "")).strip()
    if tag == "head":
        return None if not lexeme or lexeme.upper() in HEAD_LEXEMES else (lexeme, "a nod")
    if tag not in ("faceFacs", "face", "faceLexeme", "faceShift", "gesture", "posture", "postureShift"):
        return None
    if not lexeme and tag != "faceFacs":
        return None
    if lexicon is None:
        lexicon = Lexicon.builtin()
    if tag == "faceFacs":
        au = str(attrs.get("au", "")).strip()
        known = au.isdigit() and int(au) in lexicon.facs
        return None if known else (f"AU{au}", "no motion")
    if tag in ("face", "faceLexeme", "faceShift"):
        return None if lexeme.upper() in lexicon.faces else (lexeme, "no motion")
    if tag == "gesture":
        known = lexeme.upper() in SIGNALS or lexicon.knows_gesture(lexeme)
        return None if known else (lexeme, "a generic gesture")
    if tag in ("posture", "postureShift"):
        return None if lexeme.upper() in lexicon.postures else (lexeme, "a weight shift")
    return None


def fallbacks(behaviours: Iterable[tuple[str, str, Mapping[str, str]]],
              lexicon: Lexicon | None = None) -> dict[str, list[str]]:
    """For ``(tag, id, attrs)`` of behaviours: what plays instead (in ``lexicon``, default the built-in one)
    -> ``["WAVE (g)", ...]``, in order."""
    found: dict[str, list[str]] = {}
    for tag, bid, attrs in behaviours:
        unknown = fallback(tag, attrs, lexicon)
        if unknown is not None:
            found.setdefault(unknown[1], []).append(f"{unknown[0]} ({bid})")
    return found


def describe(found: dict[str, list[str]]) -> list[str]:
    """One sentence per fallback: ``lexemes with no motion of their own here, played as a nod: WIGGLE (h)``."""
    lines = []
    for instead, items in found.items():
        shown = ", ".join(items[:6]) + (f" and {len(items) - 6} more" if len(items) > 6 else "")
        lines.append(f"lexemes with no motion of their own here, played as {instead}: {shown}")
    return lines
