"""Robots as data: descriptions and their loaders, the one FK, IK families, dynamics, singularity models."""
