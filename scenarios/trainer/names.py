"""The trainer scenario's names: exercises, strategies, the default output folder."""

EXERCISES = ("squat", "jumping-jack", "arm-raise")
STRATEGIES = ("follow", "lead", "fixed")
DEFAULT_OUT = "out/trainer"
#: Each exercise's target tempo (repetitions a minute) when --target-tempo does not say.
TARGET_TEMPO = {"squat": 25.0, "jumping-jack": 50.0, "arm-raise": 20.0}
