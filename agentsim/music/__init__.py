"""Music for the virtual conductor and for testing beat trackers: scores with meter and tempo maps,
General MIDI instruments, rendering through FluidSynth block by block, and the exact beat times of what
was rendered."""
