"""The core of the realizer: the clock, time pegs and the PegBoard, the block model,
timed behaviours, engines (planner, plan, player), the solver, the scheduler, feedback, the anticipator
interface and the recording of a run. It imports nothing of agentsim but the error root (``agentsim.errors``)."""
