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
  the same system (all effects on; and with the ideal system, the scattering alone); with
  a sensor, also the same renders decoded without it (``surface_noise_free``: the row less
  the noise of both captures).

Deviations per fringe direction in phase of the finest width (mrad), monitor coordinate
(monitor px and mm) and surface slope (urad: the exact 3-D conversion of
:func:`pmdsim.measure.chain.slope_deviation_urad`, the same as ``simulate``'s: the tilt
that moves the exact reflection point by the deviation along the direction's monitor
axis). Statistics over pixels valid in every decoding involved: RMS and P95 of the
absolute value.

With fringes in x and y every decoding is also reconstructed as ``simulate`` does
(:mod:`pmdsim.measure.reconstruct`, ``[reconstruct]`` settings, the camera and monitor of the
ideal system) and gives a **height row** (:func:`height_row`): slope errors dz/dx, dz/dy
(urad, surface frame) and the height error (nm RMS/PV/P95) after the removal of
``[budget]`` (:mod:`pmdsim.measure.form`), with the Zernike tables of what is left. System
rows: reconstruction minus the true surface; surface rows: the surface's reconstruction
minus the mirror's through the same system. The calibration rows
(:mod:`pmdsim.studies.calibration`) reconstruct the ideal mirror's decoding with a
perturbed calibration.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from ..config import MirrorConfig, RunConfig
from ..measure.chain import SlopeGeometry, decode_fringes, slope_deviation_urad, surface_to_monitor_mm
from ..measure.deviation import deviation_stats
from ..measure.numerical import exceeds
from ..render import Simulation
from ..scene import Scene
from ..scene.sensor import Sensor, capture_dn
from .budget_areal import areal_of
from .budget_error import (ROW_STATS, at_order, difference_error, error_stats, estimator_label,
                           height_error_bounds, node_errors, second_estimate, solver_floors,
                           stat_error,
                           unknown_share)
from .height_rows import (Decoded, HeightError, SurfaceMaps, form_spec, height_error, height_row,
                          reconstruct_decoded, true_maps, wants_heights, zernike_disc)

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
_LENS = ("f_number", "numerical_aperture", "focus_distance_mm", "aperture_samples", "aperture_seed")

EFFECTS: tuple[Effect, ...] = (
    Effect("monitor_pixels", "monitor pixel grid (flat square emitters)",
           lambda c: c.monitor.pixel_model == "nearest", _copy_fields("monitor", ("pixel_model",))),
    Effect("footprint", "pixel footprint (sub-pixel rays)",
           lambda c: c.camera.subpixels > 1, _copy_fields("camera", ("subpixels",))),
    Effect("defocus", "lens aperture (monitor out of focus)",
           lambda c: c.camera.has_aperture, _copy_fields("camera", _LENS)),
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
    cam.update(subpixels=1, f_number=None, numerical_aperture=None, focus_distance_mm=None)
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


def decode_config(cfg: RunConfig, stream: int = 0, noise_free: bool = False):
    """Render the fringes of ``cfg``, capture them with its sensor, decode every direction.
    ``noise_free``: (the decoding, the same render decoded without the sensor) -- the second
    None without a sensor."""
    from ..measure.numerical import finest_phase_error

    t0 = time.perf_counter()
    sim = Simulation.from_config(cfg)
    fr = cfg.patterns.fringes
    res = sim.render_fringes(fr.widths_px, fr.directions, fr.shifts)
    error_px = None
    if not sim.scene.brdf.is_delta and res.phase_error() is not None:
        w = float(min(fr.widths_px))
        error_px = {d: np.asarray(finest_phase_error(res, d), np.float64) * w / (2 * math.pi)
                    for d in fr.directions}
    sensor = Sensor.from_config(cfg.sensor)
    level = None
    clean = None
    if noise_free and sensor.enabled:
        dn = decode_fringes(res, cfg.monitor.resolution, cfg.decode, None)
        clean = Decoded({d: np.asarray(r.monitor_coord_px, np.float64) for d, r in dn.items()},
                        {d: np.asarray(r.valid, bool) for d, r in dn.items()}, 0.0, error_px,
                        res.sampling)
    if sensor.enabled:
        # coupled shot noise: two orders of one render differ by the render, not a new draw
        res = replace(res, images=capture_dn(sensor, res.images, stream, coupled=True))
        level = sensor.saturation_dn
    dec = decode_fringes(res, cfg.monitor.resolution, cfg.decode, level)
    coord = {d: np.asarray(r.monitor_coord_px, np.float64) for d, r in dec.items()}
    valid = {d: np.asarray(r.valid, bool) for d, r in dec.items()}
    dec = Decoded(coord, valid, time.perf_counter() - t0, error_px, res.sampling)
    return (dec, clean) if noise_free else dec


@dataclass(frozen=True, eq=False)
class Truth:
    """Exact monitor coordinates (px) of the chief rays' principal reflections, the
    surface-to-monitor distance (mm) per pixel and what the 3-D slope conversion needs
    (the chief rays' geometry and the surface points, camera centre and monitor)."""

    coord: dict
    distance_mm: np.ndarray
    pitch_mm: float
    finest_width_px: float
    geometry: object = None
    slope_geometry: SlopeGeometry | None = None


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
                 float(min(cfg.patterns.fringes.widths_px)), geo,
                 SlopeGeometry(geo.points, sim.scene.camera.viewpoint, sim.scene.monitor))


