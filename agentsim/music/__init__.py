"""Music for the virtual conductor and for testing beat trackers: scores with meter and tempo maps,
General MIDI instruments, rendering through FluidSynth block by block, and the exact beat times of what
was rendered.

===============  ========================================================================================
module           what lives there
===============  ========================================================================================
``tempo``        meters and tempo maps (tempo changes, ramps, steps, rubato) and the beat times they give.
``instruments``  General MIDI program names and aliases, the percussion channel and kit keys, the band's
                 parts and their programs.
``score``        notes placed in beats, the generated band piece, and the levels of dynamics markings.
``events``       timed synthesizer events (notes, program and control changes) and those of a score.
``midi``         scores as MIDI files with a tempo event per beat, their events and tick times.
``rendering``    FluidSynth: block-by-block rendering as a simulation advances, and MIDI files through the
                 ``fluidsynth`` program.
``onsets``       energy onsets and the renderer's constant onset offsets per instrument.
``ensemble``     a composed band rendered through MIDI and FluidSynth, with its exact reference beats.
===============  ========================================================================================

Times are seconds, tempi beats per minute, positions beats or bars counted from 0, levels decibels. A
missing FluidSynth library or program or a missing soundfont raises
:class:`~agentsim.errors.Unavailable` saying ``apt-get install fluidsynth fluid-soundfont-gm``.
"""
