"""agentsim: a BML realizer on a discrete-event clock, with measured synchronisation.

The packages: ``agentsim`` (clock, BML, PegBoard, scheduler, engines, feedback, CLI), ``agentsim.speech``
(text-to-speech backends and speech timing), ``anticipators`` (predictors of the world's timing) and
``scenarios`` (the conductor and the storyteller).
"""

__version__ = "0.1.0"
