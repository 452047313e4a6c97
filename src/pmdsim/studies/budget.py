"""Error budget: how large the deviation is that each effect of a real PMD system causes,
next to the deviation the surface's scattering causes.

Ground truth: the exact geometric reflection point of each camera pixel, i.e. where the
principal reflection of the *chief ray through the pixel centre* (through the lens centre,
after undistortion) meets the *nominal* monitor plane (flat, no cover glass), in monitor px.
A calibrated PMD system without display or footprint models assumes exactly this point.

For each effect present in a configuration the chain (render -> display -> sensor -> decode)
runs on the *ideal mirror* with that effect alone on top of the ideal system (pinhole, one
ray per pixel, analytic continuous monitor, linear unquantised display, no glass, flat, no
falloff, noise-free), then with all the configuration's effects together:

- **system** rows: decoded minus ground truth, ideal mirror;
- **surface** rows: the scattering surface decoded minus the ideal mirror decoded through
  the same system (all effects on; and with the ideal system, the scattering alone).

Deviations per fringe direction in phase of the finest width (mrad), monitor coordinate
(monitor px and mm) and surface slope (urad, ``d_mm / (2 d)``, d the surface-to-monitor
distance of the pixel). Statistics over pixels valid in every decoding involved: RMS and
P95 of the absolute value.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from ..config import MirrorConfig, RunConfig
from ..measure.chain import decode_fringes, surface_to_monitor_mm
from ..measure.deviation import deviation_stats, slope_deviation
from ..render import Simulation
from ..scene.sensor import Sensor, capture_dn

QUANTITIES = ("mrad", "px", "mm", "urad")


@dataclass(frozen=True)
class Effect:
    """One error source: ``present(cfg)`` says whether the configuration has it,
    ``apply(ideal, cfg)`` puts the configuration's settings for it onto the ideal
    configuration's mapping (sections ``camera``, ``monitor``, ``sensor``)."""

    name: str
    label: str
    present: Callable[[RunConfig], bool]
    apply: Callable[[dict, RunConfig], None]


def _copy_fields(section: str, fields: tuple[str, ...]):
    def apply(ideal: dict, cfg: RunConfig) -> None:
        src = getattr(cfg, section)
        for f in fields:
            ideal[section][f] = getattr(src, f)
    return apply


_RESPONSE = ("gamma", "response_lut", "bit_depth", "precompensate_gamma", "black_level", "white_level")
_LENS = ("f_number", "focus_distance_mm", "aperture_samples", "aperture_seed")

EFFECTS: tuple[Effect, ...] = (
    Effect("monitor_pixels", "monitor pixel grid (flat square emitters)",
           lambda c: c.monitor.pixel_model == "nearest", _copy_fields("monitor", ("pixel_model",))),
    Effect("footprint", "pixel footprint (sub-pixel rays)",
           lambda c: c.camera.subpixels > 1, _copy_fields("camera", ("subpixels",))),
    Effect("defocus", "lens aperture (monitor out of focus)",
           lambda c: c.camera.f_number is not None, _copy_fields("camera", _LENS)),
    Effect("display_response", "display response (gamma/LUT, drive bits, black level)",
           lambda c: (c.monitor.gamma != 1.0 or c.monitor.response_lut is not None
                      or c.monitor.bit_depth is not None or c.monitor.black_level != 0.0),
           _copy_fields("monitor", _RESPONSE)),
    Effect("cover_glass", "cover glass refraction",
           lambda c: c.monitor.cover_glass_thickness_mm > 0,
           _copy_fields("monitor", ("cover_glass_thickness_mm", "cover_glass_index"))),
    Effect("flatness", "display flatness",
           lambda c: (any(v != 0 for row in c.monitor.flatness_coefficients_mm for v in row)
                      or c.monitor.flatness_map is not None),
           _copy_fields("monitor", ("flatness_coefficients_mm", "flatness_map"))),
    Effect("falloff", "display angular falloff",
           lambda c: c.monitor.falloff_exponent != 0 or len(c.monitor.falloff_table) > 0,
           _copy_fields("monitor", ("falloff_exponent", "falloff_table"))),
    Effect("sensor", "sensor (shot/dark noise, DSNU, PRNU, ADC)",
           lambda c: c.sensor.enabled, lambda ideal, c: ideal.update(sensor=c.sensor.model_dump())),
)


def ideal_config(cfg: RunConfig) -> RunConfig:
    """``cfg`` with the ideal system: pinhole with one ray per pixel (pose, intrinsics and
    distortion kept: the calibration is assumed right), continuous linear monitor without
    glass, bow or falloff, noise-free sensor; surface, BRDF, sampling and patterns kept."""
    d = cfg.model_dump()
    cam = d["camera"]
    cam.update(subpixels=1, f_number=None, focus_distance_mm=None)
    mon = d["monitor"]
    mon.update(pixel_model="continuous", gamma=1.0, response_lut=None, bit_depth=None,
               precompensate_gamma=False, black_level=0.0, white_level=1.0,
               cover_glass_thickness_mm=0.0, flatness_coefficients_mm=(), flatness_map=None,
               falloff_exponent=0.0,
               falloff_table=())
    d["sensor"] = {"enabled": False}
    d["variants"] = ()
    return RunConfig.model_validate(d)


def with_effects(cfg: RunConfig, names) -> RunConfig:
    """The ideal configuration with the effects ``names`` taken from ``cfg``."""
    d = ideal_config(cfg).model_dump()
    for e in EFFECTS:
        if e.name in names:
            e.apply(d, cfg)
    return RunConfig.model_validate(d)


def mirror(cfg: RunConfig) -> RunConfig:
    return cfg.model_copy(update={"brdf": MirrorConfig()})


