"""The vocabulary of other realizers' BML and what the lenient reader reads it as: tables kept as data in
``agentsim/bml/data/dialects.toml``, read and checked once, when this module is imported.

=========================  ==================================================================================
name                       what it holds
=========================  ==================================================================================
``DRAFT_NAMESPACES``       the namespaces of the BML drafts before 1.0, read as BML 1.0's
``TYPE_IS_LEXEME``         behaviour types whose ``type=`` attribute the drafts used for the lexeme
``UNMAPPED_HINTS``         elements with no counterpart here, and what each is (said when it is taken out)
``COMPOSITIONS``           Greta's compositions as BML 1.0's
``EXPRESSIONS``            facial expressions of the drafts, Greta and EMBR as face lexemes
``DEICTIC_TARGETS``        Greta's deictic lexicon as scene targets
``CLIP_WORDS``             words in SmartBody/NVBG clip names and the gesture lexeme each is closest to
``SACCADE_DIRECTIONS``     the eight directions of a saccade in BML's names, 45 degrees apart
``JOINT_RANGE``            SmartBody's ``sbm:joint-range`` by its highest joint, as a gaze influence
``SYNC_ALIASES``           sync points as SmartBody and EMBR name them, by behaviour type
=========================  ==================================================================================
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from agentsim.errors import AgentsimError

#: The file the tables are read from.
TABLES_PATH = Path(__file__).resolve().parent / "data" / "dialects.toml"


def _strings(value, where: str) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise AgentsimError(f"{TABLES_PATH}: {where} must be a list of non-empty strings")
    return tuple(value)


def _mapping(value, where: str) -> dict[str, str]:
    if not isinstance(value, dict) or not all(isinstance(k, str) and isinstance(v, str) and v
                                              for k, v in value.items()):
        raise AgentsimError(f"{TABLES_PATH}: [{where}] must map names to non-empty strings")
    return dict(value)


def _pairs(value, where: str, first: str, second: str) -> tuple[tuple[str, str], ...]:
    if not isinstance(value, list) or not all(isinstance(v, dict) and set(v) == {first, second}
                                              and all(isinstance(x, str) and x for x in v.values()) for v in value):
        raise AgentsimError(f"{TABLES_PATH}: every [[{where}]] needs {first} and {second}, both non-empty strings")
    return tuple((v[first], v[second]) for v in value)


def read_tables(text: str) -> dict:
    """The tables of a dialects file's ``text``, checked (:class:`~agentsim.errors.AgentsimError` naming the
    entry that is wrong)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise AgentsimError(f"{TABLES_PATH}: not TOML: {exc}") from None
    expected = {"draft_namespaces", "type_is_lexeme", "compositions", "saccade_directions", "unmapped", "expressions",
                "deictic_targets", "clip_words", "joint_range", "sync_aliases"}
    if set(data) != expected:
        missing, extra = sorted(expected - set(data)), sorted(set(data) - expected)
        raise AgentsimError(f"{TABLES_PATH}: missing tables {missing}, unknown tables {extra}")
    directions = _strings(data["saccade_directions"], "saccade_directions")
    if len(directions) != 8:
        raise AgentsimError(f"{TABLES_PATH}: saccade_directions must name 8 directions, 45 degrees apart")
    if not isinstance(data["sync_aliases"], dict):
        raise AgentsimError(f"{TABLES_PATH}: [sync_aliases] must hold one table per behaviour type")
    return {
        "DRAFT_NAMESPACES": _strings(data["draft_namespaces"], "draft_namespaces"),
        "TYPE_IS_LEXEME": set(_strings(data["type_is_lexeme"], "type_is_lexeme")),
        "UNMAPPED_HINTS": _mapping(data["unmapped"], "unmapped"),
        "COMPOSITIONS": _mapping(data["compositions"], "compositions"),
        "EXPRESSIONS": _mapping(data["expressions"], "expressions"),
        "DEICTIC_TARGETS": _mapping(data["deictic_targets"], "deictic_targets"),
        "CLIP_WORDS": _pairs(data["clip_words"], "clip_words", "word", "lexeme"),
        "SACCADE_DIRECTIONS": directions,
        "JOINT_RANGE": _pairs(data["joint_range"], "joint_range", "joint", "influence"),
        "SYNC_ALIASES": {kind: _mapping(table, f"sync_aliases.{kind}") for kind, table in data["sync_aliases"].items()},
    }


_TABLES = read_tables(TABLES_PATH.read_text(encoding="utf-8"))
DRAFT_NAMESPACES: tuple[str, ...] = _TABLES["DRAFT_NAMESPACES"]
TYPE_IS_LEXEME: set[str] = _TABLES["TYPE_IS_LEXEME"]
UNMAPPED_HINTS: dict[str, str] = _TABLES["UNMAPPED_HINTS"]
COMPOSITIONS: dict[str, str] = _TABLES["COMPOSITIONS"]
EXPRESSIONS: dict[str, str] = _TABLES["EXPRESSIONS"]
DEICTIC_TARGETS: dict[str, str] = _TABLES["DEICTIC_TARGETS"]
CLIP_WORDS: tuple[tuple[str, str], ...] = _TABLES["CLIP_WORDS"]
SACCADE_DIRECTIONS: tuple[str, ...] = _TABLES["SACCADE_DIRECTIONS"]
JOINT_RANGE: tuple[tuple[str, str], ...] = _TABLES["JOINT_RANGE"]
SYNC_ALIASES: dict[str, dict[str, str]] = _TABLES["SYNC_ALIASES"]
