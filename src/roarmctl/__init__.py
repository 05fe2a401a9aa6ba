"""roarmctl: plan and execute pick-and-place trajectories for small robot arms."""

__version__ = "0.1.0"
