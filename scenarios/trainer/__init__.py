"""The reactive virtual trainer: it exercises together with a person, at the person's tempo.

Elckerlyc's next application after the conductor (Reidsma, Nijholt & Bos): the trainer performs an exercise
with a user whose repetitions it hears through a motion sensor (:mod:`anticipators.reps`), pegs its own key
points and its counting to the predicted ones, and fits its remarks between repetitions.

=================  ========================================================================================
module             what lives there
=================  ========================================================================================
``signal``         the motion signal a phone worn by a person exercising reports, made from key points.
=================  ========================================================================================
"""
