"""BML as other realizers write it, read as BML 1.0: the lenient reader's adaptations of an element tree.

Greta, SmartBody, the Virtual Human Toolkit (NVBG), EMBR, SEMAINE and the BML drafts write BML that BML 1.0
does not accept: blocks in envelopes (``<act>``, ``<fml-apml>``) or several in one file, blocks and
behaviours without ids, the draft namespace, draft attribute names (``type=`` for the lexeme,
``rotation``, ``stroke_start``), negative start times, and behaviours of their own (``<animation>``,
``<lips>``, ``<saccade>``, ...). :func:`~agentsim.bml.documents.find_blocks` finds the blocks of a document
and :class:`Adapter` rewrites one block's tree into BML 1.0 (and the few types BML 1.0 lacks, see
:data:`~agentsim.bml.vocabulary.DIALECT_BEHAVIOURS`), noting every adaptation, so that the strict reader
can read it. What has no mapping is taken out and reported, one report per kind of element. The
vocabulary it maps (other realizers' names and what they are read as) is data:
:mod:`agentsim.bml.dialect_tables`.
"""

from __future__ import annotations

import math
import re

# The gesture lexicon (agentsim.animation.arms, with numpy) and the posture table are imported where foreign
# vocabulary is mapped or noted: reading BML 1.0 does without them.
from agentsim.bml import lexemes
from agentsim.bml.dialect_tables import (CLIP_WORDS, COMPOSITIONS, DEICTIC_TARGETS, DRAFT_NAMESPACES, EXPRESSIONS,
                                         JOINT_RANGE, SACCADE_DIRECTIONS, SYNC_ALIASES, TYPE_IS_LEXEME, UNMAPPED_HINTS)
from agentsim.bml.documents import (NUMBER, Envelope, implied_start, is_bml_uri, is_smartbody, remove_nodes,
                                    seconds, speech_marks)
from agentsim.bml.spelling import AS_WRITTEN, REF_SYNC, SYNC_SPELLINGS, References
from agentsim.core.xmltree import Captured, Node, held_attribute
from agentsim.bml.vocabulary import (BML_NAMESPACE, BMLA_BLOCK_ATTRIBUTES, BMLA_NAMESPACE, BMLT_NAMESPACE,
                                     CONSTRAINT_KINDS, DIALECT_BEHAVIOURS, EXTENSION_BEHAVIOURS)
from agentsim.animation.lexicon import Lexicon
from agentsim.core.block import BEHAVIOUR_TYPES

#: The prefix given to BMLA where older BMLT names are read as BMLA's.
BMLA_PREFIX = "bmla"
#: Lexemes of head movements, which EMBR writes as gestures.
HEAD_LEXEMES = lexemes.HEAD_LEXEMES
#: The sync point names that have an alias on some type, without those that hold another (``strokeStart`` holds
#: ``stroke``): a reference with none of them in its text is never retargeted.
_ALIASED = re.compile("|".join(sorted(
    name for name in {n for aliases in SYNC_ALIASES.values() for n in aliases}
    if not any(other != name and other in name for aliases in SYNC_ALIASES.values() for other in aliases))))
#: Elements of BMLA and BMLT, which only count in their own namespaces.
EXTENSION_LOCALS = set().union(*EXTENSION_BEHAVIOURS.values())
#: The BML 1.0 types whose draft attributes :meth:`Adapter.core` reads (it leaves the others as they are).
_CORE_REWRITTEN = frozenset(("gesture", "face", "head", "gaze"))
_UNSEEN = object()


