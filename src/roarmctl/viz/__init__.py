"""Pictures of plans, trajectories and workspaces (matplotlib)."""
