"""The physical body: mixed dynamics on MuJoCo (Elckerlyc's second characteristic).

The procedural animation steers some body parts kinematically (by default the neck, head, arms and hands:
gestures keep their exact timing and angles); the rest, with the root (the pelvis, legs and spine by
default), is simulated, and feels the kinematic parts' motion through inverse dynamics. Physical
controllers (``<bmlt:controller class="BalanceController|HangController|JointController">``) are timed
behaviours; while one is active its joints are physical. :mod:`~agentsim.physics.model` builds the body,
:mod:`~agentsim.physics.controllers` reads the controllers, :mod:`~agentsim.physics.simulation` steps it,
:mod:`~agentsim.physics.run` plays a realized run's poses through it. The package itself loads nothing
(the realizer reads controllers without numpy or MuJoCo): import what is needed from its modules.
"""