class Adapter:
    """Rewrites one block's element tree into BML 1.0 as the strict reader reads it, noting each change.

    ``name_block`` gives an id to a block without one; foreign names become the lexemes of ``lexicon``
    (default: the built-in one).
    """

    def __init__(self, envelope: Envelope, name_block, drafts: bool = True, lexicon: Lexicon | None = None):
        self.envelope = envelope
        self.lexicon = lexicon if lexicon is not None else Lexicon.builtin()
        self.drafts = drafts  # False: no namespace declared in the document is a draft's
        self.node = envelope.node
        self.notes = envelope.notes
        self.losses = envelope.losses
        self.name_block = name_block
        self.unmapped: dict[str, list[Node]] = {}
        self.clips: dict[str, str] = {}
        self.curves: list[Node] = []
        self.prosody: list[Node] = []
        self.constraints: list[Node] = []
        self.written: dict[int, str] = {}  # id() of an element -> its name as written, before mapping
        self.references = References()  # how the block's references are spelled, each read once
        self._spelled: dict[str, str | None] = {}  # attribute name -> the sync point it spells (None: none)
        # whether a reference in a constraint names a sync point that has an alias (else retarget_refs has
        # nothing to do in the constraints)
        self._aliased_constraint = False

    # ------------------------------------------------------------------------------------------- the block
    def adapt(self) -> None:
        node = self.node
        self.declared_namespace = node.namespace
        if self.drafts:
            self.read_namespaces(node)
        if not node.attrs.get("id", "").strip():
            node.attrs["id"] = self.name_block()
            self.notes.add(f"block without id: named {node.attrs['id']}")
        if self.envelope.character and not node.attrs.get("characterId"):
            node.attrs["characterId"] = self.envelope.character
            self.notes.add(f"character {self.envelope.character!r} taken from the <participant> of the envelope")
        for key in ("character", "characterid", "agent"):
            if key in node.attrs and "characterId" not in node.attrs:
                node.attrs["characterId"] = node.attrs.pop(key).strip()
                self.notes.add(f"<bml {key}=...> read as characterId")
        composition = node.attrs.get("composition", "").strip()
        if composition.lower() in COMPOSITIONS:
            node.attrs["composition"] = COMPOSITIONS[composition.lower()]
            self.notes.add(f"composition {composition!r} (Greta's) read as {node.attrs['composition']}")
        for key in list(node.attrs):
            prefix, _, name = key.partition(":")
            if name and node.namespaces.get(prefix) == BMLT_NAMESPACE:
                value = node.attrs.pop(key)
                if name in BMLA_BLOCK_ATTRIBUTES:
                    node.attrs[f"{BMLA_PREFIX}:{name}"] = value
                    node.namespaces = {**node.namespaces, BMLA_PREFIX: BMLA_NAMESPACE}
                    self.notes.add(f"older BMLT block attribute {key} read as BMLA's")
                else:
                    self.notes.add(f"older BMLT block attribute {key} not needed; ignored")
        behaviours = self.behaviours(node)
        self.name_behaviours(behaviours)
        self.retarget_refs(behaviours, self.constraints)
        if self.declared_namespace != BML_NAMESPACE:
            # Greta's ways with time read otherwise valid BML 1.0 otherwise: only where BML 1.0 is not declared
            self.times_after_start(behaviours)
            self.shift_negative_times(behaviours)
        speeches = [b for b in behaviours if b.tag == "speech"]
        for curves in self.curves:
            if speeches and not self.sync_keys(curves):
                curves.attrs["start"] = f"{speeches[0].attrs['id']}:start"
                self.notes.add("<curves> without a time start with the speech (their keys are times in it)", curves)
        self.move_prosody(speeches)
        if self.clips:
            shown = ", ".join(f"{name!r} as {lexeme}" for name, lexeme in list(self.clips.items())[:6])
            more = f" and {len(self.clips) - 6} more" if len(self.clips) > 6 else ""
            self.notes.add(f"SmartBody/NVBG <animation> clips played as the closest gesture: {shown}{more}")
        if self.notes:  # a foreign document: its lexemes are among the adaptations (else the reader warns)
            self.note_lexemes(behaviours)
        for name, nodes in self.unmapped.items():
            hint = UNMAPPED_HINTS.get(name, UNMAPPED_HINTS.get(name.split(":")[-1], "no counterpart here"))
            count = f"{len(nodes)} <{name}> elements" if len(nodes) > 1 else f"<{name}>"
            self.losses.append((f"{count}: {hint}; not realized", nodes[0]))

    def note_lexemes(self, behaviours: list[Node]) -> None:
        """Say which lexemes of the foreign vocabulary have no motion of their own here, and what plays
        instead."""
        found = lexemes.fallbacks(((b.tag, b.attrs.get("id", ""), b.attrs) for b in behaviours), self.lexicon)
        self.notes.extend(lexemes.describe(found))
        self.notes.touch(*(b for b in behaviours if lexemes.fallback(b.tag, b.attrs, self.lexicon) is not None))

    def read_namespaces(self, node: Node) -> None:
        """The draft namespace is read as BML 1.0 (in every element's declarations)."""
        changed: dict[int, dict[str, str]] = {}
        drafts: set[str] = set()
        stack = [node]
        while stack:  # (every element, each on its own; most share their parent's declarations, one dict)
            n = stack.pop()
            key = id(n.namespaces)
            mapping = changed.get(key)
            if mapping is None:
                mapping = n.namespaces
                if any(uri in DRAFT_NAMESPACES for uri in mapping.values()):
                    drafts.update(uri for uri in mapping.values() if uri in DRAFT_NAMESPACES)
                    mapping = {p: (BML_NAMESPACE if uri in DRAFT_NAMESPACES else uri) for p, uri in mapping.items()}
                changed[key] = mapping
            n.namespaces = mapping
            if n.children:
                stack += [c for c in n.children if isinstance(c, Node)]
        for uri in sorted(drafts):
            self.notes.add(f"namespace {uri} (a BML draft) read as BML 1.0")

    def behaviours(self, parent: Node) -> list[Node]:
        """Map the behaviour elements under ``parent`` (and its ``<required>``) in place; returns them."""
        kept: list[Node | str] = []
        found: list[Node] = []
        for child in parent.children:
            if isinstance(child, str):
                kept.append(child)
                continue
            uri = child.namespace
            self.written[id(child)] = child.local
            self.notes.current = child  # what is noted while it is read touched it
            if child.local == "required" and is_bml_uri(uri):
                self.notes.current = None
                found.extend(self.behaviours(child))
                kept.append(child)
            elif child.local == "constraint" and is_bml_uri(uri) and self.constraint_refs(child):
                self.constraints.append(child)
                kept.append(child)
            elif uri == BMLT_NAMESPACE and child.local in EXTENSION_BEHAVIOURS[BMLA_NAMESPACE]:
                child.tag = f"{BMLA_PREFIX}:{child.local}"
                child.namespaces = {**child.namespaces, BMLA_PREFIX: BMLA_NAMESPACE}
                self.notes.add(f"older BMLT <bmlt:{child.local}> read as BMLA's")
                self.sync_attributes(child)
                found.append(child)
                kept.append(child)
            elif uri in EXTENSION_BEHAVIOURS and child.local in EXTENSION_BEHAVIOURS[uri]:
                self.sync_attributes(child)
                found.append(child)
                kept.append(child)
            elif child.local in ("pitchaccent", "boundary"):
                self.prosody.append(child)  # Greta's: they belong to the speech they name
            elif self.map_element(child):
                found.append(child)
                kept.append(child)
            else:
                self.unmapped.setdefault(child.tag, []).append(child)
        self.notes.current = None
        parent.children = kept
        return found

    # ------------------------------------------------------------------------------------------- elements
    def map_element(self, node: Node) -> bool:
        """Rewrite one behaviour element into a type we have; False if it has no mapping."""
        local = node.local
        if local in BEHAVIOUR_TYPES and local not in DIALECT_BEHAVIOURS and local not in EXTENSION_LOCALS:
            if not is_bml_uri(node.namespace):
                self.notes.add(f"<{node.tag}> (namespace {node.namespace or 'undeclared'}) read as BML <{local}>")
            new = self.core(node)
        else:
            mapped = getattr(self, f"map_{local.replace('-', '_')}", None)
            if mapped is None:
                return False
            new = mapped(node)
            if new is None:
                return False
        self.make_bml(node, new)
        self.attributes(node)
        return True

    def make_bml(self, node: Node, new_type: str) -> None:
        if node.tag != new_type:
            node.namespaces = {**node.namespaces, "": BML_NAMESPACE}
            node.tag = new_type
        elif node.namespace not in (None, "", BML_NAMESPACE):
            node.namespaces = {**node.namespaces, "": BML_NAMESPACE}

    def core(self, node: Node) -> str:
        """A BML 1.0 element, perhaps with draft attributes: ``type=`` naming the kind of behaviour (a
        pointing gesture, FACS, a head orientation), Greta's ``class=instance`` lexicon keys, EMBR's nods
        written as gestures, a face lexeme in a child element."""
        local, attrs = node.local, node.attrs
        if local not in _CORE_REWRITTEN:
            return local  # (nothing below rewrites another type)
        kind = attrs.get("type", "").strip()
        family, _, instance = kind.partition("=")
        family = family.strip().upper()
        pointing_self = instance.strip().upper().startswith("ME")
        if local == "gesture" and family in ("POINT", "POINTING", "DEICTIC") and not attrs.get("lexeme") \
                and not pointing_self:
            attrs.pop("type")
            if instance and "target" not in attrs:
                attrs["target"] = DEICTIC_TARGETS.get(instance.strip().rstrip("0123456789").upper(), "user")
            self.notes.add(f"<gesture type={kind!r}> (a draft) read as <pointing>")
            return "pointing"
        if local == "gesture" and attrs.get("lexeme", "").strip().upper() in HEAD_LEXEMES:
            self.notes.add(f"<gesture lexeme={attrs['lexeme']!r}> (a head movement written as a gesture) read as "
                           "<head>")
            attrs["lexeme"] = attrs["lexeme"].strip().upper()
            return "head"
        if local == "gesture" and instance and not attrs.get("lexeme"):
            attrs.pop("type")
            attrs["lexeme"] = family if family in self.lexicon.strokes else instance.strip().upper()
            self.notes.add("Greta's lexicon key type=\"class=instance\" read as the lexeme")
        if local == "gesture" and "hand" in attrs and "mode" not in attrs:
            hand = attrs.pop("hand").strip().upper()
            attrs["mode"] = {"LEFT": "LEFT_HAND", "RIGHT": "RIGHT_HAND", "BOTH": "BOTH_HANDS"}.get(hand, hand)
            self.notes.add("draft attribute hand= read as mode")
        if local == "face":
            if family == "FACS":
                attrs.pop("type")
                self.notes.add("<face type=\"facs\" au=...> read as <faceFacs>")
                return "faceFacs"
            lexeme = next((c.attrs.get("lexeme", "") for c in node.elements() if c.local == "lexeme"), "")
            if lexeme and not attrs.get("lexeme"):
                attrs["lexeme"] = lexeme
                self.notes.add("a face's lexeme given in a <lexeme> child read as its lexeme")
            if kind and not attrs.get("lexeme"):
                attrs.pop("type")
                word = (instance or family).strip().lower()
                if family == "MOUTH" and "shape" in attrs:
                    word = attrs.pop("shape").strip().lower()
                attrs["lexeme"] = EXPRESSIONS.get(word.rstrip("0123456789").split("_")[0], word.upper())
                self.notes.add(f"face type={kind!r} read as the expression {attrs['lexeme']}")
        if local == "head" and family == "ORIENT":
            attrs.pop("type")
            attrs.setdefault("target", (attrs.get("direction") or "").lower() or "user")
            attrs.pop("direction", None)
            self.notes.add("<head type=\"ORIENT\"> read as <headDirectionShift>")
            return "headDirectionShift"
        if local == "gaze":
            if kind:
                attrs.pop("type")
                self.notes.add("draft attribute type= of <gaze> not needed in BML 1.0; ignored")
            if "modality" in attrs and "influence" not in attrs:
                attrs["influence"] = attrs.pop("modality").strip().upper()
                self.notes.add("draft attribute modality= read as the gaze influence")
        return local

    def map_animation(self, node: Node) -> str:
        """SmartBody/NVBG ``<animation name>``: a gesture of the closest lexeme, or a beat, timing kept."""
        name = node.attrs.pop("name", "")
        low = name.lower()
        lexeme = next((lex for word, lex in CLIP_WORDS if word in low and lex in self.lexicon.strokes), "BEAT")
        node.attrs.setdefault("lexeme", lexeme)
        self.clips[name] = lexeme
        for key in ("speed", "ref"):
            node.attrs.pop(key, None)
        return "gesture"

    def map_body(self, node: Node) -> str | None:
        """SmartBody's ``<body posture>``: a posture shift (a lean if the clip's name says so, else a weight
        shift)."""
        name = node.attrs.pop("posture", None)
        if name is None:
            return None
        low = name.lower().replace("_", "")
        lexeme = next((p for p in self.lexicon.postures if p.lower().replace("_", "") in low), "WEIGHT_SHIFT")
        node.attrs.setdefault("lexeme", lexeme)
        self.notes.add(f"<body posture={name!r}> played as a posture shift ({lexeme})")
        return "postureShift"

    def map_torso(self, node: Node) -> str:
        """Greta's ``<torso>``: a posture shift."""
        self.notes.add("Greta's <torso> played as a posture shift")
        lexeme = node.attrs.pop("lexeme", "") or node.attrs.pop("type", "")
        reference = next((c.text().strip() for c in node.elements() if c.local == "description"), "")
        low = (lexeme + " " + reference).lower().replace("_", "").replace("=", "")
        node.attrs["lexeme"] = next((p for p in self.lexicon.postures if p.lower().replace("_", "") in low),
                                    "WEIGHT_SHIFT")
        return "postureShift"

    def map_saccade(self, node: Node) -> str | None:
        """SmartBody's ``<saccade direction magnitude duration>``: a short gaze of the eyes, that far off
        ahead. A saccade model (``mode=listen|talk|think``) has no mapping."""
        if "mode" in node.attrs and "magnitude" not in node.attrs:
            return None
        attrs = node.attrs
        try:
            direction = float(attrs.pop("direction", "0"))
            magnitude = float(attrs.pop("magnitude", "5"))
        except ValueError:
            return None
        attrs.pop("duration", None)
        attrs.setdefault("target", "user")
        attrs.setdefault("influence", "EYES")
        attrs["offsetAngle"] = f"{abs(magnitude):g}"
        sector = int(((180.0 - direction) % 360.0 + 22.5) // 45.0) % 8
        attrs["offsetDirection"] = SACCADE_DIRECTIONS[sector]
        self.notes.add("SmartBody's <saccade> played as a gaze of the eyes")
        return "gaze"

    def move_prosody(self, speeches: list[Node]) -> None:
        """Greta's pitch accents and boundaries go into the speech whose time markers they name, where the
        speech reading turns them into emphasis and pauses."""
        by_id = {s.attrs["id"]: s for s in speeches}
        for node in self.prosody:
            ref = node.attrs.get("start", "") or node.attrs.get("end", "")
            owner = by_id.get(ref.split(":", 1)[0]) if ":" in ref else (speeches[0] if len(speeches) == 1 else None)
            if owner is None:
                self.losses.append((f"<{node.tag}>: it names no time marker of a speech in this block; not "
                                    "realized", node))
            else:
                owner.children.append(node)

    def map_lips(self, node: Node) -> str:
        self.notes.add("SmartBody's <lips viseme> played as visemes on the jaw and lips")
        return "lips"

    def map_event(self, node: Node) -> str:
        """SmartBody's ``<event message>``: a sync point without motion, at the time it names."""
        attrs = node.attrs
        for key in ("stroke", "ready", "relax", "time"):
            if key in attrs and "start" not in attrs:
                attrs["start"] = attrs.pop(key)
            attrs.pop(key, None)
        self.notes.add("SmartBody's <event> realized as a sync point without motion (start = end)")
        return "event"

    def map_curves(self, node: Node) -> str | None:
        """SmartBody's ``<curves>`` of ``<curve name num_keys>t v in out ...</curve>``: face channels."""
        params: list[Node] = []
        for curve in node.elements():
            name = curve.attrs.get("name", "").strip()
            try:
                numbers = [float(x) for x in curve.text().split()]
            except ValueError:
                self.losses.append((f"<curve name={name!r}>: its keys are not numbers; not realized", curve))
                continue
            keys = int(float(curve.attrs.get("num_keys", "0") or 0))
            step = 4 if keys and len(numbers) == 4 * keys else 2
            pairs = [(numbers[i], numbers[i + 1]) for i in range(0, len(numbers) - 1, step)]
            if not name or not pairs:
                continue
            value = " ".join(f"{t:g} {v:g}" for t, v in pairs)
            params.append(Node("parameter", {"name": f"curve:{name}", "value": value}, curve.line, curve.column,
                               {"": BMLT_NAMESPACE}))
        node.children = list(params)
        self.notes.add("SmartBody's <curves> played as keyframed jaw and lip channels" if params else
                       "an empty <curves> realized as a face motion without keys")
        self.curves.append(node)
        return "curves"

    # ------------------------------------------------------------------------------------------- attributes
    def attributes(self, node: Node) -> None:
        attrs = node.attrs
        kind = node.tag
        if kind in TYPE_IS_LEXEME and attrs.get("type", "").strip() and not attrs.get("lexeme", "").strip():
            attrs["lexeme"] = attrs.pop("type").strip().upper()
            self.notes.add("draft attribute type= read as the lexeme")
        if kind == "head":
            for key in ("rotation", "action"):
                value = attrs.get(key, "").strip()
                if key == "rotation" and value and not attrs.get("lexeme"):
                    attrs["lexeme"] = attrs.pop(key).upper()
                    self.notes.add("draft attribute rotation= read as the lexeme of the head movement")
                elif key in attrs:
                    attrs.pop(key)
                    self.notes.add(f"draft attribute {key}={value!r} of <head> not needed; ignored")
            if "repeats" in attrs and "repetition" not in attrs:
                attrs["repetition"] = attrs.pop("repeats")
                self.notes.add("repeats= read as repetition")
        if kind in ("gaze", "gazeShift", "pointing", "headDirectionShift"):
            for old, new in (("direction", "offsetDirection"), ("angle", "offsetAngle")):
                if old in attrs and new not in attrs:
                    attrs[new] = attrs.pop(old)
                    self.notes.add(f"draft attribute {old}= read as {new}")
        for key in list(attrs):
            if key in ("agent", "character"):
                attrs.pop(key)
                self.notes.add(f"per-behaviour {key}= ignored: every behaviour plays on its block's character")
            elif ":" in key:
                prefix = key.split(":", 1)[0]
                if key == "sbm:joint-range" and kind in ("gaze", "gazeShift"):
                    value = attrs.pop(key).upper()
                    influence = next((inf for joint, inf in JOINT_RANGE if joint in value), None)
                    if influence:
                        attrs.setdefault("influence", influence)
                        self.notes.add("sbm:joint-range read as the gaze influence")
                elif is_smartbody(prefix, node.namespaces.get(prefix)):
                    attrs.pop(key)
                    self.notes.add(f"SmartBody attribute {key} ignored")
        if kind == "speech":
            nvbg = [key for key in ("ready", "stroke", "relax", "strokeStart", "strokeEnd") if key in attrs]
            if nvbg:
                if "end" in attrs:
                    nvbg.append("end")  # a template's times (0.1, 0.2), not the speech's
                for key in nvbg:
                    attrs.pop(key)
                self.notes.add(f"speech timing attributes {', '.join(nvbg)} (NVBG's placeholders) ignored: the "
                               "speech takes as long as it takes to say")
            if "wait" in attrs and "start" not in attrs:
                attrs["start"] = attrs.pop("wait")
                self.notes.add("EMBR's wait= of a speech read as its start")
        self.sync_attributes(node)

    def sync_attributes(self, node: Node) -> None:
        """Sync point names as the drafts and EMBR spell them (``stroke_start``, ``strokeENd``), and as
        SmartBody names them for every kind of behaviour (a face's ``ready`` is its attackPeak), in the
        attributes and in the references; a sync point the behaviour does not have is left out."""
        syncs = BEHAVIOUR_TYPES[node.local].syncs if node.local in BEHAVIOUR_TYPES else ()
        aliases = SYNC_ALIASES.get(node.local, {})
        spelled = self._spelled
        for key in list(node.attrs):
            canonical = spelled.get(key, _UNSEEN)
            if canonical is _UNSEEN:
                canonical = spelled[key] = SYNC_SPELLINGS.get(key.lower().replace("_", "").replace("-", ""))
            if canonical is None:
                continue
            if canonical not in syncs and aliases.get(canonical) in syncs:
                if aliases[canonical] in node.attrs:
                    node.attrs.pop(key)
                    self.notes.add(f"sync point {key} of <{node.local}> left out (it has no such sync point, and "
                                   f"{aliases[canonical]} is given)")
                    continue
                self.notes.add(f"sync point {key} of <{node.local}> read as {aliases[canonical]}")
                canonical = aliases[canonical]
            elif canonical != key and canonical in syncs:
                self.notes.add(f"sync point {key} read as {canonical}")
            if canonical not in syncs:
                node.attrs.pop(key)
                self.notes.add(f"sync point {key} of <{node.local}> left out: it has no such sync point")
                continue
            if canonical != key:
                if canonical in node.attrs:
                    node.attrs.pop(key)
                    continue
                node.attrs[canonical] = node.attrs.pop(key)
            node.attrs[canonical] = self.ref(node.attrs[canonical])

    def constraint_refs(self, node: Node) -> bool:
        """Respell the references of a ``<constraint>`` whose elements are all ``<synchronize>``, ``<before>``
        and ``<after>`` (:meth:`ref`), and say whether it is one: a ``<constraint>`` with no element, or
        with another one, is left as it is (then False)."""
        if type(node) is Captured and node.events is not None and self.held_kept(node.events):
            return True  # (its references all kept as written: nothing to do, and no node made of it)
        elements = node.elements()
        if not elements or not {c.local for c in elements} <= CONSTRAINT_KINDS:
            return False
        references, notes = self.references, self.notes  # (Adapter.ref, without a call per reference)
        aliased = False
        for child in elements:
            for n in (child, *child.children) if child.children else (child,):
                value = None if isinstance(n, str) else n.attrs.get("ref")
                if value is not None:
                    found = references.found(value)
                    if found is AS_WRITTEN:  # (most references)
                        continue
                    if found[1] is not None:
                        notes.add(found[1])
                    n.attrs["ref"] = found[0]
                    aliased = aliased or found[2]
        self._aliased_constraint = self._aliased_constraint or aliased
        return True

    def held_kept(self, events: list) -> bool:
        """Whether the content of a ``<constraint>`` held as events (:class:`~agentsim.core.xmltree.Captured`)
        has elements, all ``<synchronize>``, ``<before>`` and ``<after>`` (as written, no prefix), and keeps
        every reference of theirs and of their children as written (what :meth:`constraint_refs` reads)."""
        level, elements, kept = 0, False, self.references.kept
        for event in events:
            if event is None:
                level -= 1
            elif type(event) is tuple:
                level += 1
                if level == 1:
                    if event[0] not in CONSTRAINT_KINDS:
                        return False
                    elements = True
                elif level > 2:
                    continue
                attrs = event[1]  # (expat's list: its ref, the usual one, first)
                if not attrs:
                    continue
                value = attrs[1] if attrs[0] == "ref" else held_attribute(attrs, "ref")
                if value is not None and not kept(value):
                    return False
        return elements

    def ref(self, value: str) -> str:
        """A reference with its sync point spelled as BML does, noting the respelling (a block repeats its
        references: each one is read once)."""
        found = self.references.found(value)
        if found is AS_WRITTEN:
            return value
        if found[1] is not None:
            self.notes.add(found[1])
        return found[0]

    def retarget_refs(self, behaviours: list[Node], constraints: list[Node]) -> None:
        """References to a sync point that the behaviour referred to has under another name (SmartBody's
        ``sp1:relax`` of a speech is its end, a face's ``ready`` its attackPeak)."""
        block_id = self.node.attrs.get("id", "")
        kinds = {b.attrs.get("id", ""): b.local for b in behaviours}
        marks = {b.attrs.get("id", ""): speech_marks(b) for b in behaviours if b.local == "speech"}

        def retarget(value: str) -> tuple[str, str | None]:
            if not _ALIASED.search(value):  # (most references: no sync point with an alias)
                return value, None
            match = REF_SYNC.match(value.strip())
            if not match:
                return value, None
            path = match.group("path")[:-1].split(":")
            if len(path) == 2 and path[0] == block_id:
                path = path[1:]
            if len(path) != 1 or path[0] not in kinds:
                return value, None
            kind, sync = kinds[path[0]], match.group("sync")
            if sync in BEHAVIOUR_TYPES[kind].syncs or sync in marks.get(path[0], ()):
                return value, None
            alias = SYNC_ALIASES.get(kind, {}).get(sync)
            if alias is None:
                return value, None
            return (f"{match.group('path')}{alias}{match.group('rest')}",
                    f"{path[0]}:{sync} read as {path[0]}:{alias} (a <{kind}> has no {sync})")

        done: dict[str, tuple[str, str | None]] = {}  # (a block repeats its references: each is read once)

        def fix(value: str) -> str:
            found = done.get(value)
            if found is None:
                found = done[value] = retarget(value)
            if found[1] is not None:
                self.notes.add(found[1])
            return found[0]

        for b in behaviours:
            for key in self.sync_keys(b):
                b.attrs[key] = fix(b.attrs[key])
        if not self._aliased_constraint:
            return  # (no reference in the constraints can be retargeted)
        for c in constraints:
            for child in c.children:
                if not isinstance(child, Node):
                    continue
                for n in (child, *child.children):
                    if isinstance(n, Node) and "ref" in n.attrs:
                        n.attrs["ref"] = fix(n.attrs["ref"])

    # ------------------------------------------------------------------------------------------- ids, times
    def name_behaviours(self, behaviours: list[Node]) -> None:
        """Behaviours without id are named ``<element><n>``, the element's name as written without a prefix
        (n counts the id-less elements of that name from 1, in document order, skipping ids in use); a
        repeated id becomes ``<id>_<k>`` (k from 2)."""
        used = {b.attrs["id"].strip() for b in behaviours if b.attrs.get("id", "").strip()}
        counters: dict[str, int] = {}
        seen: set[str] = set()
        named: list[str] = []
        first: dict[str, Node] = {}
        merged: list[Node] = []
        for b in behaviours:
            bid = b.attrs.get("id", "").strip()
            if not bid:
                written = self.written.get(id(b), b.local)
                n = counters.get(written, 0)
                while True:
                    n += 1
                    bid = f"{written}{n}"
                    if bid not in used:
                        break
                counters[written] = n
                used.add(bid)
                b.attrs["id"] = bid
                named.append(bid)
            elif bid in seen and self.merges(first[bid], b):
                for key, value in b.attrs.items():
                    first[bid].attrs.setdefault(key, value)
                merged.append(b)
                self.notes.add(f"repeated <{b.local} id={bid!r}> that only adds attributes merged into the first "
                               "(Greta writes one attribute to an element)", first[bid])
                continue
            elif bid in seen:
                k = 2
                while f"{bid}_{k}" in used:
                    k += 1
                new = f"{bid}_{k}"
                used.add(new)
                b.attrs["id"] = new
                self.notes.add(f"duplicate behaviour id {bid!r} renamed {new!r} (references to {bid!r} mean "
                               "the first)", b)
                bid = new
            seen.add(bid)
            first.setdefault(bid, b)
        if merged:
            gone = {id(n) for n in merged}
            behaviours[:] = [b for b in behaviours if id(b) not in gone]
            remove_nodes(self.node, gone)
        named_ids = set(named)
        self.notes.touch(*(b for b in behaviours if b.attrs.get("id") in named_ids))
        if named:
            shown = ", ".join(named[:8]) + (f" and {len(named) - 8} more" if len(named) > 8 else "")
            self.notes.add(f"{len(named)} behaviour{'s' if len(named) > 1 else ''} without id named by element and "
                           f"number: {shown}")

    def times_after_start(self, behaviours: list[Node]) -> None:
        """Greta's older BML writes a behaviour's later times as seconds after its start (``start="5.34"
        stroke="0.68" end="2.62"``): a number smaller than the behaviour's own start is read so."""
        for b in behaviours:
            start = b.attrs.get("start", "")
            if not NUMBER.match(start):
                continue
            t0 = float(start)
            for key in self.sync_keys(b):
                value = b.attrs[key]
                if key != "start" and NUMBER.match(value) and float(value) < t0:
                    b.attrs[key] = seconds(t0 + float(value))
                    self.notes.add(f"{key}= smaller than start=: read as seconds after the start (Greta)", b)

    def merges(self, first: Node, again: Node) -> bool:
        """Whether a repeated id is Greta's way of giving one more attribute: same element, no time of its
        own, and only attributes the first lacks."""
        extra = {k for k in again.attrs if k != "id"}
        return (again.local == first.local and not self.sync_keys(again) and bool(extra)
                and not extra & set(first.attrs) and not again.elements())

    def shift_negative_times(self, behaviours: list[Node]) -> None:
        """Greta writes times before the block's start (``start="-0.2"``, or a ``ready="0"`` that leaves no
        time to prepare) and plays the block later by as much: every number in the block moves later by
        the earliest start's distance before 0 (a behaviour's start as its numbers and its preferred timing
        put it), and behaviours that had no time of their own start at that time."""
        numbers = [(b, key) for b in behaviours for key in self.sync_keys(b) if NUMBER.match(b.attrs[key])]
        timed = {id(b) for b, _ in numbers}  # (the behaviours with a number: looked up, not searched for)
        earliest = min((implied_start(b, self.lexicon) for b in behaviours if id(b) in timed), default=0.0)
        if not earliest < -1e-9 or not math.isfinite(earliest):
            return
        shift = -earliest
        for b, key in numbers:
            b.attrs[key] = seconds(float(b.attrs[key]) + shift)
        for b in behaviours:
            if not self.sync_keys(b) and b.local not in ("interrupt", "activate"):
                b.attrs["start"] = seconds(shift)
        self.notes.add(f"times before the block start (the earliest behaviour would start at {earliest:.3f} s): "
                       f"the whole block plays {shift:.3f} s later, its relative timing kept", *behaviours)

    @staticmethod
    def sync_keys(node: Node) -> list[str]:
        syncs = BEHAVIOUR_TYPES[node.local].syncs if node.local in BEHAVIOUR_TYPES else ()
        return [k for k in node.attrs if k in syncs]
