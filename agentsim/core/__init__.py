"""The core of the realizer: the clock, the one error root, time pegs and the PegBoard, the block model,
timed behaviours, engines (planner, plan, player), the solver, the scheduler, feedback, the anticipator
interface and the recording of a run. It imports nothing else of agentsim."""
