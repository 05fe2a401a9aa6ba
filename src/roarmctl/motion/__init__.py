"""Motion: scene and FCL collision, OMPL paths, Cartesian lines, timing (TOPP-RA, jerk, blending), trajectories."""
