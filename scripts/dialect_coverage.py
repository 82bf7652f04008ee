"""How much of a folder of BML documents the realizer realizes: for each document alone, the behaviour elements
whose ``end`` is reported, by the naming rules for what has no id (docs/howto/dialects.md). Prints JSON, per sub-folder
(one per system) and in all, with the warnings that cost behaviours, most frequent first.

    .venv/bin/python scripts/dialect_coverage.py CORPUS_DIR [--strict]
"""

from __future__ import annotations

import argparse
import collections
import json
import re
import sys
from pathlib import Path

from agentsim.bml.documents import find_blocks
from agentsim.bml.spelling import fold_case, without_doctype
from agentsim.core.xmltree import read_forest
from agentsim.errors import BMLError
from agentsim.realizer import Realizer

SUFFIXES = {".xml", ".bml"}


def expected_ids(data: bytes) -> list[str] | None:
    """``block:behaviour`` of every behaviour element of a document, ids given or generated as documented."""
    try:
        root, forest = read_forest(without_doctype(data)[0])
    except BMLError:
        return None
    fold_case(root)
    envelopes = find_blocks(root, forest)
    taken = {e.node.attrs.get("id", "").strip() for e in envelopes}
    unnamed = 0
    out = []
    for envelope in envelopes:
        block = envelope.node.attrs.get("id", "").strip()
        if not block:
            unnamed += 1
            while f"bml{unnamed}" in taken:
                unnamed += 1
            block = f"bml{unnamed}"
        elements = []

        def walk(node) -> None:
            for child in node.elements():
                if child.local == "required":
                    walk(child)
                elif child.local != "constraint":
                    elements.append(child)

        walk(envelope.node)
        used = {e.attrs.get("id", "").strip() for e in elements} - {""}
        counters: dict[str, int] = {}
        for element in elements:
            bid = element.attrs.get("id", "").strip()
            if not bid:
                n = counters.get(element.local, 0)
                while True:
                    n += 1
                    bid = f"{element.local}{n}"
                    if bid not in used:
                        break
                counters[element.local] = n
                used.add(bid)
            out.append(f"{block}:{bid}")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("corpus", type=Path)
    parser.add_argument("--strict", action="store_true")
    args = parser.parse_args(argv)
    if not args.corpus.is_dir():
        print(f"no such folder: {args.corpus}", file=sys.stderr)
        return 2
    totals = collections.Counter()
    realized = collections.Counter()
    documents = collections.Counter()
    unreadable: list[str] = []
    losses = collections.Counter()
    for path in sorted(p for p in args.corpus.rglob("*") if p.suffix.lower() in SUFFIXES and p.is_file()):
        system = path.relative_to(args.corpus).parts[0] if path.parent != args.corpus else "."
        data = path.read_bytes()
        expected = expected_ids(data)
        if expected is None:
            unreadable.append(str(path))
            continue
        realizer = Realizer(strict=args.strict)
        realizer.submit(data, source=str(path))
        realizer.run()
        ends = {f["id"].rsplit(":", 1)[0] for f in realizer.feedback.items
                if f["type"] == "syncPointProgress" and f["id"].endswith(":end")}
        got = sum(1 for e in expected if e in ends)
        documents[system] += 1
        totals[system] += len(expected)
        realized[system] += got
        if got < len(expected):
            for w in realizer.feedback.warnings():
                if w["warningType"] != "NONSTANDARD_BML":
                    losses[f"{w['warningType']}: " + re.sub(r"\(line \d+, column \d+\)|'[^']*'|[\d.]+", "#",
                                                          w["description"])[:120]] += 1
    summary = {
        "strict": args.strict,
        "systems": {s: {"documents": documents[s], "behaviours": totals[s], "realized": realized[s],
                        "percent": round(100 * realized[s] / max(1, totals[s]), 1)} for s in sorted(totals)},
        "documents": sum(documents.values()), "behaviours": sum(totals.values()),
        "realized": sum(realized.values()),
        "percent": round(100 * sum(realized.values()) / max(1, sum(totals.values())), 1),
        "unreadable": unreadable,
        "losses": losses.most_common(20),
    }
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
