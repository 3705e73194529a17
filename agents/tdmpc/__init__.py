"""TD-MPC on those networks: the world model, its losses, the MPPI planner, replay of
episode slices, and the agent that ties them together (``agent``)."""
