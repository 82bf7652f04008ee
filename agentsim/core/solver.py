"""Timing one BML block: constraints become shared time pegs, behaviours get keys tied to them.

The algorithm follows the SmartBody/Elckerlyc scheduler. Sync points that constraints tie together share
one peg (a weighted union-find keeps their offsets). Behaviours are placed one at a time in document
order, except that a behaviour tied to a time already known (a number, an anticipator, another block, a
behaviour placed before) goes before behaviours that know nothing yet. Each planner resolves the unknown
times of its behaviour from the known ones (preferred durations, linear stretch, rigid speech). Then
``before``/``after`` constraints are honoured by moving behaviours that are free to move, a tied cluster
that would start before the block start is shifted later, invalid behaviours and conflicts on one body
resource are dropped with a warning, and a block whose ``<required>`` part fails is refused.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field
from typing import Callable, Protocol

from agentsim.core.block import BEHAVIOUR_TYPES, Behaviour, Block, Constraint, SyncRef
from agentsim.core.engine import Engine
from agentsim.errors import ScheduleError
from agentsim.core.pegboard import OffsetPeg, PegBoard, TimePeg
from agentsim.core.timed import EPSILON, BlockRun, KeyRef, TimedBehaviour

TOLERANCE = 1e-6

#: Behaviours with a preparation before their stroke, which may be shortened to fit a block that starts later
#: than their preparation would (see :meth:`BlockSolver.shorten_preparation`).
PREPARED = ("gesture", "pointing")
#: How short that preparation may become: this fraction of its preferred length (a beat's 0.45 s from its
#: start to its stroke: 0.15 s).
MIN_PREPARATION = 1 / 3


class AnticipatorLookup(Protocol):
    """Finds ``anticipators:<id>:<sync>``; raises ScheduleError if there is no such peg."""

    def __call__(self, anticipator_id: str, sync_id: str) -> TimePeg: ...


@dataclass
class Issue:
    """Something the solver could not do, to be reported as warning feedback."""

    warning_type: str
    description: str
    behaviours: list[str] = field(default_factory=list)


class _Ties:
    """Weighted union-find over sync points: ``T(x) = T(parent) + delta``."""

    def __init__(self) -> None:
        self.parent: list[int] = []
        self.delta: list[float] = []
        self.fixed: list[tuple[TimePeg, float] | None] = []  # T(node) = peg.time + offset, for fixed nodes
        self.fixed_node: dict[int, int] = {}  # root -> a fixed node in its group

    def add(self, fixed: tuple[TimePeg, float] | None = None) -> int:
        n = len(self.parent)
        self.parent.append(n)
        self.delta.append(0.0)
        self.fixed.append(fixed)
        if fixed is not None:
            self.fixed_node[n] = n
        return n

    def find(self, x: int) -> tuple[int, float]:
        parent = self.parent[x]
        if parent == x:  # (a root, or a node tied to one: the usual cases, told without a walk)
            return x, 0.0
        if self.parent[parent] == parent:
            return parent, self.delta[x]
        path = []
        while self.parent[x] != x:
            path.append(x)
            x = self.parent[x]
        root, total = x, 0.0
        for node in reversed(path):
            total += self.delta[node]
            self.delta[node] = total
            self.parent[node] = root
        return (root, self.delta[path[0]]) if path else (root, 0.0)

    def union(self, a: int, b: int, d: float) -> str | None:
        """Tie ``T(a) = T(b) + d``; returns a reason if that contradicts the ties so far."""
        parent, delta = self.parent, self.delta
        # (what find gives, told here without its call for a root or a node tied to one: the usual cases)
        ra = parent[a]
        if ra == a:
            da = 0.0
        elif parent[ra] == ra:
            da = delta[a]
        else:
            ra, da = self.find(a)
        rb = parent[b]
        if rb == b:
            db = 0.0
        elif parent[rb] == rb:
            db = delta[b]
        else:
            rb, db = self.find(b)
        if ra == rb:
            if abs(da - (db + d)) > TOLERANCE:
                return "contradictory constraints: they put it at two different times"
            return None
        fa, fb = self.fixed_node.get(ra), self.fixed_node.get(rb)
        if fa is not None and fb is not None:
            return "it ties together two times that are fixed independently"
        parent[ra] = rb
        delta[ra] = db + d - da
        if fa is not None:
            self.fixed_node[rb] = fa
        self.fixed_node.pop(ra, None)
        return None


class BlockSolver:
    """Resolves the timing of one block into timed behaviours tied to pegs."""

    def __init__(self, block: Block, run: BlockRun, board: PegBoard, engines: dict[str, Engine],
                 anticipator_peg: AnticipatorLookup, existing: Callable[[], list[TimedBehaviour]]):
        self.block = block
        self.run = run
        self.block_peg = run.block_peg
        self.board = board
        self.engines = engines
        self.anticipator_peg = anticipator_peg
        self.existing = existing
        self.issues: list[Issue] = []
        self.failed = False
        self.ties = _Ties()
        self.block_node = self.ties.add((self.block_peg, 0.0))
        self.nodes: dict[tuple, int] = {}  # tie nodes of anticipators' and other blocks' sync points
        # the tie nodes of this block's sync points: behaviour id -> sync id -> node
        self.local_nodes: dict[str, dict[str, int]] = {}
        self.dropped: dict[str, tuple[str, str]] = {}  # behaviour id -> (warning type, reason)
        self.group_peg: dict[int, OffsetPeg] = {}
        self._group_name = f"{block.id}:group"  # (the name of every group's peg)
        self.anchors: list[OffsetPeg] = []
        self.timed: dict[str, TimedBehaviour] = {}
        self._anchor_cache: dict[int, int | None] = {}
        # what each reference to this block's own sync points stands for, by the reference's id (the
        # references live as long as the block; a block refers to one sync point many times)
        self._local_refs: dict[int, tuple[int, float]] = {}
        self._sync_sets: dict[str, tuple[object, frozenset[str]]] = {}
        # the times of each timed behaviour, computed once for every phase that reads them after placing, and
        # made again when a peg moved (the generation of the pegs' time cache changed: see times_of)
        self._cache = self.block_peg.cache
        self._times: dict[TimedBehaviour, list[float | None]] = {}
        self._times_in = -1

    # ----------------------------------------------------------------- problems
    def drop(self, behaviour_id: str, reason: str, kind: str = "IMPOSSIBLE_TO_SCHEDULE") -> None:
        if behaviour_id in self.dropped:
            return
        self.dropped[behaviour_id] = (kind, reason)
        self.issues.append(Issue(kind, f"{behaviour_id}: {reason}; behaviour dropped", [behaviour_id]))
        beh = self.block.behaviour(behaviour_id)
        if beh is not None and beh.required:
            self.fail(f"required behaviour {behaviour_id} cannot be realized ({reason})")
        timed = self.timed.pop(behaviour_id, None)
        if timed is not None:
            timed.drop()

    def fail(self, reason: str) -> None:
        if not self.failed:
            self.failed = True
            self.issues.append(Issue("IMPOSSIBLE_TO_SCHEDULE", f"block refused: {reason}",
                                     [b.id for b in self.block.behaviours]))

    # ----------------------------------------------------------------- references
    def node(self, ref: SyncRef) -> tuple[int, float]:
        """The tie node a reference stands for, and its offset. Raises ScheduleError if it is dangling."""
        found = self._local_refs.get(id(ref))  # (one to this block's own sync points, met before)
        if found is not None:
            return found
        kind, offset, block, behaviour, sync, _, _ = ref  # (its fields at once)
        if kind == "absolute":
            return self.block_node, offset
        if kind == "anticipator":
            key = ("anticipator", ref.anticipator, ref.sync)
            if key not in self.nodes:
                peg = self.anticipator_peg(ref.anticipator, ref.sync)
                if peg.time is None:
                    raise ScheduleError(f"anticipator {ref.anticipator!r} has no prediction for {ref.sync!r} yet")
                self.nodes[key] = self.ties.add((peg, 0.0))
            return self.nodes[key], ref.offset
        if block is None or block == self.block.id:
            nodes = self.local_nodes.get(behaviour)
            node = nodes.get(sync) if nodes is not None else None
            if node is not None:  # a sync point referred to before (by another reference): known to exist
                found = self._local_refs[id(ref)] = (node, offset)
                return found
        else:
            key = ("block", ref.block, ref.behaviour, ref.sync)
            if key not in self.nodes:
                found = self.board.find_sync(ref.block, ref.behaviour, ref.sync)
                if found is None:
                    raise ScheduleError(f"no sync point {ref.target()} in a planned block")
                self.nodes[key] = self.ties.add(found)
            return self.nodes[key], ref.offset
        node = self._new_node(behaviour, sync, nodes)
        if node is None:
            if self.block.behaviour(behaviour) is None:
                raise ScheduleError(f"no behaviour {behaviour!r} in block {self.block.id}")
            raise ScheduleError(f"behaviour {behaviour!r} has no sync point {sync!r}")
        found = self._local_refs[id(ref)] = (node, offset)
        return found

    def _new_node(self, behaviour_id: str, sync_id: str, nodes: dict[str, int] | None) -> int | None:
        """The new node of a sync point of this block that has none yet (``nodes``: its behaviour's nodes so
        far, if any); None if there is no such sync point (:meth:`node` says why)."""
        beh = self.block.behaviour(behaviour_id)
        if beh is None:
            return None
        syncs = beh.sync_ids  # (a short list is searched as it is; a speech's thousands, in a set)
        if sync_id not in (syncs if len(syncs) <= 16 else self._sync_set(beh)):
            return None
        if nodes is None:  # (what local_node does, with the look-up above: the sync point has no node yet)
            nodes = self.local_nodes[beh.id] = {}
        node = nodes[sync_id] = self.ties.add()
        return node

    def _sync_set(self, beh) -> frozenset[str]:
        """The sync ids of ``beh`` as a set (a speech has thousands: references to them are looked up in
        constant time), made again if they change."""
        held = self._sync_sets.get(beh.id)
        if held is None or held[0] is not beh or len(held[1]) != len(beh.sync_ids):
            held = self._sync_sets[beh.id] = (beh, frozenset(beh.sync_ids))
        return held[1]

    def local_node(self, behaviour_id: str, sync_id: str) -> int:
        nodes = self.local_nodes.get(behaviour_id)
        if nodes is None:
            nodes = self.local_nodes[behaviour_id] = {}
        node = nodes.get(sync_id)
        if node is None:
            node = nodes[sync_id] = self.ties.add()
        return node

    # ----------------------------------------------------------------- ties
    def tie_all(self) -> list[tuple[Constraint, list[tuple[int, float, SyncRef]], tuple[int, float, SyncRef]]]:
        """Apply synchronisations; return the before/after constraints with their resolved nodes."""
        for beh in self.block.behaviours:
            if BEHAVIOUR_TYPES[beh.type].name not in self.engines:
                self.drop(beh.id, f"no engine realizes <{beh.type}>", "BEHAVIOR_TYPE_NOT_SUPPORTED")
        for beh in self.block.behaviours:
            for sync_id, ref in beh.refs.items():
                if beh.id in self.dropped:
                    break
                try:
                    target, offset = self.node(ref)
                except ScheduleError as exc:
                    self.drop(beh.id, f"{sync_id}={ref.text!r}: {exc}")
                    continue
                reason = self.ties.union(self.local_node(beh.id, sync_id), target, offset)
                if reason:
                    self.drop(beh.id, f"{sync_id}={ref.text!r}: {reason}")
        inequalities = []
        # (what node() gives for a sync point of this block that has its node already, found here without
        # the call: a block's constraints name thousands)
        local_nodes, own = self.local_nodes, (None, self.block.id)
        union, node_of, new_node = self.ties.union, self.node, self._new_node
        for constraint in self.block.constraints:
            resolved = []
            for ref in constraint.refs:
                kind, offset, block, behaviour, sync, _, _ = ref  # (its fields at once)
                if kind == "sync" and block in own:
                    nodes = local_nodes.get(behaviour)
                    node = nodes.get(sync) if nodes is not None else None
                    if node is None:
                        node = new_node(behaviour, sync, nodes)
                    if node is not None:
                        resolved.append((node, offset, ref))
                        continue
                try:
                    found = node_of(ref)
                except ScheduleError as exc:
                    self.constraint_issue(constraint, f"reference {ref.text!r} ignored: {exc}")
                    continue
                resolved.append((found[0], found[1], ref))
            if constraint.kind == "synchronize":
                if resolved:
                    n0, o0, first = resolved[0]
                for node, offset, ref in resolved[1:]:
                    reason = union(n0, node, offset - o0)
                    if reason:
                        blame = ref if ref.kind == "sync" else first
                        self.constraint_issue(constraint, f"cannot synchronise {ref.text!r}: {reason}", blame)
            else:
                ref = constraint.anchor
                nodes = local_nodes.get(ref.behaviour) if ref.block in own and ref.kind == "sync" else None
                node = nodes.get(ref.sync) if nodes is not None else None
                if node is not None:
                    inequalities.append((constraint, resolved, (node, ref.offset, ref)))
                    continue
                try:
                    anchor = self.node(ref)
                except ScheduleError as exc:
                    self.constraint_issue(constraint, f"constraint ignored: {exc}")
                    continue
                inequalities.append((constraint, resolved, (*anchor, ref)))
        return inequalities

    def constraint_issue(self, constraint: Constraint, reason: str, ref: SyncRef | None = None) -> None:
        where = f" (line {constraint.line}, column {constraint.column})" if constraint.line else ""
        if ref is not None and ref.kind == "sync" and (ref.block in (None, self.block.id)):
            self.drop(ref.behaviour, f"<{constraint.kind}>{where}: {reason}")
        else:
            self.issues.append(Issue("IMPOSSIBLE_TO_SCHEDULE", f"<{constraint.kind}>{where}: {reason}"))
        if constraint.required:
            self.fail(f"required constraint{where} cannot be met: {reason}")

    # ----------------------------------------------------------------- placing
    def solve(self) -> list[TimedBehaviour]:
        inequalities = self.tie_all()
        if self.failed:
            return []
        members: dict[int, list[int]] = {}
        behaviours = self.block.behaviours
        find, parent = self.ties.find, self.ties.parent
        for index, beh in enumerate(behaviours):
            nodes = self.local_nodes.get(beh.id)
            if not nodes:
                continue
            for node in nodes.values():  # (each of its sync points tied: in any order, the same index)
                root = parent[node]  # (its root as find gives it, told without the call in the usual cases)
                if parent[root] != root:
                    root = find(node)[0]
                group = members.get(root)
                if group is None:
                    members[root] = [index]
                else:
                    group.append(index)
        # Among behaviours tied to known times, rigid ones (speech) go first: the others can stretch.
        priority = [(0 if self.engines[b.type].planner.rigid else 1, i) if b.type in self.engines else (1, i)
                    for i, b in enumerate(behaviours)]
        ready: list[tuple[int, int]] = []
        for root, fixed in list(self.ties.fixed_node.items()):
            peg, offset = self.ties.fixed[fixed]
            _, d = self.ties.find(fixed)
            self.group_peg[root] = OffsetPeg(peg, offset - d, name=self._group_name)
            ready.extend(priority[i] for i in members.get(root, ()))
        heapq.heapify(ready)
        placed = [False] * len(behaviours)
        next_free = 0
        while True:
            index = None
            while ready:
                _, candidate = heapq.heappop(ready)
                if not placed[candidate]:
                    index = candidate
                    break
            if index is None:
                while next_free < len(behaviours) and placed[next_free]:
                    next_free += 1
                if next_free == len(behaviours):
                    break
                index = next_free
            placed[index] = True
            beh = behaviours[index]
            if beh.id in self.dropped:
                continue
            for root in self.place(beh):
                for other in members.get(root, ()):
                    if not placed[other]:
                        heapq.heappush(ready, priority[other])
        self.drop_dependants()
        self.honour_inequalities(inequalities)
        if self.shift_clusters(inequalities):
            self.check_inequalities(inequalities)
        self.check_validity()
        self.check_resources()
        if self.failed:
            return []
        return [self.timed[b.id] for b in behaviours if b.id in self.timed]

    def place(self, beh: Behaviour) -> list[int]:
        """Resolve and tie one behaviour; returns the groups whose time became known."""
        engine = self.engines[beh.type]
        planner = engine.planner
        known: dict[str, float] = {}
        groups: dict[str, tuple[int, float]] = {}
        nodes = self.local_nodes.get(beh.id)
        group_peg = self.group_peg
        if nodes:
            base = self.block_peg.time
            find, parent, delta = self.ties.find, self.ties.parent, self.ties.delta
            # (its tied sync points, in the order they were tied: what is made of them does not depend on it)
            for sync_id, node in nodes.items():
                root = parent[node]  # (what find gives, told without its call for a root or a node tied to one)
                if root == node:
                    d = 0.0
                elif parent[root] == root:
                    d = delta[node]
                else:
                    root, d = find(node)
                groups[sync_id] = root, d
                peg = group_peg.get(root)
                if peg is not None:
                    known[sync_id] = peg.time + d - base
        try:
            preferred = planner.preferred(beh)
            times = planner.resolve(beh, known, preferred=preferred)
            if len(groups) - len(known) > 1:  # (else no two sync points of unknown time: none implies another's)
                implied = self.self_ties(beh, groups, known, times)
                if implied:
                    times = planner.resolve(beh, {**known, **implied}, preferred=preferred)
        except ScheduleError as exc:
            self.drop(beh.id, str(exc), exc.warning_type)
            return []
        except Exception as exc:  # a planner or backend failed on this behaviour: report, keep going
            self.drop(beh.id, f"{type(exc).__name__}: {exc}")
            return []
        sync_ids = beh.sync_ids
        n = len(sync_ids)
        keys: list[KeyRef | None] = [None] * n
        refs: dict[int, KeyRef] = {}
        if known:  # (each known sync point found where it is; the first of a name, as resolve finds it)
            index = sync_ids.index
            for sync_id in known:
                i = index(sync_id)
                root, d = groups[sync_id]
                keys[i] = refs[i] = KeyRef(group_peg[root], d)
        if not refs:
            anchor = OffsetPeg(self.block_peg, times[0], name=f"{self.block.id}:{beh.id}:anchor", anchor=True)
            self.anchors.append(anchor)
            refs[0] = KeyRef(anchor, 0.0)
        newly_known: list[int] = []
        owns: list[bool] | None = None  # which sync points' groups get their time from this behaviour
        only = next(iter(refs)) if len(refs) == 1 else None  # (the nearest key when there is one)
        every, last = planner.rigid, n - 1  # (which sync points get keys: a rigid behaviour's all)
        for i, sync_id in enumerate(sync_ids):
            if keys[i] is not None:
                continue
            tied = sync_id in groups
            if not (tied or every or i == 0 or i == last):
                continue
            j = only if only is not None else min(refs, key=lambda r: (abs(preferred[r] - preferred[i]), r))
            ref_key = refs[j]
            offset = ref_key.offset + times[i] - times[j]
            if tied:
                root, d = groups[sync_id]
                peg = group_peg.get(root)
                if peg is None:
                    peg = group_peg[root] = OffsetPeg(ref_key.peg, offset - d, name=self._group_name)
                    newly_known.append(root)
                    if owns is None:
                        owns = [False] * n
                    owns[i] = True
                keys[i] = KeyRef(peg, d)
            else:
                keys[i] = KeyRef(ref_key.peg, offset)
        tied = fixed = None  # (None: none of its keys is tied, or none of those held by a fixed time)
        if groups:
            tied = [sync_id in groups for sync_id in sync_ids]
            fixed_node = self.ties.fixed_node
            for root, _ in groups.values():
                if root in fixed_node:  # (a group held by a fixed time: which keys are; else none is)
                    fixed = [tie and groups[sync_id][0] in fixed_node for sync_id, tie in zip(sync_ids, tied)]
                    break
        timed = TimedBehaviour(self.run, beh, preferred, keys, engine, self.board.plan_order(), tied, fixed, owns)
        self.timed[beh.id] = timed
        return newly_known

    def drop_dependants(self) -> None:
        """A behaviour whose sync points are tied to one that was dropped is dropped too, with its own
        warning (else it would run at a time nothing gave it)."""
        changed = bool(self.dropped)  # (nothing dropped: nothing to look for)
        while changed:
            changed = False
            for beh in self.block.behaviours:
                if beh.id in self.dropped:
                    continue
                for sync_id, ref in beh.refs.items():
                    if ref.kind == "sync" and ref.block in (None, self.block.id) and ref.behaviour in self.dropped:
                        self.drop(beh.id, f"{sync_id}={ref.text!r}: it is tied to {ref.behaviour}, which was dropped")
                        changed = True
                        break

    def self_ties(self, beh: Behaviour, groups, known, times) -> dict[str, float]:
        """Times implied by constraints between sync points of the same behaviour (``end="b:start+1"``)."""
        if len(groups) - len(known) < 2:
            return {}  # no two sync points whose time is not known yet: none can imply the other's
        by_root: dict[int, list[str]] = {}
        for sync_id, (root, _) in groups.items():
            if sync_id not in known:
                by_root.setdefault(root, []).append(sync_id)
        implied = {}
        index = {s: i for i, s in enumerate(beh.sync_ids)}
        for syncs in by_root.values():
            if len(syncs) > 1:
                first = min(syncs, key=index.__getitem__)
                t_root = times[index[first]] - groups[first][1]
                for sync_id in syncs:
                    implied[sync_id] = t_root + groups[sync_id][1]
        return implied

    # ----------------------------------------------------------------- after placing
    def times_of(self, timed: TimedBehaviour) -> list[float | None]:
        """``timed.times()``, computed once while no peg moves (the list is shared: not to be changed)."""
        if self._times_in != self._cache.generation:
            self._times.clear()
            self._times_in = self._cache.generation
        times = self._times.get(timed)
        if times is None:
            times = self._times[timed] = timed.times()
        return times

    def times_now(self) -> dict[TimedBehaviour, list[float | None]]:
        """The times computed by :meth:`times_of` that are still good now (none if a peg moved since)."""
        return self._times if self._times_in == self._cache.generation else {}

    def local(self, timed: TimedBehaviour, sync_id: str) -> float | None:
        t = self.times_of(timed)[timed.sync_ids.index(sync_id)]
        return None if t is None else t - self.block_peg.time

    def ref_time(self, node: int, offset: float, ref: SyncRef) -> tuple[float | None, TimedBehaviour | None]:
        """Current time of a resolved reference, and the behaviour of this block it belongs to."""
        kind, _, block, behaviour, sync, _, _ = ref  # (the fields at once: this is asked of every constraint)
        if kind == "sync" and (block is None or block == self.block.id):
            timed = self.timed.get(behaviour)
            if timed is None:
                return None, None
            times = self._times.get(timed) if self._times_in == self._cache.generation else None
            if times is None:
                times = self.times_of(timed)
            return times[timed.sync_ids.index(sync)] + offset, timed
        root, d = self.ties.find(node)
        peg = self.group_peg.get(root)
        return (None if peg is None or peg.time is None else peg.time + d + offset), None

    def anchors_of(self, timed: TimedBehaviour) -> tuple[set[int], bool]:
        """The free anchors a behaviour's keys hang from, and whether it also hangs from a fixed time."""
        anchors: set[int] = set()
        fixed = False
        cache = self._anchor_cache
        for key in timed.keys:
            if key is not None:
                peg = key.peg
                anchor = cache.get(id(peg), cache)  # (the memo, looked up here: the usual answer)
                if anchor is cache:
                    anchor = self.anchor_of(peg)
                if anchor is None:
                    fixed = True
                else:
                    anchors.add(anchor)
        return anchors, fixed

    def anchor_of(self, peg) -> int | None:
        """id of the free anchor a peg hangs from, or None if it hangs from a fixed time (memoised)."""
        cache = self._anchor_cache
        chain = []
        while True:
            key = id(peg)
            if key in cache:
                found = cache[key]
                break
            if isinstance(peg, OffsetPeg) and peg.anchor:
                found = key
                break
            if not isinstance(peg, OffsetPeg) or peg.base is None:
                found = None
                break
            chain.append(key)
            peg = peg.base
        for key in chain:
            cache[key] = found
        return found

    def movable(self, timed: TimedBehaviour) -> list[OffsetPeg] | None:
        anchors, fixed = self.anchors_of(timed)
        if fixed or not anchors:
            return None
        by_id = {id(a): a for a in self.anchors}
        return [by_id[a] for a in anchors]

    def honour_inequalities(self, inequalities) -> None:
        reported: set[tuple[int, str]] = set()
        ref_time = self.ref_time
        for _ in range(len(inequalities) + 1):
            changed = False
            for constraint, refs, (a_node, a_offset, a_ref) in inequalities:
                t_anchor, anchor_beh = ref_time(a_node, a_offset, a_ref)
                if t_anchor is None:
                    continue
                before = constraint.kind == "before"
                for node, offset, ref in refs:
                    t, beh = ref_time(node, offset, ref)
                    if t is None:
                        continue
                    gap = (t - t_anchor) if before else (t_anchor - t)
                    if gap <= TOLERANCE:
                        continue
                    # Move the constrained behaviour toward the anchor, else the anchor toward it; moving
                    # helps only if the two sides do not hang from the same anchors.
                    shift = -gap if constraint.kind == "before" else gap
                    moved = False
                    for target, other, delta in ((beh, anchor_beh, shift), (anchor_beh, beh, -shift)):
                        pegs = self.movable(target) if target is not None else None
                        if pegs and (other is None or not {id(p) for p in pegs} & self.anchors_of(other)[0]):
                            for peg in pegs:
                                peg.shift(delta)
                            changed = moved = True
                            break
                    if not moved and (id(constraint), ref.text) not in reported:
                        reported.add((id(constraint), ref.text))
                        self.constraint_issue(constraint, f"{ref.text} cannot be {constraint.kind} {a_ref.text}",
                                              ref if beh is not None else a_ref)
            if not changed:
                break

    def check_inequalities(self, inequalities) -> None:
        """Report what ``before``/``after`` constraints are still not met once clusters are in the block (a
        behaviour moved earlier than the block start and shifted back): the constrained behaviour goes."""
        for constraint, refs, (a_node, a_offset, a_ref) in inequalities:
            t_anchor, _ = self.ref_time(a_node, a_offset, a_ref)
            if t_anchor is None:
                continue
            for node, offset, ref in refs:
                t, beh = self.ref_time(node, offset, ref)
                if t is None or (beh is not None and beh.id in self.dropped):
                    continue
                gap = (t - t_anchor) if constraint.kind == "before" else (t_anchor - t)
                if gap > TOLERANCE:
                    self.constraint_issue(constraint, f"{ref.text} cannot be {constraint.kind} {a_ref.text} "
                                                      "within the block", ref if beh is not None else a_ref)

    def shift_clusters(self, inequalities) -> bool:
        """Shift every cluster of freely placed behaviours that starts before the block start; returns
        whether any was shifted."""
        block_start, times_of = self.block_peg.time, self.times_of
        known = self.times_now()  # (the times times_of has, told without its call: no peg moves in this loop)
        for timed in self.timed.values():  # (most blocks have none that starts before the block: then none moves)
            times = known.get(timed)
            start = (times if times is not None else times_of(timed))[0]
            if start is not None and start - block_start < -EPSILON:
                break
        else:
            return False
        parent: dict[int, int] = {}

        def find(x: int) -> int:
            while parent.setdefault(x, x) != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        fixed_clusters: set[int] = set()
        shifted = False
        info = []
        anchors_of: dict[int, set[int]] = {}  # by id() of the timed behaviour (nothing moves meanwhile)
        for timed in self.timed.values():
            anchors, fixed = self.anchors_of(timed)
            info.append((timed, anchors, fixed))
            anchors_of[id(timed)] = anchors
            anchors = list(anchors)
            for other in anchors[1:]:
                parent[find(other)] = find(anchors[0])
        links = [(self.timed.get(ref.behaviour), self.timed.get(a_ref.behaviour))
                 for _, refs, (_, _, a_ref) in inequalities for (_, _, ref) in refs
                 if ref.kind == "sync" and a_ref.kind == "sync"]
        for a, b in links:
            if a is None or b is None:
                continue
            aa, bb = anchors_of[id(a)], anchors_of[id(b)]
            if aa and bb:
                parent[find(next(iter(bb)))] = find(next(iter(aa)))
        earliest: dict[int, float] = {}
        for timed, anchors, fixed in info:
            if not anchors:
                continue
            root = find(next(iter(anchors)))
            if fixed:
                fixed_clusters.add(root)
            start = self.local(timed, timed.sync_ids[0])
            if start is not None:
                earliest[root] = min(earliest.get(root, start), start)
        for anchor in self.anchors:
            root = find(id(anchor))
            if root in fixed_clusters:
                continue
            deficit = -earliest.get(root, 0.0)
            if deficit > EPSILON:
                anchor.shift(deficit)
                shifted = True
        return shifted

    def check_validity(self) -> None:
        block_start, times_of = self.block_peg.time, self.times_of  # (no peg moves here)
        known = self.times_now()  # (the times times_of has, told without its call)
        for beh_id, timed in list(self.timed.items()):
            times = known.get(timed)
            if times is None:
                times = times_of(timed)
            start = times[0] - block_start
            if start < -TOLERANCE:
                refused = self.shorten_preparation(timed, times)
                if refused is not None:
                    self.drop(beh_id, f"it would start {-start:.3f} s before the block start{refused}")
                    continue
                times = self._times[timed] = timed.times()  # (its first key moved)
            try:
                timed.engine.planner.check_times(timed.behaviour, timed.preferred, times)
            except ScheduleError as exc:
                self.drop(beh_id, str(exc))

    def shorten_preparation(self, timed: TimedBehaviour, times: list[float | None]) -> str | None:
        """A gesture or pointing tied to a time (its stroke, say) whose preparation would begin before the
        block starts begins at the block start instead, its preparation shortened and its stroke kept, down
        to :data:`MIN_PREPARATION` of the preferred time from its start to the first sync point tied (at the
        latest its stroke). None if it was shortened, else why not (the end of the drop's reason)."""
        if timed.behaviour.type not in PREPARED or timed.tied[0] or "stroke" not in timed.sync_ids:
            return ""
        first = next((i for i in range(1, len(timed.keys)) if timed.keys[i] is not None), None)
        if first is None or first > timed.sync_ids.index("stroke"):
            return ""  # nothing before the stroke is tied: shortening would move the stroke
        block_start = self.block_peg.time
        available = times[first] - block_start
        preferred = timed.preferred[first] - timed.preferred[0]
        shortest = MIN_PREPARATION * preferred
        if available < shortest - TOLERANCE:
            return (f", and its preparation ({preferred:.3f} s to its {timed.sync_ids[first]}) cannot be shortened "
                    f"below {shortest:.3f} s to fit ({max(available, 0.0):.3f} s are left)")
        key = timed.keys[0]
        timed.keys[0] = KeyRef(key.peg, key.offset + block_start - times[0])
        return None

    def check_resources(self) -> None:
        """Two behaviours on one exclusive body resource (two gazes) may not overlap: drop the later one."""
        holders: dict[str, list[tuple[float, float, str]]] = {}
        for timed in self.existing():
            resource = BEHAVIOUR_TYPES[timed.behaviour.type].resource
            if resource and timed.state in ("planned", "active"):
                holders.setdefault(resource, []).append((timed.start, timed.end, f"{timed.block_id}:{timed.id}"))
        for beh in self.block.behaviours:
            timed = self.timed.get(beh.id)
            resource = BEHAVIOUR_TYPES[beh.type].resource
            if timed is None or resource is None:
                continue
            times = self.times_of(timed)
            start, end = times[0], times[-1]
            clash = next((name for s, e, name in holders.get(resource, ())
                          if start < e - EPSILON and s < end - EPSILON), None)
            if clash is not None:
                self.drop(beh.id, f"{resource} is already used by {clash} at that time")
            else:
                holders.setdefault(resource, []).append((start, end, f"{self.block.id}:{beh.id}"))
