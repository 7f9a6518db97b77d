"""Simulator worlds: geometry, loading, ray casts (see :mod:`bagtools_simulate.world.world`)."""

from bagtools_simulate.world.world import Cylinder, Prism, World, load_world, packaged_world_names

__all__ = ["Cylinder", "Prism", "World", "load_world", "packaged_world_names"]
