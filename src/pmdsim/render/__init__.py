"""Rendering: scattered bundles, BRDF weights and pattern sums, tile by tile on Dask
(:class:`Simulation`); trace once, render any number of patterns from that transport."""

from .results import FringeResult, Geometry
from .simulation import Simulation
from .tile_tasks import local_scheduler
from .geometry_rows import scene_geometry_rows

__all__ = ["Simulation", "FringeResult", "Geometry", "scene_geometry_rows", "local_scheduler"]
