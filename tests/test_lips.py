"""Lip sync on the mouth: visemes (``lips``) and keyframed face channels (``curves``) realized and evaluated.

The blocks are built by hand (the lenient reader that makes these behaviours from other realizers' XML
lives elsewhere). Poses are evaluated at 100 frames per second, so every sync time used here is a frame.
"""

from __future__ import annotations

import numpy as np
import pytest

from agentsim.animation import evaluate_poses, write_bvh
from agentsim.animation.body import Body
from agentsim.animation.lexicon import Lexicon
from agentsim.animation.lips import MIN_RAMP, MOUTH_DOFS, NEUTRAL, MouthShape, channel_shape, monotone_cubic
from agentsim.bml.parser import parse_ref
from agentsim.core.block import BEHAVIOUR_TYPES, Behaviour, Block
from agentsim.realizer import Realizer

LEXICON = Lexicon.builtin()
#: the built-in lexicon's mouth shapes of visemes, and of every face channel (the visemes and the others)
VISEMES = {name: MouthShape(**entry) for name, entry in LEXICON.visemes.items()}
CHANNELS = {name: channel_shape(name, LEXICON) for name in {**LEXICON.visemes, **LEXICON.channels}}

FPS = 100
DT = 1.0 / FPS
JAW = "temporomandibular.pitch"


def behaviour(bid, kind, attrs=None, params=None, text="", **refs):
    return Behaviour(bid, kind, list(BEHAVIOUR_TYPES[kind].syncs), dict(attrs or {}),
                     {sync: parse_ref(str(ref)) for sync, ref in refs.items()}, text=text, params=dict(params or {}))


def viseme(bid, name, start, ready, relax, end, articulation=None):
    attrs = {"viseme": name}
    if articulation is not None:
        attrs["articulation"] = str(articulation)
    return behaviour(bid, "lips", attrs, start=start, ready=ready, relax=relax, end=end)


def realize(*behaviours) -> Realizer:
    r = Realizer()
    r.submit(Block("b1", behaviours=list(behaviours)))
    r.run()
    assert not r.feedback.warnings(), r.feedback.warnings()
    return r


def frames(stream, t0, t1):
    """Indices of the frames from t0 to t1, both included."""
    return np.nonzero((stream.times >= t0 - 1e-9) & (stream.times <= t1 + 1e-9))[0]


def mouth(stream, k) -> dict[str, float]:
    return {d: float(stream.channel(d)[k]) for d in MOUTH_DOFS}


# --------------------------------------------------------------------------------------------- the table
def lip_points(body: Body, values: dict[str, float]) -> dict[str, np.ndarray]:
    """The lip edges and mouth corners (end sites) in the skull's frame, for the rest pose plus ``values``."""
    pose = body.rest_pose()
    for name, v in values.items():
        pose[body.dof(name)] = v
    fk = body.forward_kinematics(pose[None])
    rot_s, pos_s = fk["skullbase"][0][0], fk["skullbase"][1][0]
    out = {}
    for j in ("upper_lip", "lower_lip", "l_lip_corner", "r_lip_corner"):
        rot, pos = fk[j][0][0], fk[j][1][0]
        out[j] = rot_s.T @ (pos + rot @ np.asarray(body.joint[j].end_site) - pos_s)
    return out


def test_the_table_shapes_do_what_their_visemes_need_on_this_skeleton():
    body = Body()
    rest = lip_points(body, {})
    gap = lambda p: p["upper_lip"][1] - p["lower_lip"][1]  # noqa: E731  (vertical opening of the lips)
    width = lambda p: p["l_lip_corner"][0] - p["r_lip_corner"][0]  # noqa: E731
    shape = {name: lip_points(body, s.dofs()) for name, s in VISEMES.items()}
    assert gap(rest) > 0 and all(VISEMES["_"].dofs()[d] == 0.0 for d in MOUTH_DOFS)  # silence: the rest pose
    # Aa opens the mouth most, by more than a centimetre
    assert gap(shape["aa"]) > 0.01 and gap(shape["aa"]) == max(gap(p) for p in shape.values())
    # bilabials close the lips (the lower edge at or above the upper); labiodentals raise the lower lip but
    # leave the lips apart (it meets the upper teeth)
    for name in ("bmp", "pbm"):
        assert gap(shape[name]) < 0
    for name in ("f", "fv"):
        assert shape[name]["lower_lip"][1] > rest["lower_lip"][1] + 0.0015 and gap(shape[name]) > 0
    # spread visemes widen the mouth; rounded ones narrow it and bring the corners forward
    for name in ("iy", "ee", "ih", "eh", "z"):
        assert width(shape[name]) > width(rest) + 0.002, name
    for name in ("uw", "oo", "w", "oh", "ao", "r", "shch"):
        assert width(shape[name]) < width(rest) - 0.004, name
        assert shape[name]["l_lip_corner"][2] > rest["l_lip_corner"][2] + 0.002, name
    assert width(shape["w"]) < width(shape["oh"]) < width(shape["ao"])  # the closer, the rounder
    assert width(shape["iy"]) > width(shape["ih"]) > width(shape["eh"])  # the closer, the wider
    # every shape, and every channel at full weight, lies within the joint limits
    for s in CHANNELS.values():
        for name, v in s.dofs().items():
            d = body.dof(name)
            assert body.lower[d] <= v <= body.upper[d], (s, name)


