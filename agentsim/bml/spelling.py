"""How the names of a BML document are spelled, and spelled as BML 1.0 does: element names in another case
(``<BML>``, ``<SPEECH>``), sync points spelled as the drafts and EMBR do (``stroke_start``, ``strokeENd``) in
attributes and references, and the document type declaration that only names an external DTD."""

from __future__ import annotations

import functools
import re

from agentsim.bml.dialect_tables import SYNC_ALIASES
from agentsim.core.block import BEHAVIOUR_TYPES
from agentsim.core.xmltree import Node

#: Sync point names as every type of behaviour spells them, by a spelling folded to lower case without
#: underscores or hyphens (``stroke_start``, ``strokeENd`` and ``STROKE`` are strokeStart, strokeEnd, stroke).
SYNC_SPELLINGS = {s.lower(): s for t in BEHAVIOUR_TYPES.values() for s in t.syncs}
#: Element names the lenient reader knows, by their lower-case spelling (EMBR writes ``<BML>``, ``<SPEECH>``).
KNOWN_ELEMENTS = {name.lower(): name for name in (*BEHAVIOUR_TYPES, "bml", "text", "sync", "required", "constraint",
                                                  "synchronize", "before", "after", "act", "participant",
                                                  "fml-apml", "tm", "mark", "description", "animation", "lips",
                                                  "curves", "curve", "event", "saccade", "body", "torso")}
_DOCTYPE = re.compile(rb"<!DOCTYPE\s+[\w:.-]+(?:\s+(?:SYSTEM|PUBLIC)(?:\s+(?:\"[^\"]*\"|'[^']*')){1,2})?\s*"
                      rb"(?:\[\s*\])?\s*>")


def without_doctype(data: bytes) -> tuple[bytes, bool]:
    """A document type declaration that only names an external DTD (and declares nothing) is blanked out:
    the DTD is never fetched, and the hardened reader refuses what could fetch it. One that declares
    entities stays, and is refused."""
    match = _DOCTYPE.search(data)
    if not match:
        return data, False
    return data[:match.start()] + b" " * (match.end() - match.start()) + data[match.end():], True


def fold_case(node: Node, names=None) -> bool:
    """Element names written in another case (``<BML>``, ``<SPEECH>``) get BML's spelling; True if any did.
    ``names``: the element names the tree holds, if known (when none is spelled otherwise, nothing is walked)."""
    if names is not None and not any(_respelled_name(name) for name in names):
        return False
    changed = False
    spelling: dict[str, str | None] = {}  # a name as written -> BML's spelling if that differs, else None
    stack = [node]
    while stack:  # (every element, each on its own: the order they are met in does not matter)
        n = stack.pop()
        local = n.local
        if local in spelling:
            known = spelling[local]
        else:
            known = KNOWN_ELEMENTS.get(local.lower())
            known = spelling[local] = known if known is not None and known != local else None
        if known is not None:
            n.tag = f"{n.prefix}:{known}" if n.prefix else known
            changed = True
        if n.children:
            stack += [c for c in n.children if isinstance(c, Node)]
    return changed


def _respelled_name(name: str) -> bool:
    local = name.partition(":")[2] or name
    known = KNOWN_ELEMENTS.get(local.lower())
    return known is not None and known != local


REF_SYNC = re.compile(r"^(?P<path>.*:)(?P<sync>[^:+\-\s]+)(?P<rest>\s*(?:[+-].*)?)$")
_SYNC_TAIL = re.compile(r"([^:+\-\s]+)(\s*(?:[+-].*)?)$")


def ref_sync(value: str) -> tuple[str, str, str] | None:
    """``path``, ``sync`` and ``rest`` of a reference as :data:`REF_SYNC` splits it (None if it does not):
    read from what follows its last colon, the part references share (``b1:end`` and ``b2:end``)."""
    text = value.strip()
    path, colon, tail = text.rpartition(":")
    if colon and "\n" not in path:  # then the pattern's first try, the path to the last colon, is its match
        parts = _tail(tail)
        if parts is not None:
            return path + colon, parts[0], parts[1]
    match = REF_SYNC.match(text)
    return (match.group("path"), match.group("sync"), match.group("rest")) if match else None


@functools.lru_cache(maxsize=1024)
def _tail(tail: str) -> tuple[str, str] | None:
    match = _SYNC_TAIL.match(tail)
    return match.groups() if match else None


def tail_sync(tail: str) -> tuple[str, str] | None:
    """``sync`` and ``rest`` of what follows the last colon of a reference without white space at either end:
    :func:`ref_sync` splits such a reference there when they are not None, whatever precedes the colon (if no
    line break does)."""
    return _tail(tail)


@functools.lru_cache(maxsize=1024)
def canonical_sync(sync: str) -> str | None:
    """The sync point a spelling of it names (``stroke_start``: strokeStart), None if none."""
    return SYNC_SPELLINGS.get(sync.lower().replace("_", "").replace("-", ""))


#: The sync point names that have an alias on some type (a reference to another one is never retargeted).
ALIAS_NAMES = frozenset(name for aliases in SYNC_ALIASES.values() for name in aliases)
#: What :func:`respell` gives a reference kept as it is, that names no sync point with an alias.
AS_WRITTEN = ("", None, False)


def respell(value: str) -> tuple[str, str | None, bool]:
    """The reference spelled as BML does, the note of the respelling (None: none), and whether it names a sync
    point that has an alias (:data:`ALIAS_NAMES`); :data:`AS_WRITTEN` for a reference that is none of these
    (kept as it is, nothing noted)."""
    match = ref_sync(value)
    if not match:
        return AS_WRITTEN
    path, sync, rest = match
    canonical = canonical_sync(sync)
    if canonical and canonical != sync:
        return f"{path}{canonical}{rest}", f"sync point {sync} read as {canonical}", canonical in ALIAS_NAMES
    return (value, None, True) if sync in ALIAS_NAMES else AS_WRITTEN


class References:
    """The references of one block respelled (:func:`respell`), each one once: a block repeats its references,
    and thousands of them share what follows their last colon (``b1:end``, ``b2:end``)."""

    def __init__(self) -> None:
        self.respelled: dict[str, tuple[str, str | None, bool]] = {}
        self.written_tails: dict[str, bool] = {}  # what follows a last colon -> whether it is kept as written

    def found(self, value: str) -> tuple[str, str | None, bool]:
        """:func:`respell` of ``value``."""
        found = self.respelled.get(value)
        if found is None:
            found = self.respelled[value] = self.once(value)
        return found

    def kept(self, value: str) -> bool:
        """Whether ``value`` is kept as written (:data:`AS_WRITTEN`), told at once for most references."""
        colon = value.rfind(":")
        if colon >= 0 and self.written_tails.get(value[colon + 1:]) and "\n" not in value and value.strip() == value:
            return True
        return self.found(value) is AS_WRITTEN

    def once(self, value: str) -> tuple[str, str | None, bool]:
        """:func:`respell` of ``value``; a reference kept as it is is known from what follows its last colon,
        once that has been split."""
        path, colon, tail = value.rpartition(":")
        if not colon or "\n" in path or value[:1].isspace() or value[-1:].isspace():
            return respell(value)
        written = self.written_tails.get(tail)
        if written is None:  # (split as ref_sync splits the reference, the part before the colon aside)
            found = respell(value)
            written = self.written_tails[tail] = found is AS_WRITTEN and tail_sync(tail) is not None
            return found
        return AS_WRITTEN if written else respell(value)
