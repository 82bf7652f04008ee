"""A live realizer: the same realizer on the real-time clock, fed and watched while it plays.

:mod:`~agentsim.live.server` runs it in a thread of its own behind a WebSocket endpoint (``agentsim
serve``): clients send BML and get every feedback; a browser watches the agent move.
"""
