"""The environment of a run where its files need it: the rows of ``environment.csv``, the music mixed under the
speech, and what the report draws (the channels over time and the body as solid segments).

Nothing here runs for a run without emotions: :func:`run_environment` gives None and every output is what it
would be without this module."""

from __future__ import annotations

from agentsim.expression.environment import EnvironmentRow, environment_rows, has_emotions

#: The radius (m) of a finger's segment and of any other segment the physical model has none for.
FINGER_RADIUS = 0.009
OTHER_RADIUS = 0.02


def run_environment(recording, seed: int = 0, enabled: bool = True) -> list[EnvironmentRow] | None:
    """The environment's rows of a run with emotions (None without, or when not ``enabled``)."""
    if not enabled or not has_emotions(recording):
        return None
    return environment_rows(recording, seed)


def music_for(rows: list[EnvironmentRow] | None, sources, end: float):
    """The music source of ``rows`` under the speech ``sources`` (at their rate, 22050 Hz without any), from
    time 0 to ``end`` and its last fade; None when there is no music."""
    if not rows:
        return None
    from agentsim.expression.music import music_samples, speech_level
    from agentsim.media.audio import Source

    rate = max((s.rate for s in sources), default=22050)
    samples = music_samples(rows, end, rate, speech_level(sources))
    return Source(samples, int(rate), 0.0, label="environment:music") if len(samples) else None


def body_segments(body) -> list[list]:
    """The segments the report draws as capsules: ``[parent point, child point, radius]`` for each bone of
    :func:`~agentsim.media.report.data.point_names` outside the face, the radius that of the physical
    model's segment (:func:`~agentsim.physics.model.segment_radii`; the palm its hand's), fingers
    :data:`FINGER_RADIUS`."""
    from agentsim.media.report.data import FACE, point_names
    from agentsim.physics.model import segment_radii

    radii = segment_radii(body)
    names, parents = point_names(body)
    face = {i for i, n in enumerate(names) if n.split(".")[0] in FACE}
    hand = {i for i, n in enumerate(names) if n.split(".")[0][2:].startswith(("thumb", "index", "middle", "ring",
                                                                                 "pinky", "fingers"))}
    segments = []
    for child, parent in enumerate(parents):
        if parent < 0 or names[parent] == "skullbase" or (child in face and child not in hand):
            continue
        if names[child].endswith("_fingers"):  # the palm: the physical model's hand
            radius = radii.get(names[parent], OTHER_RADIUS)
        elif child in hand or parent in hand:
            radius = FINGER_RADIUS
        else:
            radius = radii.get(names[parent], OTHER_RADIUS)
        segments.append([parent, child, round(float(radius), 4)])
    return segments


def report_environment(rows: list[EnvironmentRow], stream) -> dict:
    """What the report's stage draws: the rows (time, emotion, intensity, shot, angle, key colour, attenuation,
    valence, music) and the body's segments."""
    return {
        "rows": [{"t": r.time, "emotion": r.channels.emotion, "intensity": r.channels.intensity,
                  "shot": r.channels.shot, "angle": r.channels.angle, "key": list(r.channels.key),
                  "attenuation": r.channels.attenuation, "valence": r.channels.valence, "music": r.music}
                 for r in rows],
        "segments": body_segments(stream.body) if stream is not None else [],
    }
