"""The face expressions, FACS action units and postures the body can show, by name: plain tables, read
without numpy (the BML reader looks up which lexemes have a motion here; :mod:`agentsim.animation.pose`
blends them)."""

from __future__ import annotations

#: Face expressions by lexeme: every ``faceLexeme`` of BML 1.0 (the brows, both or one, lowered, raised or
#: oblique; the mouth corners, both or one, raised or lowered; the mouth and the lips opened; the eyes
#: widened and closed) and a few of other realizers (FROWN, SMILE, SURPRISE, BLINK, BROW_RAISE). The face's
#: signs (see :mod:`agentsim.animation.body`): a negative eyebrow pitch raises the brow; a positive
#: ``l_eyebrow.roll`` (negative ``r_eyebrow.roll``) raises its outer end; a positive ``l_lip_corner.roll``
#: (negative ``r_lip_corner.roll``) raises that mouth corner; a positive eyelid pitch closes the eye.
FACE_LEXEMES: dict[str, dict[str, float]] = {
    "RAISE_BROWS": {"l_eyebrow.pitch": -12.0, "r_eyebrow.pitch": -12.0},
    "RAISE_LEFT_BROW": {"l_eyebrow.pitch": -12.0},
    "RAISE_RIGHT_BROW": {"r_eyebrow.pitch": -12.0},
    "LOWER_BROWS": {"l_eyebrow.pitch": 9.0, "r_eyebrow.pitch": 9.0},
    "LOWER_LEFT_BROW": {"l_eyebrow.pitch": 9.0},
    "LOWER_RIGHT_BROW": {"r_eyebrow.pitch": 9.0},
    # the inner ends up, the outer ends down: the sad, worried brows (FACS 1 + 4)
    "OBLIQUE_BROWS": {"l_eyebrow.pitch": -2.0, "r_eyebrow.pitch": -2.0, "l_eyebrow.roll": -12.0,
                      "r_eyebrow.roll": 12.0},
    "OBLIQUE_LEFT_BROW": {"l_eyebrow.pitch": -2.0, "l_eyebrow.roll": -12.0},
    "OBLIQUE_RIGHT_BROW": {"r_eyebrow.pitch": -2.0, "r_eyebrow.roll": 12.0},
    "RAISE_MOUTH_CORNERS": {"l_lip_corner.roll": 12.0, "r_lip_corner.roll": -12.0},
    "RAISE_LEFT_MOUTH_CORNER": {"l_lip_corner.roll": 12.0},
    "RAISE_RIGHT_MOUTH_CORNER": {"r_lip_corner.roll": -12.0},
    "LOWER_MOUTH_CORNERS": {"l_lip_corner.roll": -12.0, "r_lip_corner.roll": 12.0},
    "LOWER_LEFT_MOUTH_CORNER": {"l_lip_corner.roll": -12.0},
    "LOWER_RIGHT_MOUTH_CORNER": {"r_lip_corner.roll": 12.0},
    "OPEN_MOUTH": {"temporomandibular.pitch": 16.0},
    # the lips part on a closed jaw (FACS 25): the upper lip lifts, the lower drops
    "OPEN_LIPS": {"upper_lip.pitch": -8.0, "lower_lip.pitch": 12.0},
    "WIDEN_EYES": {"l_eyelid.pitch": -18.0, "r_eyelid.pitch": -18.0, "l_eyebrow.pitch": -6.0,
                   "r_eyebrow.pitch": -6.0},
    "CLOSE_EYES": {"l_eyelid.pitch": 72.0, "r_eyelid.pitch": 72.0},
    "BROW_RAISE": {"l_eyebrow.pitch": -12.0, "r_eyebrow.pitch": -12.0},
    "FROWN": {"l_eyebrow.pitch": 9.0, "r_eyebrow.pitch": 9.0, "l_eyebrow.roll": 6.0, "r_eyebrow.roll": -6.0},
    "BLINK": {"l_eyelid.pitch": 72.0, "r_eyelid.pitch": 72.0},
    "SMILE": {"temporomandibular.pitch": 3.0, "l_eyebrow.pitch": -3.0, "r_eyebrow.pitch": -3.0,
              "l_lip_corner.roll": 10.0, "r_lip_corner.roll": -10.0, "l_lip_corner.yaw": 6.0,
              "r_lip_corner.yaw": -6.0},
    "SURPRISE": {"l_eyebrow.pitch": -14.0, "r_eyebrow.pitch": -14.0, "temporomandibular.pitch": 12.0,
                 "l_eyelid.pitch": -15.0, "r_eyelid.pitch": -15.0},
}
#: The lexemes of the BML 1.0 standard (all in :data:`FACE_LEXEMES`).
BML_FACE_LEXEMES = ("OBLIQUE_BROWS", "RAISE_BROWS", "RAISE_LEFT_BROW", "RAISE_RIGHT_BROW", "LOWER_BROWS",
                    "LOWER_LEFT_BROW", "LOWER_RIGHT_BROW", "LOWER_MOUTH_CORNERS", "LOWER_LEFT_MOUTH_CORNER",
                    "LOWER_RIGHT_MOUTH_CORNER", "RAISE_MOUTH_CORNERS", "RAISE_RIGHT_MOUTH_CORNER",
                    "RAISE_LEFT_MOUTH_CORNER", "OPEN_MOUTH", "OPEN_LIPS", "WIDEN_EYES", "CLOSE_EYES")
