"""agentsim: a BML realizer on a discrete-event clock, with measured synchronisation.

Its packages form layers; each imports only from layers below it (``tests/test_layers.py`` checks):

1. ``agentsim.core``: the clock, errors, time pegs, the block model, timed behaviours, engines, the
   solver, the scheduler, feedback, the anticipator interface and the recording of a run.
2. Libraries that know nothing of the realizer: ``agentsim.bml`` (reading BML), ``agentsim.speech``
   (text-to-speech and speech timing), ``agentsim.beats`` (beat tracking), ``agentsim.music`` (scores
   rendered through FluidSynth) and ``agentsim.animation`` (the body and its motion).
3. The realizer's parts: ``agentsim.engines`` and ``agentsim.anticipators``.
4. ``agentsim.realizer``, which wires them together.
5. ``agentsim.scenarios``: the conductor, the storyteller and the speech-sync measurement.
6. ``agentsim.cli``: the command line.
"""

__version__ = "0.1.0"
