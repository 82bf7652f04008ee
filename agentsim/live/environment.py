"""The environment of a live run: each change of the camera and the key light that the realizer's emotions
make, said to the viewers as it happens.

:class:`LiveEmotions` listens to the realizer's feedback in its thread (:attr:`LiveRealizer.listeners
<agentsim.live.runtime.LiveRealizer.listeners>`); an emotion's start or end that changes the strongest active
emotion becomes an ``environment`` message to the subscribers of the poses::

    {"type": "environment", "globalTime": 4.2, "emotion": "joy", "intensity": 3.2, "shot": "close-up",
     "angle": "eye", "key": [255, 255, 0], "attenuation": 0.5, "valence": "positive"}

The viewer cuts to it when its own clock reaches ``globalTime``. A block without emotions costs a look at its
behaviours' types, once."""

from __future__ import annotations

import math
from typing import Callable

from agentsim.expression.emotions import DEFAULT_INTENSITY, NO_EMOTION, VALENCE, channels_of
from agentsim.expression.environment import Felt, strongest


class LiveEmotions:
    """Turns the feedback of emotions into ``environment`` messages handed to ``send`` (in the realizer's
    thread)."""

    def __init__(self, live, send: Callable[[dict], None]):
        self.live = live
        self.send = send
        self.active: dict[tuple[str, str], Felt] = {}
        self.emotions: dict[str, dict[str, tuple[str, float]]] = {}  # block -> its emotions' types, intensities
        self.shown = NO_EMOTION
        self.order = 0

    def __call__(self, item: dict, sender: object = None) -> None:
        kind = item.get("type")
        if kind == "blockProgress" and item.get("id", "").endswith(":end"):
            block = item["id"][:-len(":end")]
            if self.emotions.pop(block, None):
                for key in [k for k in self.active if k[0] == block]:
                    del self.active[key]
                self.show(item["globalTime"])
            return
        if kind != "syncPointProgress":
            return
        block, _, rest = item.get("id", "").partition(":")
        behaviour, _, sync = rest.partition(":")
        if sync not in ("start", "end"):
            return
        if block not in self.emotions:
            self.emotions[block] = self.read(block)
        felt = self.emotions[block].get(behaviour)
        if felt is None:
            return
        if sync == "start":
            self.order += 1
            self.active[(block, behaviour)] = Felt(felt[0], felt[1], item["globalTime"], math.inf, self.order)
        else:
            self.active.pop((block, behaviour), None)
        self.show(item["globalTime"])

    def read(self, block_id: str) -> dict[str, tuple[str, float]]:
        """The emotions of a block: type and intensity by behaviour id (those the reader kept are valid)."""
        run = self.live.realizer.scheduler.book.find(block_id)
        if run is None:
            return {}
        return {b.id: (b.attributes.get("type", "").strip(), float(b.attributes.get("intensity", DEFAULT_INTENSITY)))
                for b in run.block.behaviours if b.type == "emotion" and b.attributes.get("type", "").strip() in VALENCE}

    def show(self, t: float) -> None:
        top = strongest(list(self.active.values()), t)
        channels = NO_EMOTION if top is None else channels_of(top.emotion, top.intensity)
        if channels == self.shown:
            return
        self.shown = channels
        self.send({"type": "environment", "globalTime": t, "emotion": channels.emotion,
                   "intensity": channels.intensity, "shot": channels.shot, "angle": channels.angle,
                   "key": list(channels.key), "attenuation": channels.attenuation, "valence": channels.valence})
