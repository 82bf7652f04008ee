"""The virtual orchestra conductor: a closed loop of conducting gestures, a simulated ensemble and its sound.

The conductor beats time with its right hand (BML conducting gestures whose strokes are pegged to
anticipator beats), hears the ensemble (FluidSynth audio, block by block, through a causal beat tracker)
and re-times its planned beats while they play, to lead a dragging ensemble back to the score's tempo
(Elckerlyc's running example; Reidsma, Nijholt & Bos 2008). The ensemble is simulated: each musician
is a timekeeper with linear phase and period correction toward the conductor's ictus (seen after a
visual delay) and toward the other musicians (Vorberg & Wing 1996; Repp 2005; Wing, Endo, Bradbury &
Vorberg 2014), with timekeeper and motor noise.

=================  ========================================================================================
module             what lives there
=================  ========================================================================================
``config``         pieces (meter, bars, tempo changes, dynamics) and scenario configurations from TOML,
                   with their checks and defaults; meter, tempo and General MIDI instruments are
                   :mod:`agentsim.music`'s.
``ensemble``       the musician model (:class:`~scenarios.conductor.ensemble.Timekeeper`) and the
                   simulated ensemble that plays the score into a FluidSynth renderer.
``hearing``        the conductor's ears: the beat tracker that also records the audio and measures its
                   loudness.
``planning``       the conductor's online model of how the ensemble responds (a bank of Kalman filters)
                   and the model-predictive planner of ictus times.
``strategies``     ``follow``, ``target``, ``lead`` and ``best``: where the strokes go.
``conductor``      the conductor: conducting BML bar by bar, "play louder", stopping the piece.
``metrics``        tempo curves, recovery, asynchrony, beat-prediction scores and the tempo plot.
``scenario``       one run (simulated or live) and its output files.
``run``            the ``agentsim run conductor`` command's run (its options are in :mod:`agentsim.cli.scenarios`).
=================  ========================================================================================

Times are seconds, tempi beats per minute, levels decibels.
"""
