"""The virtual storyteller: a story told for minutes with its gestures on the right syllables.

After de Melo's *Papous* (a 7.5-minute story told with 286 transcribed gestures reproduced) and his
phoneme-level sync marks (EML ``<tm event="onStart|onEnd|onPhone">``):

=============  ==========================================================================================
module         what it holds
=============  ==========================================================================================
``markup``     the annotation format (text with ``[beat]``, ``[point:door]``, ... in front of words) and
               its compiler to BML
``praat``      stories from, and tellings to, Praat TextGrids (words, phones and gestures tiers)
``voice``      the voice: a disk cache of synthesised utterances and phoneme-level sync marks
``telling``    realizing a story under an event-delivery condition and scoring every stroke against
               the stressed syllable it aims at
``run``        ``agentsim run storytelling``: the command, its outputs and the strategy comparison
``stories/``   the stories shipped
=============  ==========================================================================================
"""
