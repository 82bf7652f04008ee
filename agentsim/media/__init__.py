"""Everything a run writes, on one time axis: simulated time 0 is WAV sample 0, BVH and npz frame 0, and
``globalTime`` 0 of the feedback.

:mod:`~agentsim.media.audio` mixes what a listener of the run heard (each speech where it was heard, with its
playback latency, clock drift, volume changes and interruption; the sound files; an ensemble) into one
track; :mod:`~agentsim.media.tables` makes the tables people analyse (one row per pegged behaviour);
:mod:`~agentsim.media.files` writes the files, saying which axis they use where the format allows.
"""

#: What every file a run writes says of its time axis (where its format has room for it).
AXIS = "simulated time of the run: 0 s = WAV sample 0 = BVH/npz frame 0 = feedback globalTime 0"

#: Where every JSON a run writes points for what its fields mean: the README's "Glossary", which leads to the
#: documentation's (docs/reference/glossary.md).
GLOSSARY = "README.md#glossary"