# --------------------------------------------------------------------------------------------- one viseme
@pytest.mark.parametrize("name, articulation, table", [
    ("Aa", None, "aa"), ("Aa", 0.8, "aa"), ("iY", 0.5, "iy"), ("OO", None, "oo"), ("BMP", 1.0, "bmp"),
    ("f", 0.6, "f"), ("_", None, "_")])
def test_a_viseme_holds_its_table_shape_times_articulation_from_ready_to_relax(name, articulation, table):
    r = realize(viseme("lips1", name, 0.2, 0.3, 0.5, 0.6, articulation))
    s = evaluate_poses(r, fps=FPS)
    scale = 1.0 if articulation is None else articulation
    expected = VISEMES[table].dofs(scale)
    hold = frames(s, 0.3, 0.5)
    assert len(hold) == 21
    for d in MOUTH_DOFS:
        assert s.channel(d)[hold] == pytest.approx(np.full(len(hold), expected[d]), abs=1e-9), d
        assert {s.writer(k, d) for k in hold[:-1]} == {"b1:lips1"}  # at relax the rest pose takes over
    # before its start and after its end the mouth is at rest (the idle driver holds it again)
    for k in (*frames(s, 0.0, 0.19), *frames(s, 0.6, 0.8)):
        assert mouth(s, k) == pytest.approx({d: 0.0 for d in MOUTH_DOFS}, abs=1e-9)
    assert s.unit("lips1")["note"] == ""


def test_an_unknown_viseme_gets_a_neutral_half_open_mouth_and_a_note():
    r = realize(viseme("lips1", "Qx", 0.2, 0.3, 0.5, 0.6))
    s = evaluate_poses(r, fps=FPS)
    k = frames(s, 0.4, 0.4)[0]
    assert mouth(s, k) == pytest.approx(NEUTRAL.dofs(), abs=1e-9)
    assert 0 < NEUTRAL.jaw < VISEMES["aa"].jaw and NEUTRAL.spread == NEUTRAL.upper == NEUTRAL.lower == 0
    assert "unknown viseme 'Qx'" in s.unit("lips1")["note"]


def test_a_viseme_reports_its_sync_points_when_they_pass():
    r = realize(viseme("lips1", "Aa", 0.2, 0.3, 0.5, 0.6))
    progress = {f["id"]: f["globalTime"] for f in r.feedback.of_type("syncPointProgress")}
    assert progress["b1:lips1:start"] == pytest.approx(0.2, abs=1e-12)
    assert progress["b1:lips1:ready"] == pytest.approx(0.3, abs=1e-12)
    assert progress["b1:lips1:relax"] == pytest.approx(0.5, abs=1e-12)
    assert progress["b1:lips1:end"] == pytest.approx(0.6, abs=1e-12)
    ends = [f for f in r.feedback.of_type("blockProgress") if f["id"] == "b1:end"]
    assert len(ends) == 1 and ends[0]["globalTime"] == pytest.approx(0.6, abs=1e-12)


