"""The whole BML 1.0 face: every faceLexeme of the standard and the FACS units realize without a warning and
move the side of the face they name, as the BVH has it (composed by a BVH reader, not our kinematics); the
speech's phonemes become visemes by the documented table and are written to ``visemes.csv``."""

from __future__ import annotations

import csv
import re
import subprocess
import sys

import numpy as np
import pytest

from helpers import bvh_reader, realize

from agentsim.animation import evaluate_poses, write_bvh
from agentsim.animation.lexicon import BML_FACE_LEXEMES, Lexicon
from agentsim.animation.lips import PHONEME_VISEMES, phoneme_viseme

LEXICON = Lexicon.builtin()
FACE_LEXEMES, FACS_UNITS, VISEMES = LEXICON.faces, LEXICON.facs, LEXICON.visemes

NS = "http://www.bml-initiative.org/bml/bml-1.0"
FPS = 20
#: Each behaviour's window: 1 s of attack and hold, then 1 s to get back to rest.
SLOT = 2.0


def end_sites(path) -> dict[str, np.ndarray]:
    """The End Site offset of each leaf joint, read from the BVH text."""
    sites, joint, in_site = {}, None, False
    for line in open(path).read().splitlines():
        words = line.split()
        if words[:1] in (["JOINT"], ["ROOT"]):
            joint, in_site = words[1], False
        elif words[:2] == ["End", "Site"]:
            in_site = True
        elif words[:1] == ["OFFSET"] and in_site:
            sites[joint] = np.array([float(x) for x in words[1:4]])
            in_site = False
    return sites


def face_run(tmp_path, behaviours: list[str]):
    """Realize one block of face behaviours, one per :data:`SLOT`; the BVH's reader and end-site offsets."""
    body = "".join(b.format(start=k * SLOT + 0.2, peak=k * SLOT + 0.6, relax=k * SLOT + 1.0, end=k * SLOT + 1.4)
                   for k, b in enumerate(behaviours))
    result = realize(f'<bml xmlns="{NS}" id="b1">{body}</bml>'.encode())
    stream = evaluate_poses(result.realizer.recording(), fps=FPS, duration=len(behaviours) * SLOT)
    path = tmp_path / "face.bvh"
    write_bvh(path, stream)
    return result, bvh_reader(path), end_sites(path)


def site(reader, sites, joint, k) -> np.ndarray:
    """World position of a joint's end site at frame k, in the skull's frame (metres); for the jaw, which
    has the lower lip below it, where the lower lip's joint is."""
    import glm

    _, _, _, world = reader
    srot, spos = world("skullbase", k)
    if joint == "temporomandibular":
        p = world("lower_lip", k)[1]
    else:
        rot, pos = world(joint, k)
        p = pos + rot * glm.vec3(*sites[joint])
    return np.array(list(glm.inverse(srot) * (p - spos)))


POINTS = ("l_eyebrow", "r_eyebrow", "l_lip_corner", "r_lip_corner", "l_eyelid", "r_eyelid", "temporomandibular",
          "upper_lip", "lower_lip")


def moves(reader, sites, k_rest, k_peak) -> dict[str, np.ndarray]:
    return {j: site(reader, sites, j, k_peak) - site(reader, sites, j, k_rest) for j in POINTS}


