"""The storyteller's names that the command line needs before anything runs: where a stroke may be
anchored in its word and the default output folder (kept here, apart from the modules that use them,
so that reading options imports nothing heavy)."""

#: Where in its word a gesture's stroke goes: the stressed vowel, a fixed offset, or the word's onset.
ANCHORS = ("stress", "offset", "word")
#: Where ``agentsim run storytelling`` writes by default.
DEFAULT_OUT = "out/storytelling"