# --------------------------------------------------------------------------------------------- visemes in a row
def check_transition(s, first: dict, second: dict, t0: float, t1: float, ramp: float) -> None:
    """From t0 (the first shape held) to t1 (the second reached) every mouth DOF goes monotonically from
    the first shape to the second, never by more per frame than the steepest part of the ease (slope 1.5
    of the smoothstep over ``ramp`` seconds) allows."""
    ks = frames(s, t0, t1)
    for d in MOUTH_DOFS:
        v = s.channel(d)[ks]
        assert v[0] == pytest.approx(first[d], abs=1e-9) and v[-1] == pytest.approx(second[d], abs=1e-9), d
        delta = second[d] - first[d]
        steps = np.diff(v)
        assert np.all(steps * np.sign(delta) >= -1e-9), (d, v)  # monotone: no dip towards rest and back
        bound = 1.5 * abs(delta) * DT / ramp + 1e-9
        assert np.max(np.abs(steps)) <= bound, (d, np.max(np.abs(steps)), bound)


def test_a_viseme_starting_in_the_previous_ones_retraction_takes_over_from_its_shape():
    a, b = VISEMES["aa"].dofs(), VISEMES["uw"].dofs()
    r = realize(viseme("lips1", "Aa", 0.2, 0.3, 0.5, 0.6), viseme("lips2", "Uw", 0.55, 0.65, 0.8, 0.9))
    s = evaluate_poses(r, fps=FPS)
    check_transition(s, a, b, 0.3, 0.65, ramp=0.1)
    assert s.writer(frames(s, 0.54, 0.54)[0], JAW) == "b1:lips1"  # the first holds its shape until then
    assert s.writer(frames(s, 0.56, 0.56)[0], JAW) == "b1:lips2"
    for k in frames(s, 0.65, 0.8):
        assert mouth(s, k) == pytest.approx(b, abs=1e-9)


def test_a_viseme_starting_in_the_previous_ones_hold_takes_over_at_its_start():
    a, b = VISEMES["iy"].dofs(0.9), VISEMES["oh"].dofs()
    r = realize(viseme("lips1", "Iy", 0.2, 0.3, 0.6, 0.7, 0.9), viseme("lips2", "Oh", 0.4, 0.5, 0.8, 0.9))
    s = evaluate_poses(r, fps=FPS)
    check_transition(s, a, b, 0.3, 0.5, ramp=0.1)
    for k in frames(s, 0.5, 0.8):
        assert mouth(s, k) == pytest.approx(b, abs=1e-9)


def test_visemes_written_back_to_back_without_ramps_blend_over_the_shortest_ramp():
    # SmartBody's lip sync: ready at start, end at relax, each viseme starting where the last ends
    row = [("Ih", 0.2, 0.34), ("Aa", 0.34, 0.48), ("BMP", 0.48, 0.6), ("W", 0.6, 0.76)]
    r = realize(*[viseme(f"lips{i + 1}", v, a, a, e, e) for i, (v, a, e) in enumerate(row)])
    s = evaluate_poses(r, fps=FPS)
    rest = {d: 0.0 for d in MOUTH_DOFS}
    shapes = [VISEMES[v.lower()].dofs() for v, _, _ in row]
    check_transition(s, rest, shapes[0], 0.2, 0.2 + MIN_RAMP, ramp=MIN_RAMP)
    for (_, a, e), before, shape in zip(row[1:], shapes, shapes[1:]):
        check_transition(s, before, shape, a, a + MIN_RAMP, ramp=MIN_RAMP)
        for k in frames(s, a + MIN_RAMP, e):
            assert mouth(s, k) == pytest.approx(shape, abs=1e-9)
    # over the whole row no DOF jumps: the largest change in one frame is what the shortest ramp allows
    # for the largest difference between neighbouring shapes
    for d in MOUTH_DOFS:
        largest = max(abs(p[d] - q[d]) for p, q in zip([rest] + shapes, shapes + [rest]))
        assert np.max(np.abs(np.diff(s.channel(d)))) <= 1.5 * largest * DT / MIN_RAMP + 1e-9, d