def _unit_maps(direction: str, dev_px: np.ndarray, truth: Truth) -> dict:
    """A monitor-coordinate map (px) in every unit of :data:`QUANTITIES`."""
    with np.errstate(invalid="ignore"):
        urad = slope_deviation_urad(direction, dev_px, truth.geometry, truth.slope_geometry,
                                    truth.distance_mm, truth.pitch_mm)
    return {"mrad": dev_px * (2 * math.pi / truth.finest_width_px) * 1e3, "px": dev_px,
            "mm": dev_px * truth.pitch_mm, "urad": urad}


def _error_maps(direction: str, dev_px: np.ndarray, err_px: np.ndarray, truth: Truth) -> dict:
    """The per-pixel numerical error ``err_px`` (monitor px, >= 0) of a deviation ``dev_px``
    in every unit; the slope's: the larger change of the 3-D conversion for ``+-err_px``."""
    e = np.nan_to_num(np.abs(err_px), nan=0.0)
    out = {"mrad": e * (2 * math.pi / truth.finest_width_px) * 1e3, "px": e, "mm": e * truth.pitch_mm}
    s0 = _unit_maps(direction, dev_px, truth)["urad"]
    with np.errstate(invalid="ignore"):
        up = np.abs(_unit_maps(direction, dev_px + e, truth)["urad"] - s0)
        dn = np.abs(_unit_maps(direction, dev_px - e, truth)["urad"] - s0)
    out["urad"] = np.fmax(up, dn)
    return out


def _row(effect: str, label: str, part: str, direction: str, dev_px: np.ndarray, valid: np.ndarray,
         truth: Truth, seconds: float, err_px: np.ndarray | None = None) -> dict:
    """One deviation row: RMS and P95 of ``|dev_px|`` over ``valid`` in every unit, each with
    its numerical error (``*_err``, :func:`pmdsim.studies.budget_error.stat_error`; 0 without
    ``err_px``: the mirror's renders have no quadrature)."""
    row = {"effect": effect, "label": label, "part": part, "direction": direction}
    maps = _unit_maps(direction, dev_px, truth)
    errs = None if err_px is None else _error_maps(direction, dev_px, err_px, truth)
    for q, m in maps.items():
        s = deviation_stats(m, valid)
        row[f"rms_{q}"] = s.rms
        row[f"p95_{q}"] = s.p95
        for k in ROW_STATS:
            row[f"{k}_{q}_err"] = 0.0 if errs is None else stat_error(m, errs[q], valid, k)
    row["mean_px"] = deviation_stats(dev_px, valid).mean
    row["n_valid"] = int(np.count_nonzero(valid & np.isfinite(dev_px)))
    row["seconds"] = round(seconds, 2)
    if err_px is not None:
        row["error_unknown_share"] = unknown_share(err_px, valid & np.isfinite(dev_px))
    return row


