"""Tracing: the vision ray of every camera pixel to the surface and its principal
reflection P (:mod:`.vision`)."""

from .vision import (PrimaryHits, bundle_geometry, cone_basis, specular_monitor_coords,
                     trace_pixels, trace_primary)

__all__ = ["PrimaryHits", "trace_primary", "trace_pixels", "cone_basis", "bundle_geometry",
           "specular_monitor_coords"]
