"""The ideal specular reference of a run's measurement chain (rendered and decoded once,
shared by the variants)."""

from __future__ import annotations

import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..config import ConfigError, RunConfig
from ..measure import chain
from ..studies.specular_reference import decode_specular_reference
from ..render import Geometry, Simulation
from .result import _Steps
from .threads import numba_takes_two_threads


@dataclass(frozen=True, eq=False)
class Reference:
    """The decoded ideal specular reference of a run (shared by its variants).

    ``reconstruction``: the reference's (Reconstruction, SurfaceErrors), or None; given as
    a :class:`concurrent.futures.Future` it is computed in a thread while the run renders
    and decodes the surface, and the attribute waits for it (and raises its error)."""

    decoded: dict
    distance_mm: np.ndarray
    seconds: float
    notes: tuple = ()
    _reconstruction: object = None

    @property
    def reconstruction(self):
        r = self._reconstruction
        return r.result() if isinstance(r, Future) else r

    def settle(self) -> None:
        """Wait until the reconstruction's thread (if any) has finished, without raising
        its error (that is raised where :attr:`reconstruction` is read). A run calls it
        before it forks: a fork while the thread runs a DCT shuts SciPy's pocketfft worker
        pool under it ("Work item submitted after shutdown")."""
        r = self._reconstruction
        if isinstance(r, Future):
            r.exception()



def chain_mode(cfg: RunConfig, decode: bool | None) -> tuple[bool, list[str]]:
    """(run the measurement chain?, notes). Raises ValueError when decoding is required
    (``decode.enabled = true`` or ``decode=True``) but impossible."""
    enabled = cfg.decode.enabled if decode is None else decode
    if enabled is False:
        return False, []
    problem = chain.decode_problem(cfg.patterns.fringes, cfg.decode, cfg.monitor.resolution)
    if problem is None:
        return True, []
    if enabled is True:
        raise ConfigError(f"invalid configuration:\n  decode.enabled: decoding was requested (decode.enabled = true or --decode), but "
                         f"{problem}")
    if cfg.patterns.fringes is None:
        return False, []  # nothing to decode, nothing to say
    return False, [f"decoding skipped: {problem}"]



def specular_reference(cfg: RunConfig, sim: Simulation, geometry: Geometry, steps: _Steps,
               n_tiles: int) -> Reference:
    """Render and decode the fringes of the ideal specular reference (mirror BRDF, one ray
    per pixel, the same camera, surface and monitor model)."""
    t = time.perf_counter()
    base = steps.done
    decoded, distance = decode_specular_reference(cfg, sim, geometry,
                                                  progress=steps.tiles(n_tiles))
    steps.finish_render(base, n_tiles)
    notes = []
    for d, res in decoded.items():
        exact = geometry.specular_u if d == "x" else geometry.specular_v
        q = (res.monitor_coord_px - exact)[res.valid]
        rms = float(np.sqrt(np.mean(q**2))) if q.size else 0.0
        if rms > 0.05:
            real = (cfg.sensor.enabled or not sim.scene.camera.is_simple_pinhole
                    or not sim.scene.monitor.is_linear or sim.scene.monitor.correction_params() is not None)
            why = ("the modelled camera, sensor and display (pmdsim budget splits it by effect)"
                   if real else "on a 'nearest' monitor a mirror sees single pixels, so every "
                   "deviation contains that quantisation; monitor.pixel_model = 'continuous' shows "
                   "the scattering alone")
            notes.append(
                f"the specular reference decodes {rms:.2f} monitor px RMS ({d.upper()}) away from "
                f"the exact specular points: {why} (statistics.json: reference_vs_exact_px)")
            break
    from . import reconstruction as recon

    # the reference's reconstruction runs in a thread while the run renders and decodes
    # the surface (it is read only when the surface is reconstructed): about 0.5 s less
    # wall on the Fig. 3 run. Its compiled kernels are parallel too: only with a Numba
    # threading layer that takes launches from two threads at once
    if recon.wanted(cfg, decoded) and numba_takes_two_threads():
        pool = ThreadPoolExecutor(1, thread_name_prefix="pmdsim-reference-reconstruction")
        rec = pool.submit(recon.reference_reconstruction, cfg, sim.scene, decoded)
        pool.shutdown(wait=False)  # its one thread ends with the job
    else:
        rec = recon.reference_reconstruction(cfg, sim.scene, decoded)
    return Reference(decoded, distance, time.perf_counter() - t, tuple(notes), rec)
