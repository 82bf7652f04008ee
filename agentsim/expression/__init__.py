"""Emotion expressed through the environment, as de Melo's storyteller does it: ``ex:emotion`` behaviours
drive a camera, a three-point light and music (thesis, section 3.5.4).

:mod:`~agentsim.expression.emotions` holds the tables (valence, shot, angle, key light and attenuation),
:mod:`~agentsim.expression.environment` the channels over a run's time, :mod:`~agentsim.expression.library`
the music library (generated in code, rendered with FluidSynth, cached) and :mod:`~agentsim.expression.music`
the music track mixed under the speech.
"""