#: FACS action units that this face can show (brows, lids, lips, mouth corners, jaw); ``side`` keeps one
#: side's half of a unit.
FACS_UNITS: dict[int, dict[str, float]] = {
    1: {"l_eyebrow.pitch": -5.0, "r_eyebrow.pitch": -5.0, "l_eyebrow.roll": -6.0, "r_eyebrow.roll": 6.0},  # inner brow raiser
    2: {"l_eyebrow.pitch": -5.0, "r_eyebrow.pitch": -5.0, "l_eyebrow.roll": 6.0, "r_eyebrow.roll": -6.0},  # outer brow raiser
    4: {"l_eyebrow.pitch": 9.0, "r_eyebrow.pitch": 9.0, "l_eyebrow.roll": 3.0, "r_eyebrow.roll": -3.0},  # brow lowerer
    5: {"l_eyelid.pitch": -18.0, "r_eyelid.pitch": -18.0},  # upper lid raiser
    7: {"l_eyelid.pitch": 25.0, "r_eyelid.pitch": 25.0},  # lid tightener
    10: {"upper_lip.pitch": -8.0},  # upper lip raiser
    12: {"l_lip_corner.roll": 12.0, "r_lip_corner.roll": -12.0, "l_lip_corner.yaw": 6.0,
         "r_lip_corner.yaw": -6.0},  # lip corner puller
    15: {"l_lip_corner.roll": -12.0, "r_lip_corner.roll": 12.0},  # lip corner depressor
    16: {"lower_lip.pitch": 12.0},  # lower lip depressor
    17: {"lower_lip.pitch": -8.0},  # chin raiser: the lower lip pushed up
    18: {"l_lip_corner.yaw": -16.0, "r_lip_corner.yaw": 16.0},  # lip pucker
    20: {"l_lip_corner.yaw": 14.0, "r_lip_corner.yaw": -14.0},  # lip stretcher
    22: {"l_lip_corner.yaw": -12.0, "r_lip_corner.yaw": 12.0, "upper_lip.pitch": -4.0,
         "lower_lip.pitch": 6.0},  # lip funneler
    24: {"upper_lip.pitch": 8.0, "lower_lip.pitch": -10.0},  # lip pressor
    25: {"upper_lip.pitch": -8.0, "lower_lip.pitch": 12.0},  # lips part
    26: {"temporomandibular.pitch": 12.0},  # jaw drop
    27: {"temporomandibular.pitch": 22.0},  # mouth stretch
    41: {"l_eyelid.pitch": 35.0, "r_eyelid.pitch": 35.0},  # lid droop
    42: {"l_eyelid.pitch": 55.0, "r_eyelid.pitch": 55.0},  # slit
    43: {"l_eyelid.pitch": 72.0, "r_eyelid.pitch": 72.0},  # eyes closed
    45: {"l_eyelid.pitch": 72.0, "r_eyelid.pitch": 72.0},  # blink
    46: {"l_eyelid.pitch": 72.0},  # wink (the left eye unless side says otherwise)
}

POSTURES: dict[str, dict[str, float]] = {
    "LEAN_FORWARD": {"vl5.pitch": 8.0, "HumanoidRoot.tz": 0.02},
    "LEAN_BACK": {"vl5.pitch": -6.0, "HumanoidRoot.tz": -0.02},
    "LEAN_LEFT": {"vl5.roll": -5.0, "HumanoidRoot.tx": 0.02},
    "LEAN_RIGHT": {"vl5.roll": 5.0, "HumanoidRoot.tx": -0.02},
    "WEIGHT_SHIFT": {"HumanoidRoot.tx": 0.025, "vl5.roll": 2.0, "r_knee.pitch": 8.0, "r_hip.pitch": -4.0},
}

