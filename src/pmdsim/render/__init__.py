"""Rendering: scattered bundles, BRDF weights and pattern sums, tile by tile on Dask
(:class:`Simulation`); trace once, render any number of patterns from that transport.

``simulation`` (the render entry points), ``results`` (what a render returns, with its
numerical error), ``geometry_rows`` (the vision rays' rows for the kernels, sub-ray
reduction), ``tile_tasks`` (the tiles' Dask tasks), ``fringe_finish`` (the fringes finished
in each tile), ``convergence_grid`` (the pixels of the second embedded rule),
``control_variate`` (fringes on a nearest-pixel monitor), ``specular`` (a specular peak
beside a lobe)."""

from .results import FringeResult, Geometry
from .simulation import Simulation
from .tile_tasks import local_scheduler
from .geometry_rows import scene_geometry_rows

__all__ = ["Simulation", "FringeResult", "Geometry", "scene_geometry_rows", "local_scheduler"]