def test_the_speech_jaw_yields_to_visemes_and_comes_back_after_them():
    speech = behaviour("s1", "speech", text="Hello there, how are you today my friend", start=0.5)
    r = realize(speech, viseme("lips1", "Aa", "s1:start+0.5", "s1:start+0.6", "s1:start+0.8", "s1:start+0.9"),
                viseme("lips2", "Uw", "s1:start+0.85", "s1:start+0.95", "s1:start+1.1", "s1:start+1.2"))
    syncs = r.feedback.sync_times()
    assert syncs["b1:lips1:start"] == pytest.approx(1.0) and syncs["b1:lips2:end"] == pytest.approx(1.7)
    assert syncs["b1:s1:end"] > 2.5
    s = evaluate_poses(r, fps=FPS)
    jaw = s.channel(JAW)
    writers = lambda t0, t1: {s.writer(k, JAW) for k in frames(s, t0, t1)}  # noqa: E731
    assert writers(0.5, 0.99) == {"b1:s1"}
    assert writers(1.0, 1.34) == {"b1:lips1"} and writers(1.35, 1.59) == {"b1:lips2"}
    assert writers(1.6, syncs["b1:s1:end"] - 0.01) == {"b1:s1"}
    assert jaw[frames(s, 1.1, 1.3)] == pytest.approx(VISEMES["aa"].jaw, abs=1e-9)
    assert jaw[frames(s, 1.45, 1.6)] == pytest.approx(VISEMES["uw"].jaw, abs=1e-9)
    # the speech jaw moves at syllable rate before and after the visemes
    for t0, t1 in ((0.55, 0.95), (1.8, 2.4)):
        v = jaw[frames(s, t0, t1)]
        assert v.max() - v.min() > 5.0
    # and the hand-overs do not jump: at most what a smoothstep over the shortest ramp allows for the
    # whole range of the jaw in play, or the speech jaw's own fastest change
    steps = np.abs(np.diff(jaw[frames(s, 0.5, 2.5)]))
    assert steps.max() <= max(1.5 * VISEMES["aa"].jaw * DT / MIN_RAMP, 9.0 * np.pi * 4.3 * DT) + 1e-9


# --------------------------------------------------------------------------------------------- curves
CURVES = {"curve:open": "0 0 0.2 0.5 0.5 1 0.8 0", "curve:wide": "0 0 0.5 0.6 0.8 0",
          "curve:W": "0 0 0.5 0.5 0.8 0", "curve:tBack": "0 0 0.4 1", "curve:Blink": "0 0 0.3 1 0.6 0"}


def test_curves_channels_move_the_mouth_by_their_keys_times_their_shapes():
    r = realize(behaviour("c1", "curves", params=CURVES, start=1.0))
    assert r.feedback.sync_times()["b1:c1:end"] == pytest.approx(1.8)
    s = evaluate_poses(r, fps=FPS)
    open_, wide, w = CHANNELS["open"], CHANNELS["wide"], CHANNELS["w"]
    at = lambda d, t: float(s.channel(d)[frames(s, t, t)[0]])  # noqa: E731
    # at a key time each channel has its key value: open 0.5 at 0.2 s (wide and W between keys there)
    assert at(JAW, 1.5) == pytest.approx(1.0 * open_.jaw + 0.5 * w.jaw, abs=1e-9)  # open 1, W 0.5 at 0.5 s
    assert at("l_lip_corner.yaw", 1.5) == pytest.approx(0.6 * wide.spread + 0.5 * w.spread, abs=1e-9)
    assert at("r_lip_corner.yaw", 1.5) == pytest.approx(-(0.6 * wide.spread + 0.5 * w.spread), abs=1e-9)
    # 0.2 s: open is at its key; the others are interpolated between their keys at 0 and 0.5 s
    w_02 = float(monotone_cubic([0, 0.5, 0.8], [0, 0.5, 0], 0.2))
    assert at(JAW, 1.2) == pytest.approx(0.5 * open_.jaw + w_02 * w.jaw, abs=1e-9)
    # at the end (the last key, 0) the mouth is handed back to the rest pose, there by 0.1 s later
    assert abs(at(JAW, 1.79)) < 0.1 and np.all(s.channel(JAW)[frames(s, 1.9, 2.5)] == 0.0)
    # between keys the weights stay between the neighbouring keys' (no overshoot)
    jaw = s.channel(JAW)[frames(s, 1.0, 1.8)]
    assert jaw.min() >= -1e-9 and jaw.max() <= open_.jaw + 0.5 * w.jaw + 1e-9
    # channels that move nothing here are named; the lips no channel moves are left to the idle driver
    note = s.unit("c1")["note"]
    assert "tBack: no tongue" in note and "Blink: no mapping" in note
    assert {s.writer(k, "upper_lip.pitch") for k in frames(s, 1.0, 1.8)} == {"idle sway"}
    assert {s.writer(k, JAW) for k in frames(s, 1.04, 1.79)} == {"b1:c1"}