def numerical_row(direction: str, err_px: np.ndarray, valid: np.ndarray, truth: Truth,
                  dev_px: np.ndarray, label: str) -> dict:
    """The budget's numerical error row of one direction: RMS and P95 of the per-pixel
    numerical error ``err_px`` (monitor px) of a surface row, in every unit."""
    row = {"effect": "numerical_error", "label": label, "part": "numerical",
           "direction": direction}
    for q, m in _error_maps(direction, dev_px, err_px, truth).items():
        st = error_stats(m, valid)
        row[f"rms_{q}"], row[f"p95_{q}"] = st["rms"], st["p95"]
        for k in ROW_STATS:
            row[f"{k}_{q}_err"] = None
    row["mean_px"] = float("nan")
    row["n_valid"] = int(np.count_nonzero(valid & np.isfinite(dev_px)))
    row["seconds"] = 0.0
    return row


# ------------------------------------------------------------------------ budget
@dataclass(frozen=True, eq=False)
class Budget:
    """Result of :func:`budget`: ``rows`` per (effect, direction) in every unit of
    ``QUANTITIES``; ``height_rows`` per effect (:func:`height_row`; empty without x and y
    fringes), calibration rows among them (``part == "calibration"``); ``settings`` (truth,
    estimator, removal, calibration uncertainties)."""

    rows: list
    height_rows: list = field(default_factory=list)
    settings: dict = field(default_factory=dict)


