"""agentsim: a BML realizer on a discrete-event clock, with measured synchronisation.

The project is four packages in layers; each imports only from the layers below it (``tests/test_layers.py``
checks, module by module):

1. ``agentsim.errors``: the one error root, which every package reaches (this package itself holds only
   its version, so importing the error root costs nothing).
2. ``speech_timing``: text-to-speech backends with word and phoneme timing, event delivery, the linear
   characters-to-time model and its calibration, animator-time strategies and speech metrics.
3. The realizer, in ``agentsim``: ``agentsim.core`` (the clock, time pegs, the block model, timed
   behaviours, engines, the solver, the scheduler, feedback, the anticipator interface and the recording),
   then ``agentsim.bml`` (reading BML), ``agentsim.music`` (scores rendered through FluidSynth) and
   ``agentsim.animation`` (the body and its motion), then ``agentsim.engines`` and ``agentsim.media`` (what
   a run writes), then ``agentsim.realizer``, which wires them together.
4. ``anticipators``: the beat tracker (``anticipators.beats``), the metronome, tap tempo and audio beat
   anticipators, the plugin registry and template.
5. ``scenarios``: the conductor, the storyteller and the speech-sync measurement.
6. ``agentsim.cli`` (the command line) and ``agentsim.live`` (the live service), on top of everything.
"""

__version__ = "0.1.0"
