"""Engines: each one a Planner, a Plan and a Player for one output channel (speech, animation, waiting)."""
