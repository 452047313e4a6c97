"""The ideal specular reference of a run, rendered and decoded: the same camera, surface and
monitor model with a mirror BRDF and one ray per pixel, captured by the run's sensor (its own
noise stream 1) and decoded as the surface is (:func:`decode_specular_reference`)."""

from __future__ import annotations

from ..config import RunConfig
from ..measure.chain import decode_fringes, surface_to_monitor_mm


def decode_specular_reference(cfg: RunConfig, sim, geometry, progress=None):
    """Render, capture (with ``[sensor]``: its own noise stream 1) and decode the fringes of
    the ideal specular reference of ``sim`` (mirror BRDF, one ray per pixel, the same camera,
    surface and monitor model). Returns ``(decoded, distance_mm)``: the decoded directions
    (:func:`decode_fringes`) and the surface-to-monitor distance
    (:func:`surface_to_monitor_mm`)."""
    from dataclasses import replace

    from ..render import Simulation
    from ..scene.sensor import Sensor, capture_dn

    fr_cfg = cfg.patterns.fringes
    ref_sim = Simulation(sim.scene.specular(), sim.tile_rows, sim.scheduler, sim.num_workers)
    fr = ref_sim.render_fringes(fr_cfg.widths_px, fr_cfg.directions, fr_cfg.shifts,
                                progress=progress)
    sensor = Sensor.from_config(cfg.sensor)
    if sensor.enabled:
        fr = replace(fr, images=capture_dn(sensor, fr.images, 1))
    decoded = decode_fringes(fr, cfg.monitor.resolution, cfg.decode,
                             sensor.saturation_dn if sensor.enabled else None,
                             keep_amplitude=False)
    del fr
    return decoded, surface_to_monitor_mm(sim, geometry)
