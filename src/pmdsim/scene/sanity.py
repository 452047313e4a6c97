"""Physics sanity before the work: a sensor, display or BRDF whose settings leave no
decodable signal, or move the monitor off the reference, is refused (or noted, with the
share it affects), naming the section and field that cause it.

All checks are arithmetic on the configuration and the scene objects (no ray is traced):

- **sensor** (``[sensor]``, when enabled): the dark level alone fills the ADC or the full
  well (``dark_signal_electrons``, ``offset_dn``, ``gain_dn_per_electron``); the fringe
  amplitude spans less than one grey level (``bit_depth``, ``gain_dn_per_electron``); the
  temporal noise exceeds the fringe amplitude (``dark_noise_electrons``, the exposure); the
  dark-signal non-uniformity pushes most pixels to 0 or the full well (``dsnu_electrons``);
- **display** (``[monitor]``): the angular falloff leaves less than 1 % of the monitor area
  (seen from the part) above 1e-3 of its luminance (``falloff_exponent``,
  ``falloff_table``); the cover glass or the flatness moves the emitting pixels by more than
  half the monitor, or to the part itself (``cover_glass_thickness_mm``,
  ``flatness_coefficients_mm``, ``flatness_map``);
- **BRDF** (``[brdf]``, ``[brdf.variation]``): ``rho_s`` times the largest ``rho_s_scale``
  above 1 (an albedo above 1 reflects more light than falls on the surface), unless
  ``diagnostics.allow_albedo_above_one`` says it is meant.

The checks of a whole configuration, run by ``simulate``, ``budget``, ``sweep`` (every
point), ``converge`` and ``fit`` before any ray is traced, are
:mod:`pmdsim.studies.physics_checks`.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import BrdfConfig, ConfigError

#: Relative luminance below which a display direction counts as dark.
DARK_FALLOFF = 1e-3
#: Share of the monitor area (seen from the part) below which a display is refused / noted.
MIN_LIT_FRACTION, NOTE_LIT_FRACTION = 0.01, 0.5
#: Share of the sensor's pixels below which the DSNU is refused / noted.
MIN_SENSOR_FRACTION, NOTE_SENSOR_FRACTION = 0.01, 0.5


def _refuse(field: str, text: str) -> ConfigError:
    return ConfigError(f"invalid configuration:\n  {field}: {text}")


def _phi(x: float) -> float:
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


# ----------------------------------------------------------------------------- sensor
def check_sensor(sensor) -> list[str]:
    """Refuse a sensor (:class:`pmdsim.scene.sensor.Sensor`) that leaves no decodable fringe
    signal; return notes for one that loses many pixels. The fringe of a camera value in
    [0, x_ref] spans mean electrons in [0, E] (E the exposure): mid level E/2, amplitude E/2."""
    if not sensor.enabled:
        return []
    notes: list[str] = []
    k, e, fw = sensor.gain, sensor.exposure, sensor.full_well_electrons
    max_dn, mu_d, off = sensor.max_dn, sensor.dark_signal_electrons, sensor.offset_dn
    s = "sensor."
    if mu_d >= fw:
        raise _refuse(s + "dark_signal_electrons", f"{mu_d:g} e- of dark signal fill the full well "
                      f"({fw:g} e-): every pixel saturates; use a dark signal well below "
                      "full_well_electrons")
    dark_dn = k * mu_d + off
    if dark_dn >= max_dn:
        field = "gain_dn_per_electron" if sensor.gain_dn_per_electron is not None else "dark_signal_electrons"
        raise _refuse(s + field, f"the dark level alone is {dark_dn:.3g} DN, at or above the "
                      f"ADC maximum {max_dn} DN (bit_depth {sensor.bit_depth}): every pixel "
                      "saturates; lower gain_dn_per_electron (or the dark signal / offset)")
    # the mid level of the fringes, in DN; the amplitude that fits below the ADC and well tops
    mid_e = mu_d + e / 2
    if mid_e >= fw or k * mid_e + off >= max_dn:
        field = ("gain_dn_per_electron" if sensor.gain_dn_per_electron is not None
                 and k * mid_e + off >= max_dn else "exposure_electrons")
        raise _refuse(s + field, f"the mean fringe level ({mid_e:.3g} e-, {k * mid_e + off:.3g} "
                      f"DN) is at or above the full well ({fw:g} e-) or the ADC maximum "
                      f"({max_dn} DN): the fringes are clipped flat; lower the gain or the "
                      "exposure (target_fill)")
    amp_e = min(e / 2, fw - mid_e)
    amp_dn = min(k * amp_e, max_dn - (k * mid_e + off))
    if amp_dn < 1.0:
        field = "bit_depth" if max_dn < 16 else "gain_dn_per_electron"
        raise _refuse(s + field, f"the fringe amplitude is {amp_dn:.3g} DN, less than one grey "
                      f"level (bit_depth {sensor.bit_depth}, gain {k:.3g} DN/e-): the phase "
                      "shifts cannot be told apart; use more bits or a higher gain")
    shot = e / 2 if sensor.shot_noise else 0.0
    parts = {"dark_noise_electrons": k * k * sensor.dark_noise_electrons**2,
             "exposure_electrons": k * k * shot, "bit_depth": 1.0 / 12.0}
    noise_dn = math.sqrt(sum(parts.values()))
    if amp_dn < noise_dn:
        field = max(parts, key=parts.get)
        raise _refuse(s + field, f"the temporal noise ({noise_dn:.3g} DN) exceeds the fringe "
                      f"amplitude ({amp_dn:.3g} DN): no decodable signal; "
                      + ("lower dark_noise_electrons" if field == "dark_noise_electrons"
                         else "raise the exposure or the bit depth"))
    if sensor.dsnu_electrons > 0:
        # a pixel is usable while its dark offset keeps the whole fringe inside [0, full well]
        lo = (-mu_d) / sensor.dsnu_electrons
        hi = (fw - mu_d - e) / sensor.dsnu_electrons
        usable = max(0.0, _phi(hi) - _phi(lo))
        text = (f"a dark-signal non-uniformity of {sensor.dsnu_electrons:g} e- pushes "
                f"{100 * (1 - usable):.3g} % of the pixels' fringes against 0 or the full well")
        if usable < MIN_SENSOR_FRACTION:
            raise _refuse(s + "dsnu_electrons", text + "; use a DSNU well below the full well")
        if usable < NOTE_SENSOR_FRACTION:
            notes.append(f"sensor.dsnu_electrons: {text} (clipped pixels decode poorly)")
    return notes


# ----------------------------------------------------------------------------- display
def _monitor_samples(monitor, target: np.ndarray, n: int = 65):
    """(points on the monitor (n*n, 3), their emission angle towards ``target`` (rad),
    distance of ``target`` from the monitor plane (mm), monitor (x, y) mm from its centre)."""
    w, h = monitor.width, monitor.height
    u = np.linspace(0, w - 1, n)
    v = np.linspace(0, h - 1, n)
    uu, vv = np.meshgrid(u, v)
    pts = monitor.pixel_to_world(uu.ravel(), vv.ravel())
    d = np.asarray(target, np.float64) - pts
    dist = np.linalg.norm(d, axis=1)
    cos = np.clip((d @ monitor.normal) / np.maximum(dist, 1e-300), -1.0, 1.0)
    plane = float((np.asarray(target) - monitor.centre) @ monitor.normal)
    x = (uu.ravel() - (w - 1) / 2) * monitor.pitch
    y = (vv.ravel() - (h - 1) / 2) * monitor.pitch
    return np.arccos(cos), plane, x, y


def check_display(monitor, target) -> list[str]:
    """Refuse a display (:class:`pmdsim.scene.monitor.Monitor`) that is dark towards the
    part ``target`` (a world point, mm) or whose emitting surface is moved off the
    reference; notes when much of it is dark."""
    geom = monitor.display
    if geom.is_ideal:
        return []
    notes: list[str] = []
    theta, plane, x, y = _monitor_samples(monitor, target)
    facing = theta < math.pi / 2
    m = "monitor."
    if plane <= 0 or not facing.any():
        return []  # the set-up check (coverage) names the pose
    # falloff: the share of the monitor area that is lit towards the part, each factor alone
    c = np.cos(theta[facing])
    with np.errstate(under="ignore"):
        by_exp = c**geom.falloff_exponent
    by_tab = np.ones_like(c)
    if geom.falloff_table.shape[0]:
        tab = geom.falloff_table
        by_tab = np.interp(np.degrees(theta[facing]), tab[:, 0], tab[:, 1])
    total = float(np.mean(by_exp * by_tab >= DARK_FALLOFF))
    if total < NOTE_LIT_FRACTION:
        shares = {"falloff_exponent": float(np.mean(by_exp >= DARK_FALLOFF)),
                  "falloff_table": float(np.mean(by_tab >= DARK_FALLOFF))}
        field = min(shares, key=shares.get)
        text = (f"only {100 * total:.3g} % of the monitor area is brighter than {DARK_FALLOFF:g} "
                f"of its luminance in the direction of the part (emission angles "
                f"{np.degrees(theta[facing].min()):.3g} to {np.degrees(theta[facing].max()):.3g} deg)")
        if total < MIN_LIT_FRACTION:
            raise _refuse(m + field, text + "; the display shows the part nothing: check " + field)
        notes.append(f"{m}{field}: {text}")
    half = 0.5 * min(monitor.width, monitor.height) * monitor.pitch
    # cover glass: the pixels lie behind it, shifted along the surface
    t = geom.glass_thickness
    if t > 0:
        if t >= plane:
            raise _refuse(m + "cover_glass_thickness_mm", f"{t:g} mm of cover glass reach the "
                          f"part ({plane:.4g} mm in front of the monitor); give the glass "
                          "thickness in mm (about 0.5-3 mm on real displays)")
        shift = np.median(geom.glass_shift(theta[facing]))
        if shift > half:
            raise _refuse(m + "cover_glass_thickness_mm", f"the cover glass moves the seen "
                          f"pixels by {shift:.4g} mm (median), more than half the monitor "
                          f"({half:.4g} mm): the monitor is off the reference")
    # flatness: the emitting surface lies h in front of the nominal plane
    if geom.flatness.size or geom.height_map.size:
        hgt = geom.height(x, y, monitor.pitch)
        poly = (np.polynomial.polynomial.polyval2d(x, y, geom.flatness) if geom.flatness.size
                else np.zeros_like(hgt))
        field = ("flatness_map" if np.abs(hgt - poly).max() > np.abs(poly).max()
                 else "flatness_coefficients_mm")
        if np.abs(hgt).max() >= plane:
            raise _refuse(m + field, f"the emitting surface lies up to {np.abs(hgt).max():.4g} mm "
                          f"from the nominal plane, reaching the part ({plane:.4g} mm away); "
                          "heights are in mm (a flat display deviates by well under 1 mm)")
        lateral = np.median(np.abs(hgt[facing]) * np.tan(theta[facing]))
        if lateral > half:
            raise _refuse(m + field, f"the flatness moves the seen pixels by {lateral:.4g} mm "
                          f"(median), more than half the monitor ({half:.4g} mm): the monitor "
                          "is off the reference; heights are in mm")
    return notes


# ----------------------------------------------------------------------------- BRDF
def check_brdf(brdf: BrdfConfig, allow_albedo_above_one: bool = False) -> list[str]:
    """Refuse an albedo above 1: ``rho_s`` (the specular reflectance / Fresnel factor of every
    model that has one) times the largest ``rho_s_scale`` of ``[brdf.variation]`` (tables or
    map), unless ``allow_albedo_above_one`` (``diagnostics.allow_albedo_above_one``; then a
    note)."""
    rho = getattr(brdf, "rho_s", None)
    if rho is None:
        return []
    var = getattr(brdf, "variation", None)
    biggest, field = None, "brdf.rho_s"
    if var is not None and var.file is not None:
        from ..config.files import read_variation_map

        scale = read_variation_map(var.file, var.quantity).get("rho_s_scale")
        biggest = None if scale is None else float(scale.max())
    elif var is not None and var.rho_s_scale is not None:
        biggest = float(max(var.rho_s_scale))
    if biggest is not None:
        field = "brdf.variation." + ("file" if var.file is not None else "rho_s_scale")
    albedo = rho * (1.0 if biggest is None else biggest)
    if albedo <= 1.0:
        return []
    what = (f"rho_s = {rho:g}" if biggest is None
            else f"rho_s = {rho:g} times the largest rho_s_scale {biggest:g}")
    text = (f"{what} is an albedo of {albedo:.3g} > 1: the surface would reflect more light "
            "than falls on it")
    if allow_albedo_above_one:
        return [f"{field}: {text} (accepted: diagnostics.allow_albedo_above_one = true)"]
    fix = ("keep rho_s <= 1" if biggest is None else f"keep rho_s_scale <= {1 / rho:.4g}")
    raise _refuse(field, f"{text}; {fix}, or set diagnostics.allow_albedo_above_one = true "
                  "to use it as a relative brightness on purpose")


__all__ = ["check_sensor", "check_display", "check_brdf"]