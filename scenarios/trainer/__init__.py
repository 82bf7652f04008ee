"""The reactive virtual trainer: it exercises together with a person, at the person's tempo.

Elckerlyc's next application after the conductor (Reidsma, Nijholt & Bos): the trainer performs an exercise
with a user whose repetitions it hears through a motion sensor (:mod:`anticipators.reps`), pegs its own key
points and its counting to the predicted ones, and fits its remarks between repetitions.

=================  ========================================================================================
module             what lives there
=================  ========================================================================================
``names``          exercises, strategies, target tempi, the default output folder.
``signal``         the motion signal a phone worn by a person exercising reports, made from key points.
``user``           the simulated user: a noisy timekeeper drawn towards the trainer's key points.
``trainer``        the trainer: its moves pegged by strategy, its counting and remarks (``exercises.toml``:
                   its postures).
``scenario``       one run and its metrics.
``outputs``        the files a run writes, the report among them.
``run``            the ``agentsim run trainer`` command's run (its options are in :mod:`agentsim.cli.trainer`).
=================  ========================================================================================
"""
