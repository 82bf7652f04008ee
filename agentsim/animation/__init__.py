"""The body side of agentsim: what moves, when, and which driver owns each joint.

A timed BML plan says *when* things happen; this package says *what the body does* then, in the
manner of Chang's Pantomime (drivers, a priority Arbitrator over degrees of freedom, a Driver Manager
with motor functions) and Elckerlyc's Animation Player (motion units whose keys are placed by linear
time warping, transition units, replacement groups):

=============  ==========================================================================================
module         what lives there
=============  ==========================================================================================
``body``       the H-Anim style skeleton: joints, offsets, Euler channels (BVH order ZXY), joint limits,
               degrees of freedom by name (``"skullbase.pitch"``), forward kinematics and the analytic
               two-link arm inverse kinematics.
``drivers``    Driver, Arbitrator (one writer per DOF and frame), master/slave drivers, the background
               drivers (breathing, eye-blink reflex, idle sway, eye fixation), the DriverManager with its
               motor functions, and TimeSource (the time a driver is advanced by).
``motion``     procedural motion units for every BML behaviour type, driven by a TimedBehaviour's actual
               key times: gesture phases with holds filled by an interpolator, the ictus of beats and
               conducting patterns at the stroke key, nods, shakes, pointing by inverse kinematics, gaze,
               face, posture, locomotion, and the jaw during speech.
``output``     ``evaluate_poses`` (a PoseStream of joint angles and joint positions per frame),
               ``write_bvh``, ``write_npz`` and ``plot_timeline``.
``analysis``   measuring where the motion really has its stroke (ictus, nod bottom, pointing arrival)
               against the stroke feedback.
=============  ==========================================================================================

Times are seconds, lengths metres, joint angles degrees.
"""

from agentsim.animation.body import Body
from agentsim.animation.drivers import Arbitrator, Driver, DriverManager, TimeSource
from agentsim.animation.output import PoseStream, evaluate_poses, plot_timeline, write_bvh, write_npz

__all__ = [
    "Arbitrator", "Body", "Driver", "DriverManager", "PoseStream", "TimeSource", "evaluate_poses",
    "plot_timeline", "write_bvh", "write_npz",
]
