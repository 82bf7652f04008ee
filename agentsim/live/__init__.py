"""A live realizer: the same realizer on the real-time clock, fed and watched while it plays.

:mod:`~agentsim.live.server` runs it in a thread of its own behind a WebSocket endpoint (``agentsim
serve``): clients send BML and get every feedback. :mod:`~agentsim.live.sound` plays its sound on an audio
device when the plan says it is heard (the clocks that meet there are :mod:`~agentsim.live.clocks`', the devices
:mod:`~agentsim.live.devices`', and :mod:`~agentsim.live.recorder` records an input to measure the loop back); :mod:`~agentsim.live.poses` streams its poses to the browser viewer;
:mod:`~agentsim.live.service` puts them together.
"""
