"""The OCC emotions of de Melo's environment expression and what each does to the channels (thesis, section
3.5.4, Table 3.2 and equations 3.1 and 3.2)."""

from __future__ import annotations

from dataclasses import dataclass

#: agentsim's own extension namespace: ``<ex:emotion xmlns:ex="urn:agentsim:expression" .../>``.
EXPRESSION_NAMESPACE = "urn:agentsim:expression"

#: The emotions' potential is on [0, MAX_INTENSITY]; a story's tag without one gives DEFAULT_INTENSITY.
MAX_INTENSITY = 10.0
DEFAULT_INTENSITY = 2.0

#: The mood valence of each emotion type the thesis uses.
VALENCE = {
    "anger": "negative", "reproach": "negative", "disappointment": "negative", "fears-confirmed": "negative",
    "disliking": "negative", "distress": "negative", "fear": "negative", "relief": "positive",
    "neutral": "neutral", "hope": "positive", "liking": "positive", "satisfaction": "positive",
    "joy": "positive", "pride": "positive",
}
#: The emotion types, in the thesis's order.
EMOTIONS = tuple(VALENCE)

#: The key light's colour (RGB, 0-255) of each emotion type: Table 3.2 (pride as joy).
KEY_COLOUR = {
    "anger": (255, 0, 0), "reproach": (255, 0, 0),
    "disappointment": (200, 200, 200), "fears-confirmed": (200, 200, 200),
    "disliking": (220, 255, 0), "distress": (153, 153, 153),
    "fear": (255, 255, 255), "relief": (255, 255, 255), "neutral": (255, 255, 255),
    "hope": (255, 255, 200), "liking": (255, 255, 200), "satisfaction": (255, 255, 200),
    "joy": (255, 255, 0), "pride": (255, 255, 0),
}

#: Camera shots from far to near, and angles.
SHOTS = ("full", "medium", "close-up", "extreme-close-up")
ANGLES = ("eye", "low", "high")


def shot_of(intensity: float) -> str:
    """The camera's distance for the strongest emotion's potential: [0, 1.5] full, (1.5, 2.5] medium,
    (2.5, 4.5] close-up, above extreme close-up."""
    if intensity <= 1.5:
        return "full"
    if intensity <= 2.5:
        return "medium"
    if intensity <= 4.5:
        return "close-up"
    return "extreme-close-up"


def angle_of(emotion: str) -> str:
    """The camera's angle: low for anger and pride, high for fear, otherwise at the eyes."""
    return "low" if emotion in ("anger", "pride") else "high" if emotion == "fear" else "eye"


def attenuation_of(emotion: str, intensity: float) -> float:
    """The key light's attenuation: equation 3.1 for a positive emotion, 3.2 for a negative one, 0.5 for
    neutral."""
    valence = VALENCE[emotion]
    if valence == "positive":
        return min(0.5, 1.0 - intensity / MAX_INTENSITY)
    if valence == "negative":
        return max(0.25, intensity / MAX_INTENSITY)
    return 0.5


@dataclass(frozen=True)
class Channels:
    """What the camera, the light and the music show of the strongest active emotion (``none``: no emotion
    active; then a full shot at eye angle, a white key light at attenuation 0.5 and no music)."""

    emotion: str = "none"
    intensity: float = 0.0
    shot: str = "full"
    angle: str = "eye"
    key: tuple[int, int, int] = (255, 255, 255)
    attenuation: float = 0.5
    valence: str = "none"


NO_EMOTION = Channels()


def channels_of(emotion: str, intensity: float) -> Channels:
    """The channels of one emotion at one potential."""
    return Channels(emotion, intensity, shot_of(intensity), angle_of(emotion), KEY_COLOUR[emotion],
                    attenuation_of(emotion, intensity), VALENCE[emotion])


def emotion_problem(kind: str, intensity: str | None) -> str | None:
    """What is wrong with an emotion's ``type`` and ``intensity`` attributes as written (None if nothing)."""
    if kind not in VALENCE:
        return f"unknown emotion type {kind!r} (known: {', '.join(EMOTIONS)})"
    if intensity is None:
        return None
    try:
        value = float(intensity)
    except ValueError:
        return f"emotion intensity {intensity!r} is not a number"
    if not 0.0 <= value <= MAX_INTENSITY:
        return f"emotion intensity {intensity} is outside 0-{MAX_INTENSITY:g}"
    return None