@dataclass(frozen=True, eq=False)
class Decoded:
    """Decoded monitor coordinates (monitor px) per direction and their validity."""

    coord: dict
    valid: dict
    seconds: float


def decode_config(cfg: RunConfig, stream: int = 0) -> Decoded:
    """Render the fringes of ``cfg``, capture them with its sensor, decode every direction."""
    t0 = time.perf_counter()
    sim = Simulation.from_config(cfg)
    fr = cfg.patterns.fringes
    res = sim.render_fringes(fr.widths_px, fr.directions, fr.shifts)
    sensor = Sensor.from_config(cfg.sensor)
    level = None
    if sensor.enabled:
        res = replace(res, images=capture_dn(sensor, res.images, stream))
        level = sensor.saturation_dn
    dec = decode_fringes(res, cfg.monitor.resolution, cfg.decode, level)
    coord = {d: np.asarray(r.monitor_coord_px, np.float64) for d, r in dec.items()}
    valid = {d: np.asarray(r.valid, bool) for d, r in dec.items()}
    return Decoded(coord, valid, time.perf_counter() - t0)


@dataclass(frozen=True)
class Truth:
    """Exact monitor coordinates (px) of the chief rays' principal reflections and the
    surface-to-monitor distance (mm) per pixel."""

    coord: dict
    distance_mm: np.ndarray
    pitch_mm: float
    finest_width_px: float


TRUTHS = ("centre", "footprint")


def ground_truth(cfg: RunConfig, truth: str = "centre") -> Truth:
    """The exact reflection points: of the chief ray through each pixel centre (``centre``),
    or averaged over the pixel's vision rays of ``cfg``'s camera (``footprint``: sub-pixels
    x aperture samples; NaN where any of them misses)."""
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {TRUTHS}, got {truth!r}")
    sim = Simulation.from_config(mirror(ideal_config(cfg)))
    geo = sim.geometry()
    dist = surface_to_monitor_mm(sim, geo)
    coord = {"x": geo.specular_u, "y": geo.specular_v}
    if truth == "footprint":
        u, v = Simulation.from_config(mirror(cfg)).footprint_specular()
        coord = {"x": u, "y": v}
    return Truth(coord, dist, float(cfg.monitor.pixel_pitch_mm),
                 float(min(cfg.patterns.fringes.widths_px)))


def _row(effect: str, label: str, part: str, direction: str, dev_px: np.ndarray, valid: np.ndarray,
         truth: Truth, seconds: float) -> dict:
    row = {"effect": effect, "label": label, "part": part, "direction": direction}
    scales = {
        "mrad": dev_px * (2 * math.pi / truth.finest_width_px) * 1e3,
        "px": dev_px,
        "mm": dev_px * truth.pitch_mm,
        "urad": slope_deviation(dev_px * truth.pitch_mm, truth.distance_mm) * 1e6,
    }
    for q, m in scales.items():
        s = deviation_stats(m, valid)
        row[f"rms_{q}"] = s.rms
        row[f"p95_{q}"] = s.p95
    row["mean_px"] = deviation_stats(dev_px, valid).mean
    row["n_valid"] = int(np.count_nonzero(valid & np.isfinite(dev_px)))
    row["seconds"] = round(seconds, 2)
    return row


def budget(cfg: RunConfig, progress: Callable[[str], None] | None = None,
           truth: str = "centre") -> list[dict]:
    """The error budget of ``cfg`` (module docstring): a list of table rows, one per
    (effect or part, direction); every row has ``rms_*`` and ``p95_*`` in ``QUANTITIES``.
    ``truth``: the ground truth of the system rows, ``centre`` (the chief ray through the
    pixel centre) or ``footprint`` (averaged over the pixel's vision rays)."""
    if cfg.patterns.fringes is None:
        raise ValueError("patterns.fringes: the budget decodes fringes; configure some")
    say = progress or (lambda msg: None)
    truth = ground_truth(cfg, truth)
    rows: list[dict] = []
    dirs = cfg.patterns.fringes.directions

    def system(name, label, c):
        say(f"system: {label}")
        dec = decode_config(mirror(c))
        for d in dirs:
            ok = dec.valid[d] & np.isfinite(truth.coord[d])
            rows.append(_row(name, label, "system", d, dec.coord[d] - truth.coord[d], ok, truth, dec.seconds))
        return dec

    system("ideal", "ideal system (reference)", ideal_config(cfg))
    present = [e for e in EFFECTS if e.present(cfg)]
    for e in present:
        system(e.name, e.label, with_effects(cfg, [e.name]))
    full = with_effects(cfg, [e.name for e in present])
    ref_full = system("all_system", "all system effects together", full)

    def surface(name, label, c, ref):
        say(f"surface: {label}")
        dec = decode_config(c, stream=1)
        for d in dirs:
            ok = dec.valid[d] & ref.valid[d]
            rows.append(_row(name, label, "surface", d, dec.coord[d] - ref.coord[d], ok, truth,
                             dec.seconds))

    if not cfg.brdf.model == "mirror":
        ideal = ideal_config(cfg)
        say("system: ideal mirror (reference for the surface)")
        ref_ideal = decode_config(mirror(ideal))
        surface("surface_ideal", "surface scattering, ideal system", ideal, ref_ideal)
        surface("surface", "surface scattering, through the full system", full, ref_full)
    return rows


TABLE_COLUMNS = ("effect", "part", "direction", "rms_mrad", "p95_mrad", "rms_px", "p95_px",
                 "rms_mm", "p95_mm", "rms_urad", "p95_urad", "mean_px", "n_valid", "seconds", "label")