def test_curves_stretched_by_the_plan_place_their_keys_in_proportion():
    r = realize(behaviour("c1", "curves", params={"curve:open": "0 0 0.5 1 0.8 0"}, start=1.0, end=2.6))
    s = evaluate_poses(r, fps=FPS)
    jaw = s.channel(JAW)
    assert jaw[frames(s, 2.0, 2.0)[0]] == pytest.approx(CHANNELS["open"].jaw, abs=1e-9)  # key 0.5 s, doubled
    assert np.argmax(jaw) == frames(s, 2.0, 2.0)[0]


def test_monotone_cubic_passes_through_its_keys_without_overshoot():
    xs, ys = [0.0, 0.1, 0.4, 0.5, 0.5, 1.0], [0.0, 1.0, 1.0, 0.2, 0.6, 0.0]
    t = np.linspace(-0.5, 1.5, 2001)
    v = monotone_cubic(xs, ys, t)
    assert monotone_cubic(xs, ys, [0.0, 0.1, 0.4, 1.0]) == pytest.approx([0.0, 1.0, 1.0, 0.0], abs=1e-12)
    assert monotone_cubic(xs, ys, [0.5]) == pytest.approx([0.6])  # two keys at one time: a step to the later
    assert v[t < 0].tolist() == [0.0] * int(np.sum(t < 0)) and np.all(v[t > 1.0] == 0.0)
    for a, b, ya, yb in zip(xs, xs[1:], ys, ys[1:]):
        seg = v[(t > a) & (t < b)]
        assert np.all(seg >= min(ya, yb) - 1e-12) and np.all(seg <= max(ya, yb) + 1e-12)
    assert np.all(v[(t > 0.1) & (t < 0.4)] == pytest.approx(1.0))  # a flat stretch stays flat


# --------------------------------------------------------------------------------------------- BVH
def test_bvh_carries_the_lip_joints_and_reads_back_with_an_independent_reader(tmp_path):
    import glm

    from helpers import bvh_reader

    r = realize(viseme("lips1", "BMP", 0.2, 0.3, 0.5, 0.6), viseme("lips2", "Aa", 0.6, 0.7, 0.9, 1.0),
                viseme("lips3", "Iy", 1.0, 1.1, 1.3, 1.4))
    s = evaluate_poses(r, fps=FPS)
    path = write_bvh(tmp_path / "lips.bvh", s)
    container, by_name, parent, world = bvh_reader(path)
    joints = list(by_name.values())
    names = [j.Name for j in joints]
    assert names == [j.name for j in s.body.joints]
    assert {n: parent[n].Name for n in ("lower_lip", "upper_lip", "l_lip_corner", "r_lip_corner")} == {
        "lower_lip": "temporomandibular", "upper_lip": "skullbase", "l_lip_corner": "skullbase",
        "r_lip_corner": "skullbase"}
    assert all(list(j.Channels) == ["Zrotation", "Xrotation", "Yrotation"] for j in joints[1:])
    assert sum(len(j.Channels) for j in joints) == len(s.channels)
    assert container.FrameCount == s.n_frames
    # the lip edges and mouth corners (end sites) where our own forward kinematics puts them
    for t in (0.4, 0.8, 1.2):
        k = int(round(t * FPS))
        fk = s.body.forward_kinematics(s.values[k:k + 1])
        for name in ("lower_lip", "upper_lip", "l_lip_corner", "r_lip_corner"):
            rot, pos = world(name, k)
            edge = pos + rot * glm.vec3(by_name[name].EndSite)
            ours = fk[name][1][0] + fk[name][0][0] @ np.asarray(s.body.joint[name].end_site)
            assert np.array(edge) == pytest.approx(ours, abs=1e-4), (t, name)


# --------------------------------------------------------------------------------------------- while speaking
SPEECH = ('<bml xmlns="http://www.bml-initiative.org/bml/bml-1.0" id="b1"><speech id="s">'
          '<text>Bob met a man, papa.</text></speech></bml>')


