"""Speech timing: text-to-speech backends with word and phoneme timing, event delivery and animator time."""
