"""A live realizer: the same realizer on the real-time clock, fed and watched while it plays.

:mod:`~agentsim.live.runtime` runs it in a thread of its own, the only one that touches it;
:mod:`~agentsim.live.intake` reads what clients send in another and hands it on ready;
:mod:`~agentsim.live.server` puts them behind a WebSocket endpoint (``agentsim serve``): clients send BML and
get every feedback, as :mod:`~agentsim.live.routing` addresses it, if :mod:`~agentsim.live.access` lets them
connect. :mod:`~agentsim.live.sound` plays its sound on an audio device when the plan says it is heard (the
clocks that meet there are :mod:`~agentsim.live.clocks`', the devices :mod:`~agentsim.live.devices`', and
:mod:`~agentsim.live.recorder` records an input to measure the loop back); :mod:`~agentsim.live.poses`
streams its poses to the browser viewer; :mod:`~agentsim.live.service` puts them together.
"""
