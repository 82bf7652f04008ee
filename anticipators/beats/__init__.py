"""Beats from audio: a causal beat tracker (onset envelope, tempo, phase, beat follower), baselines,
and their evaluation against reference beats.

Modules, front end first:

==============  ===================================================================================
``envelope``    onset-envelope sources: causal log-mel spectral flux of audio, or precomputed values
``tempo``       tempo by autocorrelation of onset strength (plain arrays, explicit frame rate)
``phase``       the latest beat at a known period, by a comb over onset strength
``onsets``      the salient onset near an expected time, timed on the waveform
``follower``    the Kalman beat follower: hypothesis switching, confidence, prediction
``dbn``         the joint tempo-phase filter: a beat-pointer network filtered forward over a beat activation
``network``     a small learned causal beat activation (dilated convolutions over per-band flux), numpy
``tracking``    :class:`~anticipators.beats.tracking.CausalBeatTracker`, which combines them, and the
                tracker registry (``make_tracker``, ``TRACKER_NAMES``)
``baselines``   the inter-onset-interval baseline and librosa's offline beat tracker
``evaluation``  scoring predictions made ahead of time, and running trackers over audio
==============  ===================================================================================
"""