def test_every_bml_face_lexeme_realizes_without_a_warning_and_moves_its_side(tmp_path):
    lexemes = list(BML_FACE_LEXEMES)
    assert len(lexemes) == 17 and set(lexemes) <= set(FACE_LEXEMES)
    result, reader, sites = face_run(tmp_path, [
        f'<faceLexeme id="f{k}" lexeme="{lex}" start="{{start}}" attackPeak="{{peak}}" relax="{{relax}}" '
        f'end="{{end}}"/>' for k, lex in enumerate(lexemes)])
    assert result.warnings == []
    mm = 1000.0
    for k, lex in enumerate(lexemes):
        rest, peak = round(k * SLOT * FPS), round((k * SLOT + 0.8) * FPS)
        d = {j: v * mm for j, v in moves(reader, sites, rest, peak).items()}
        up = {j: v[1] for j, v in d.items()}
        still = 0.05  # mm: a point the lexeme does not name stays where it is
        if "BROW" in lex:
            sides = ["l"] if "LEFT" in lex else ["r"] if "RIGHT" in lex else ["l", "r"]
            for s in ("l", "r"):
                brow = f"{s}_eyebrow"
                if s not in sides:
                    assert np.linalg.norm(d[brow]) < still, (lex, brow, d[brow])
                elif lex.startswith("RAISE"):
                    assert up[brow] > 5.0, (lex, brow, up[brow])
                elif lex.startswith("LOWER"):
                    assert up[brow] < -4.0, (lex, brow, up[brow])
                else:  # oblique: the outer end comes down relative to the brow's middle, which rises
                    assert up[brow] < -1.0, (lex, brow, up[brow])
            assert all(np.linalg.norm(d[j]) < still for j in ("l_lip_corner", "r_lip_corner", "temporomandibular"))
        elif "MOUTH_CORNER" in lex:
            sides = ["l"] if "LEFT" in lex else ["r"] if "RIGHT" in lex else ["l", "r"]
            for s in ("l", "r"):
                corner = f"{s}_lip_corner"
                if s not in sides:
                    assert np.linalg.norm(d[corner]) < still, (lex, corner)
                else:
                    assert (up[corner] > 4.0) if lex.startswith("RAISE") else (up[corner] < -4.0), (lex, corner, up)
            assert all(np.linalg.norm(d[j]) < still for j in ("l_eyebrow", "r_eyebrow"))
        elif lex == "OPEN_MOUTH":
            assert up["temporomandibular"] < -5.0 and np.linalg.norm(d["upper_lip"]) < still
        elif lex == "OPEN_LIPS":  # the lips part, the jaw stays
            assert up["upper_lip"] > 1.0 and up["lower_lip"] < -1.0 and np.linalg.norm(d["temporomandibular"]) < still
        elif lex in ("WIDEN_EYES", "CLOSE_EYES"):
            for s in ("l", "r"):
                assert (up[f"{s}_eyelid"] > 2.0) if lex == "WIDEN_EYES" else (up[f"{s}_eyelid"] < -5.0), (lex, up)
        else:
            raise AssertionError(f"no expectation for {lex}")
        back = round((k * SLOT + 1.9) * FPS)
        assert {j: round(float(np.linalg.norm(v) * mm), 2) for j, v in moves(reader, sites, rest, back).items()
                if np.linalg.norm(v) * mm >= 0.5 and "eyelid" not in j} == {}, lex  # lids: blinks, gaze


@pytest.mark.parametrize("side", ["BOTH", "LEFT", "RIGHT"])
def test_facs_units_realize_on_the_side_named(tmp_path, side):
    units = [1, 2, 4, 12, 15]
    result, reader, sites = face_run(tmp_path, [
        f'<faceFacs id="u{au}" au="{au}" side="{side}" start="{{start}}" attackPeak="{{peak}}" relax="{{relax}}" '
        f'end="{{end}}"/>' for au in units])
    assert result.warnings == []
    for k, au in enumerate(units):
        rest, peak = round(k * SLOT * FPS), round((k * SLOT + 0.8) * FPS)
        d = moves(reader, sites, rest, peak)
        joint = "eyebrow" if au < 10 else "lip_corner"
        for s in ("l", "r"):
            shown = side == "BOTH" or side[0].lower() == s
            size = np.linalg.norm(d[f"{s}_{joint}"]) * 1000
            assert (size > 1.0) if shown else (size < 0.05), (au, side, s, size)
    # the inner brow raiser lifts the brow's inner end: its outer end site less than the outer raiser's
    k1, k2 = 0, 1
    if side != "RIGHT":
        one = moves(reader, sites, 0, round((k1 * SLOT + 0.8) * FPS))["l_eyebrow"][1]
        two = moves(reader, sites, round(k2 * SLOT * FPS), round((k2 * SLOT + 0.8) * FPS))["l_eyebrow"][1]
        assert two > one + 1e-3


