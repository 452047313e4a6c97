"""Where did the valid pixels go? Each camera pixel that is not valid in a decoded fringe
direction was removed by one stage of the chain; this module counts them from a run's
statistics (``pixels`` of :func:`pmdsim.measure.chain.statistics`) and words the message,
naming the stage, its share of the camera pixels and the setting to look at:

=====================  ==========================================================  =======================
stage                  pixels                                                      look at
=====================  ==========================================================  =======================
geometry               the camera sees no surface there                            ``camera.look_at_mm``
display / reference    on the surface, but the ideal mirror's fringes do not        ``monitor`` (pose, display)
                       decode there (the reflection misses the monitor, or the
                       display is dark or moved there)
lobe off the monitor   the bundle puts too much weight off the monitor              ``brdf`` alphas, ``monitor``
scattering             the fringe modulation is washed out (below                  ``brdf`` alphas,
                       ``decode.min_modulation_ratio`` of the reference's)          ``patterns.fringes.widths_px``
sensor                 decoding flags saturated pixels                              ``sensor``
decoding               other decoding flags (low amplitude, order residual, ...)   ``decode``, ``sampling.n_rays``
=====================  ==========================================================  =======================

:func:`check_valid` refuses (a :class:`~pmdsim.config.ConfigError`) a run in which a
decoded direction has no valid pixel, unless ``diagnostics.allow_no_valid_pixels`` says it
is wanted; then it returns a note saying so.
"""

from __future__ import annotations

from ..config import ConfigError

#: (stage, what it means, the setting to look at), in chain order.
STAGES = (
    ("geometry", "miss the surface", "camera.look_at_mm"),
    ("display", "do not decode in the ideal mirror's reference (the reflection misses the "
     "monitor or the display is dark or moved there)", "monitor"),
    ("lobe off the monitor", "have their lobe off the monitor", "brdf"),
    ("scattering", "lose their fringe modulation to the scattering",
     "patterns.fringes.widths_px"),
    ("sensor", "saturate in the sensor", "sensor"),
    ("decoding", "are flagged by the decoding", "decode"),
)


def removed_by_stage(pixels: dict, camera_pixels: int) -> dict[str, int]:
    """Camera pixels removed by each stage (:data:`STAGES`) for one direction's
    ``pixels`` statistics; the counts and ``pixels['valid']`` add up to ``camera_pixels``."""
    flags = pixels.get("decode_flags_of_considered", {})
    flagged = int(pixels.get("decode_flagged", 0))
    saturated = min(flagged, int(flags.get("SATURATED", 0)))
    return {
        "geometry": camera_pixels - int(pixels["surface"]),
        "display": int(pixels["reference_flagged_on_surface"]),
        "lobe off the monitor": int(pixels.get("lobe_off_monitor", 0)),
        "scattering": int(pixels.get("low_modulation", 0)),
        "sensor": saturated,
        "decoding": flagged - saturated,
    }


def explain(direction: str, pixels: dict, camera_pixels: int) -> str:
    """'x fringes: 0 of N camera pixels valid; 12 % miss the surface (geometry), ...; the
    largest share: ... (look at ...)'."""
    counts = removed_by_stage(pixels, camera_pixels)
    parts = []
    for stage, what, _ in STAGES:
        if counts[stage]:
            parts.append(f"{100 * counts[stage] / camera_pixels:.3g} % {what} ({stage})")
    stage = culprit(counts)
    look = next(s for name, _, s in STAGES if name == stage)
    valid = int(pixels["valid"])
    return (f"{direction} fringes: {valid:,} of {camera_pixels:,} camera pixels valid; "
            + "; ".join(parts) + f"; of the pixels on the surface, the {stage} stage removed "
            f"the most (look at {look})")


def culprit(counts: dict[str, int]) -> str:
    """The stage that removed most of the pixels that see the surface (geometry only when
    no later stage removed any)."""
    later = {k: v for k, v in counts.items() if k != "geometry" and v}
    return max(later, key=later.get) if later else "geometry"


def check_valid(statistics: dict, camera_pixels: int, allow: bool, name: str = "") -> list[str]:
    """Refuse a decoded run (``statistics`` of one run or variant) in which a fringe
    direction has no valid pixel, naming the stage that removed them; with ``allow``
    return a note instead. Returns [] when every direction has valid pixels."""
    empty = [(d, st["pixels"]) for d, st in (statistics.get("directions") or {}).items()
             if int(st["pixels"]["valid"]) == 0]
    if not empty:
        return []
    who = f"{name}: " if name else ""
    text = "; ".join(explain(d, px, camera_pixels) for d, px in empty)
    if allow:
        return [f"{who}no valid pixels, kept because diagnostics.allow_no_valid_pixels = true: "
                + text]
    stage = culprit(removed_by_stage(empty[0][1], camera_pixels))
    field = next(s for n, _, s in STAGES if n == stage)
    why = ""
    if stage == "decoding" and _orders_disagree(empty[0][1]):
        field = "patterns.fringes.widths_px"
        why = (" The fringe orders of the widths disagree (ORDER_RESIDUAL): the finest fringe's "
               "phase is not the mirror's plus a small deviation; most often the bundle spans "
               "more than its period on the monitor and reverses its contrast (a cone or lobe "
               "wider than the fringe: a phase turned by pi; sampling.scheme = 'solid_angle' "
               "weighs the cone's rim more than 'polar'), or the sampling leaves a phase error "
               "above decode's residual limit. Drop the finest width, widen the fringes, use "
               "sampling.estimator = 'radiometric' (the whole lobe, no cone), or raise "
               "sampling.n_rays.")
    raise ConfigError(f"invalid set-up:\n  {field}: {who}no valid pixels to measure: {text}."
                      f"{why} Nothing was written; fix that stage (or set "
                      "diagnostics.allow_no_valid_pixels = true to keep such a run)")


def _orders_disagree(pixels: dict) -> bool:
    """Most of the pixels the decoding flagged have disagreeing fringe orders."""
    flags = pixels.get("decode_flags_of_considered", {})
    flagged = int(pixels.get("decode_flagged", 0))
    return flagged > 0 and int(flags.get("ORDER_RESIDUAL", 0)) >= 0.5 * flagged


def check_rows(rows, allow: bool, command: str, describe) -> list[str]:
    """Refuse the result of a study (``budget``'s rows, ``converge``'s rows: dicts with
    ``n_valid``) in which some row has no valid pixel, naming each such row
    (``describe(row)``); with ``allow`` (``diagnostics.allow_no_valid_pixels``) return a
    note instead. Nothing of the study is written when it is refused."""
    empty = [describe(r) for r in rows if int(r.get("n_valid", 1)) == 0]
    if not empty:
        return []
    text = f"no valid pixel in {len(empty)} of {len(rows)} rows: " + "; ".join(empty)
    if allow:
        return [f"{command}: {text} (kept because diagnostics.allow_no_valid_pixels = true)"]
    raise ConfigError(f"invalid set-up:\n  diagnostics.allow_no_valid_pixels: {command}: {text}; "
                      "nothing was written. Run the configuration with pmdsim simulate to see "
                      "which stage removes the pixels, or set "
                      "diagnostics.allow_no_valid_pixels = true to keep such rows")


__all__ = ["STAGES", "removed_by_stage", "culprit", "explain", "check_valid", "check_rows"]
