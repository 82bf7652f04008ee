"""Anticipators: predictors of the world's timing (metronome, tap tempo, audio beat tracking) that own
time pegs and move them while a plan plays."""