@pytest.mark.parametrize("side", ["LEFT", "RIGHT"])
def test_every_facs_unit_with_a_side_moves_that_side_alone(tmp_path, side):
    # each unit against the same run at amount 0 (the background's blinks and gaze the same): the points of
    # the other half stay to a hundredth of a millimetre through the whole window; the named half, or the
    # middle of the mouth for a unit that has no halves, moves
    units = sorted(FACS_UNITS)
    runs = []
    for amount in (1, 0):
        folder = tmp_path / f"amount{amount}"
        folder.mkdir()
        result, reader, sites = face_run(folder, [
            f'<faceFacs id="u{au}" au="{au}" side="{side}" amount="{amount}" start="{{start}}" '
            f'attackPeak="{{peak}}" relax="{{relax}}" end="{{end}}"/>' for au in units])
        assert result.warnings == []
        runs.append((reader, sites))
    named, other = ("l", "r") if side == "LEFT" else ("r", "l")
    for k, au in enumerate(units):
        window = range(round(k * SLOT * FPS), round((k + 1) * SLOT * FPS))
        peak = round((k * SLOT + 0.8) * FPS)

        def moved(joint, f):
            return float(np.linalg.norm(site(*runs[0], joint, f) - site(*runs[1], joint, f))) * 1000

        lateral = any(dof[:2] in ("l_", "r_") for dof in FACS_UNITS[au])
        assert max(moved(j, f) for j in POINTS if j.startswith(other + "_") for f in window) < 0.01, (au, side)
        shown = [j for j in POINTS if j.startswith(named + "_")] if lateral else \
            [j for j in POINTS if not j.startswith(("l_", "r_"))]
        assert max(moved(j, peak) for j in shown) > 1.5, (au, side)


def test_every_facs_unit_and_face_lexeme_is_known_to_the_reader():
    from agentsim.bml.lexemes import fallback

    for au in FACS_UNITS:
        assert fallback("faceFacs", {"au": str(au)}) is None
    assert fallback("faceFacs", {"au": "99"}) is not None
    for lex in BML_FACE_LEXEMES:
        assert fallback("faceLexeme", {"lexeme": lex}) is None


def test_phoneme_to_viseme_table():
    assert set(v.lower() for v in PHONEME_VISEMES.values()) <= set(VISEMES)
    cases = {"p": "PBM", "b": "PBM", "m": "PBM", "f": "FV", "v": "FV", "θ": "Th", "ð": "Th", "tʃ": "ShCh",
             "dʒ": "ShCh", "ʒ": "ShCh", "w": "W", "ɹ": "R", "l": "L", "k": "K", "ŋ": "K", "iː": "Iy", "uː": "Uw",
             "ɑː": "Aa", "ɜː": "Er", "əʊ": "Ah", "aɪ": "Aa", "ɔɪ": "Ao", "ˈa": "Aa", "": "_"}
    assert {s: phoneme_viseme(s) for s in cases} == cases


def test_realize_writes_visemes_csv_from_the_speech_phonemes(tmp_path):
    doc = tmp_path / "talk.xml"
    doc.write_text(f'<bml xmlns="{NS}" id="b1"><speech id="s1"><text>Bob fed five mice</text></speech></bml>')
    out = tmp_path / "tables"
    run = subprocess.run([sys.executable, "-m", "agentsim", "realize", str(doc), "--tts", "espeak", "--csv",
                          str(out)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    rows = list(csv.DictReader(open(out / "visemes.csv")))
    assert list(rows[0]) == ["block", "behaviour", "word", "phoneme", "viseme", "start_s", "end_s"]
    by_word = {}
    for r in rows:
        by_word.setdefault(r["word"], []).append(r["viseme"])
    assert by_word["Bob"][0] == "PBM" and by_word["Bob"][-1] == "PBM"
    assert by_word["fed"][0] == "FV" and by_word["five"][0] == "FV" and by_word["mice"][0] == "PBM"
    starts = [float(r["start_s"]) for r in rows]
    assert starts == sorted(starts) and all(float(r["end_s"]) > float(r["start_s"]) for r in rows)
    assert all(re.fullmatch(r"b1", r["block"]) and r["behaviour"] == "s1" for r in rows)
