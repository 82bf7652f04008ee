"""Speech timing: text-to-speech backends with word and phoneme timing, event delivery and animator time.

Modules
-------
backend, builtin, espeak, festival
    The backend interface and three backends (a deterministic timing model; espeak-ng with exact times;
    Festival, timed by its utterance structure, through a long-lived festival process).
plan
    :class:`~speech_timing.plan.SpeechPlan`, what is known about an utterance before it is played.
delivery
    Progress events of a playing utterance and the late, jittery, bursty channel that delivers them.
animator_time
    Animator-time strategies (Chang's ``t_A``) behind one interface, registered in ``STRATEGIES``.
    A package: path, base, baselines, envelope, warps and best, with the registry in its ``__init__``.
linear_model
    Chang's linear characters-to-time model; plans from it or from a backend's own timeline.
metrics
    Synchronisation errors and animator-time smoothness (snaps, stalls, rates).
harness
    A standalone SimPy evaluation: beat gestures on content words, scored against the audio.
"""
