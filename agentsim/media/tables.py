"""The tables people analyse: one row per pegged behaviour (a gesture tied to a word or a beat), when what
it was tied to really sounded, when its sync point happened, and the error.

A behaviour is pegged when one of its sync points refers to a speech's sync point or to an anticipator's
peg (its stroke is tried first). The word is the one the speech's sync point falls in (a syllable's mark),
else the first word after it; it really sounded where the run's listener heard it
(:mod:`agentsim.media.audio`'s placement: playback latency and drift included). An anticipator's beat
sounded where ``beat_times`` says (the ensemble's onset of it, in the conductor), else at its peg's last
time. All times are seconds on the run's axis; column names carry their units.
"""

from __future__ import annotations

import csv
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

from agentsim.written import written

#: The order in which a behaviour's sync points are tried for its peg: its stroke first.
PEG_ORDER = ("stroke", "strokeStart", "attackPeak", "ready", "strokeEnd", "relax", "start", "end")
#: Behaviour types that are never pegged behaviours of their own (they are what others are pegged to, or
#: have no motion).
NOT_PEGGED = {"speech", "wait", "event", "interrupt", "activate", "parametervaluechange", "audiofile", "emotion"}


@dataclass
class GestureRow:
    """One pegged behaviour."""

    block: str
    behaviour: str
    type: str
    sync: str
    tied_to: str
    word: str
    sounded_s: float | None
    happened_s: float | None
    error_ms: float | None
    dropped: bool
    reason: str = ""


def _word_heard(recording, block: str, speech: str, sync: str) -> tuple[str, float | None]:
    """The word a speech's sync point is on, and when its onset was heard (None if it never was)."""
    heard = next((h for h in recording.speech if (h.block, h.behaviour) == (block, speech)), None)
    if heard is None:
        return "", None
    utterance = heard.utterance
    speed = 1.0 + heard.drift_ppm * 1e-6
    if sync == "start":
        t, word = 0.0, utterance.words[0].text if utterance.words else ""
    elif sync == "end":
        t, word = utterance.duration, ""
    else:
        mark = utterance.mark(sync)
        if mark is None:
            return "", None
        t = mark.time
        found = utterance.word_sounding(t)  # a mark on a syllable of a word is on that word
        word = found.text if found is not None else ""
    sounded = heard.t0 + t * speed
    if heard.stopped is not None and sounded > heard.stopped + 1e-9:
        return word, None
    return word, sounded


def gesture_rows(recording, beat_times: Callable[[str, str], float | None] | None = None) -> list[GestureRow]:
    """The pegged behaviours of a recording, in the order they were planned."""
    speeches = {(r.block, r.id) for r in recording.behaviours if r.type == "speech"}
    drops = {(d.block, d.behaviour): d.reason for d in recording.drops}
    rows = []
    for record in recording.behaviours:
        if record.type in NOT_PEGGED:
            continue
        order = [s for s in PEG_ORDER if s in record.sync_ids] + [s for s in record.sync_ids if s not in PEG_ORDER]
        tie = None
        for sync in order:
            ref = record.behaviour.refs.get(sync)
            if ref is None:
                continue
            if ref.kind == "anticipator":
                tie = (sync, ref, f"anticipators:{ref.anticipator}:{ref.sync}")
                break
            if ref.kind == "sync" and (ref.block or record.block, ref.behaviour) in speeches:
                tie = (sync, ref, f"{ref.block or record.block}:{ref.behaviour}:{ref.sync}")
                break
        if tie is None:
            continue
        sync, ref, tied_to = tie
        if ref.kind == "sync":
            word, sounded = _word_heard(recording, ref.block or record.block, ref.behaviour, ref.sync)
        else:
            word = ref.sync
            sounded = beat_times(ref.anticipator, ref.sync) if beat_times is not None else None
            if sounded is None:
                sounded = recording.anticipators.get(ref.anticipator, {}).get(ref.sync)
        if sounded is not None:
            sounded += ref.offset
        i = record.sync_ids.index(sync)
        happened = record.times[i] if record.passed[i] else None
        error = (happened - sounded) * 1000.0 if happened is not None and sounded is not None else None
        rows.append(GestureRow(record.block, record.id, record.type, sync, tied_to, word, sounded, happened, error,
                               record.state == "dropped", drops.get((record.block, record.id), "")))
    return rows


def write_csv(path: str | Path, rows: list, columns: list[str] | None = None) -> Path:
    """Write dataclass rows (or dicts) as CSV with a header; None as an empty cell, floats to the microsecond
    (milliseconds to the nanosecond)."""
    path = Path(path)
    dicts = [asdict(r) if not isinstance(r, dict) else r for r in rows]
    if columns is None:
        columns = list(dicts[0]) if dicts else [f.name for f in GestureRow.__dataclass_fields__.values()]
    with written(path) as tmp, open(tmp, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        for d in dicts:
            writer.writerow([_cell(d.get(c), c) for c in columns])
    return path


def _cell(value, column: str) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.6f}" if not column.endswith("_ms") else f"{value:.6f}"
    return str(value)