def budget(cfg: RunConfig, progress: Callable[[str], None] | None = None,
           truth: str = "centre") -> Budget:
    """The error budget of ``cfg`` (module docstring). ``truth``: the ground truth of the
    system rows, ``centre`` (the chief ray through the pixel centre) or ``footprint``
    (averaged over the pixel's vision rays). The surface is rendered with the radiometric
    estimator unless ``cfg`` names one (:func:`pmdsim.config.physical_estimator`); with
    ``sampling.target_error_mrad`` the ideal system's surface render raises the order until
    its stated error meets the target, and the full system's render uses that order (its
    row states the error it has there; a note says when it is above the target)."""
    import warnings

    from ..config import physical_estimator

    if cfg.patterns.fringes is None:
        raise ValueError("patterns.fringes: the budget decodes fringes; configure some")
    cfg = physical_estimator(cfg)
    say = progress or (lambda msg: None)
    heights = wants_heights(cfg)
    spec = form_spec(cfg)
    kind = truth
    truth = ground_truth(cfg, kind)
    rows: list[dict] = []
    hrows: list[dict] = []
    notes: list[str] = []
    dirs = cfg.patterns.fringes.directions
    ideal = ideal_config(cfg)
    scene = Scene.from_config(mirror(ideal))
    disc = zernike_disc(scene.surface)
    recs: dict = {}
    true_cache: dict = {}
    target = cfg.sampling.target_error_mrad

    def rec_of(name, dec):
        t0 = time.perf_counter()
        rec = reconstruct_decoded(cfg, scene, dec)
        recs[name] = rec
        return rec, time.perf_counter() - t0

    def truth_of(rec):
        key = (rec.x_mm.size, rec.y_mm.size, float(rec.x_mm[0]), float(rec.y_mm[0]))
        if key not in true_cache:
            true_cache[key] = true_maps(rec, scene.surface)
        return true_cache[key]

    def system(name, label, c):
        say(f"system: {label}")
        dec = decode_config(mirror(c))
        for d in dirs:
            ok = dec.valid[d] & np.isfinite(truth.coord[d])
            rows.append(_row(name, label, "system", d, dec.coord[d] - truth.coord[d], ok, truth, dec.seconds))
        if heights:
            rec, sec = rec_of(name, dec)
            herr = height_error(SurfaceMaps.of(rec), truth_of(rec), spec, disc)
            r = height_row(name, label, "system", herr, dec.seconds + sec, "reconstruction minus the true surface")
            # the mirror's render is exact: the reconstruction solver's floor alone
            floors = solver_floors(rec)
            r["areal"] = areal_of(herr, rec.spacing, floors=floors)
            hrows.append({**r, **height_error_bounds(herr, [], floors)})
        return dec

    ideal_dec = system("ideal", "ideal system (reference)", ideal)
    present = [e for e in EFFECTS if e.present(cfg)]
    for e in present:
        system(e.name, e.label, with_effects(cfg, [e.name]))
    full = with_effects(cfg, [e.name for e in present])
    ref_full = system("all_system", "all system effects together", full)

    numerical: dict = {}  # surface row -> direction -> (err_px, valid, dev_px)
    numerical_h: dict = {}
    sampling: dict = {}

    def emit(name, label, dec, ref, ref_name, err, seconds):
        """The surface row of decoding ``dec`` minus ``ref`` (per direction, height row)."""
        for d in dirs:
            ok = dec.valid[d] & ref.valid[d]
            dev = dec.coord[d] - ref.coord[d]
            rows.append(_row(name, label, "surface", d, dev, ok, truth, seconds, err[d]))
            numerical.setdefault(name, {})[d] = (err[d], ok, dev)
        if heights:
            rec, sec = rec_of(name, dec)
            base = SurfaceMaps.of(recs[ref_name])
            herr = height_error(SurfaceMaps.of(rec), base, spec, disc)
            row = height_row(name, label, "surface", herr, seconds + sec,
                             "surface's reconstruction minus the mirror's")
            shifted = []
            for sign in (1.0, -1.0):
                moved = Decoded({d: dec.coord[d] + sign * np.nan_to_num(err[d], nan=0.0) for d in dirs},
                                dec.valid, 0.0)
                rm = reconstruct_decoded(cfg, scene, moved)
                shifted.append(height_error(SurfaceMaps.of(rm), base, spec, disc))
            floors = solver_floors(rec, recs[ref_name])  # the surface's and the mirror's
            row["areal"] = areal_of(herr, rec.spacing, shifted, floors)  # areal parameters, PSDs
            hrows.append({**row, **height_error_bounds(herr, shifted, floors)})
            ne = node_errors(herr, shifted, floors)
            numerical_h[name] = HeightError(ne["slope_x_urad"], ne["slope_y_urad"], ne["height_nm"],
                                            herr.form)

    def surface(name, label, c, ref, ref_name):
        say(f"surface: {label}")
        dec, clean = decode_config(c, stream=1, noise_free=True)
        err, how = dec.error_px, "the render's stated error (finest fringe)"
        n_used = int((dec.sampling or {}).get("n_rays") or c.sampling.n_rays)
        if err is None or c.sensor.enabled:  # the same chain once more (budget_error)
            other, how2 = second_estimate(c, n_used, (dec.sampling or {}).get("mode"))
            say(f"surface: {label}, {how2} (its numerical error)")
            lo, lo_clean = decode_config(other, stream=1, noise_free=True)
            diff = difference_error(dec.coord, dec.valid, lo.coord, lo.valid)
            if clean is not None and clean.error_px is None and lo_clean is not None:
                # the noise-free row's own difference (the same two renders, no sensor)
                clean = replace(clean, error_px=difference_error(
                    clean.coord, clean.valid, lo_clean.coord, lo_clean.valid))
            if err is None:
                err, how = diff, how2
            else:  # the sensor's discrete electrons and DN: the larger of the two
                err = {d: np.fmax(err[d], diff[d]) for d in dirs}
                how = f"the larger of {how} and the {how2} (through the sensor)"
        sampling[name] = {**(dec.sampling or {}), "n_rays": n_used, "error_from": how}
        emit(name, label, dec, ref, ref_name, err, dec.seconds)
        if clean is not None:  # the same renders without the sensor: the row less its noise
            say(f"surface: {label}, without the sensor")
            ref_clean = decode_config(mirror(c.model_copy(update={"sensor": c.sensor.model_copy(
                update={"enabled": False})})))
            if heights:
                rec_of(f"{ref_name}_noise_free", ref_clean)
            emit(f"{name}_noise_free", "surface scattering, full system, no sensor", clean,
                 ref_clean, f"{ref_name}_noise_free",
                 err if clean.error_px is None else clean.error_px, 0.0)
        return n_used

    if not cfg.brdf.model == "mirror":
        n_ideal = surface("surface_ideal", "surface scattering, ideal system", ideal, ideal_dec, "ideal")
        if target is not None:  # the order the ideal system's render chose: the full
            # system's integrand (cover glass, a display's gamma, the nearest monitor's
            # staircase) may converge far more slowly, and raising its order until its own
            # statement meets the target re-rendered the camera up to max_rays (11 renders,
            # 49152 nodes, still 0.7 mrad on the reduced realistic system): its row states
            # the error of this order instead, and a note says when that is above the target
            full = at_order(full, n_ideal)
        surface("surface", "surface scattering, through the full system", full, ref_full, "all_system")
        for name, label in (("surface_ideal", "ideal system"), ("surface", "full system"),
                            ("surface_noise_free", "no sensor")):
            if name not in numerical:
                continue
            label = f"numerical error of the surface row ({label}; quadrature)"
            for d in dirs:
                e, ok, dev = numerical[name][d]
                rows.append({**numerical_row(d, e, ok, truth, dev, label),
                             "effect": f"numerical_{name}"})
            if heights and name in numerical_h:
                hrows.append({**height_row(f"numerical_{name}", label, "numerical", numerical_h[name]),
                              "zernike_noll_nm": [], "zernike_fringe_nm": [],
                              "how": "per node, the larger change of the row's slope and height "
                                     "errors when the decoded coordinates move by their "
                                     "numerical error (both signs)"})
        for r in rows:  # a deviation whose numerical error is > 10 % of it is not converged
            num = next((n for n in rows if n["effect"] == f"numerical_{r['effect']}"
                        and n["direction"] == r["direction"]), None)
            if num is not None and exceeds(r["rms_px"], num["rms_px"]):
                notes.append(f"{r['effect']} {r['direction'].upper()}: the numerical error "
                             f"({num['rms_px']:.2g} px RMS) is more than 10 % of the row "
                             f"({r['rms_px']:.2g} px): " + ("lower sampling.target_error_mrad" if target
                             is not None else "raise sampling.n_rays or set sampling.target_error_mrad"))
        if target is not None:
            for name, smp in sampling.items():
                worst_mrad = max(r["p95_mrad"] for r in rows if r["effect"] == f"numerical_{name}")
                if smp.get("target_met") is False or (smp.get("target_met") is None
                                                      and not worst_mrad <= target):
                    if name == "surface_ideal" or smp.get("target_met") is False:
                        why = (f"with the rule of n_rays = {smp['n_rays']}, the largest "
                               f"sampling.max_rays = {cfg.sampling.max_rays} allows: raise it "
                               "or accept the error")
                    else:  # rendered at the ideal system's order
                        why = (f"with the ideal system's rule (n_rays = {smp['n_rays']}): the "
                               "full system's integrand converges more slowly there (cover "
                               "glass, a display's gamma, a nearest monitor); the row states "
                               "this error: accept it, or raise sampling.n_rays (a full-system "
                               "order above the ideal's is not chosen by the target)")
                    msg = (f"sampling.target_error_mrad = {target:g} not met: the {name} row's "
                           f"numerical error is {worst_mrad:.3g} mrad (P95 of its rows) " + why)
                    notes.append(msg)
                    warnings.warn(msg, UserWarning, stacklevel=2)  # a note, no source path
    settings = {"truth": kind, "estimator": estimator_label(cfg.sampling),
                "brdf": cfg.brdf.model, "removed": spec.describe(), "sampling": sampling,
                "target_error_mrad": target, "warnings": notes}
    if heights and cfg.budget.calibration_rows:
        from .calibration import calibration_rows

        say("calibration rows")
        # the ideal mirror's decoding (no quadrature): the solvers' floors alone
        hrows += calibration_rows(cfg, scene, ideal_dec, recs["ideal"], spec, disc)
        settings["calibration"] = cfg.budget.calibration.model_dump()
    return Budget(rows, hrows, settings)