def test_the_mouth_while_speaking_follows_the_visemes_of_its_phonemes():
    from agentsim.animation.lips import SPEECH_BLEND, speech_visemes

    r = Realizer()
    r.submit(SPEECH)
    r.run()
    assert not r.feedback.warnings(), r.feedback.warnings()
    recording = r.recording()
    s = evaluate_poses(recording, fps=FPS)
    body = Body()
    rows = speech_visemes(recording)  # the phonemes as heard, on the run's clock
    start = recording.behaviour("b1:s").start

    def at(row):
        """The jaw (degrees) and the lips' opening (m) at the frame nearest the phoneme's middle."""
        k = int(round(0.5 * (row.start_s + row.end_s) * FPS))
        assert s.writer(k, JAW) == "b1:s"
        p = lip_points(body, mouth(s, k))
        return float(s.channel(JAW)[k]), float(p["upper_lip"][1] - p["lower_lip"][1])

    rest_gap = lip_points(body, {})["upper_lip"][1] - lip_points(body, {})["lower_lip"][1]
    opened = [at(row) for row in rows if row.viseme == "Aa"]
    # the bilabials once the mouth has blended in from the pose it found
    closed = [at(row) for row in rows if row.phoneme in ("p", "b", "m") and row.start_s > start + SPEECH_BLEND]
    assert len(opened) >= 2 and len(closed) >= 5
    jaw_open, jaw_closed = min(j for j, _ in opened), max(j for j, _ in closed)
    gap_open, gap_closed = min(g for _, g in opened), max(g for _, g in closed)
    print(f"/a/: jaw {jaw_open:.1f} deg or more, lips {gap_open * 1000:.1f} mm apart or more; /p b m/: jaw "
          f"{jaw_closed:.1f} deg or less, lips at most {gap_closed * 1000:.2f} mm apart (rest {rest_gap * 1000:.1f} mm)")
    # measured: /a/ 13.5 deg and 11.3 mm, /p b m/ 1.5 deg and -0.76 mm (the lower lip pressed on the upper)
    assert jaw_open > jaw_closed + 8.0
    assert gap_open > 3 * rest_gap and gap_closed < 0.1 * rest_gap
    # co-articulation: the mouth moves smoothly from one shape to the next (a step from /m/ to /a/ is 12 deg
    # of jaw in one frame)
    k = frames(s, start, recording.behaviour("b1:s").end)
    steps = {d: float(np.abs(np.diff(s.channel(d)[k])).max()) for d in MOUTH_DOFS}
    print("largest change in one frame:", {d: round(v, 2) for d, v in steps.items()})
    assert max(steps.values()) < 5.0


def test_the_speaking_mouth_counts_the_visemes_near_each_time_and_gives_the_same_value_however_it_is_cut():
    """viseme_track weighs each time by the visemes within its reach (REACH beyond the nearest middle; those
    further add less than e^-50 of the nearest): it is the average over every viseme of the speech to 1e-12
    degrees, and a time's value does not depend on which other times are computed with it (a frame, a live
    tick of a few frames, a window of a long run)."""
    from agentsim.animation.lips import (COARTICULATION, DOMINANCE, DOMINANCE_DEFAULT, VisemeTrack, speech_segments,
                                         viseme_track)
    from speech_timing.backend import SpeechText
    from speech_timing.builtin import BuiltinBackend

    text = "Bob met a man, papa. " * 40 + "Would you show me the way to the fish market?"
    utterance = BuiltinBackend().synthesize(SpeechText(text, ()))
    phonemes = [(p.symbol, p.start, p.end) for p in utterance.phonemes]
    phonemes += [(s, a + 30.0, b + 30.0) for s, a, b in phonemes[-20:]]  # after 30 s of silence
    u = np.arange(-0.5, phonemes[-1][2] + 0.5, 1 / 60)
    whole = viseme_track(phonemes, u)
    # every viseme, weighed at every time (what the track was before it was cut into reaches)
    segments = speech_segments(phonemes)
    weights = np.array([DOMINANCE.get(n.lower(), DOMINANCE_DEFAULT) * np.exp(-np.abs(u - 0.5 * (a + b)) / COARTICULATION)
                        for n, a, b in segments])
    share = weights / weights.sum(axis=0)
    for i, d in enumerate(MOUTH_DOFS):
        every = sum(share[k] * (VISEMES.get(n.lower()) or NEUTRAL).dofs()[d] for k, (n, _, _) in enumerate(segments))
        assert np.abs(whole[d] - every).max() < 1e-12, d
    track = VisemeTrack(phonemes, LEXICON)  # built once, as the speaking mouth builds it per speech
    for width in (1, 7, 600):
        cut = [track.at(u[a:a + width]) for a in range(0, len(u), width)]
        assert all(np.array_equal(np.concatenate([c[d] for c in cut]), whole[d]) for d in MOUTH_DOFS), width
