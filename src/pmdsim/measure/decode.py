"""Decoding of phase-shifted fringe images: wrapped phase, temporal unwrapping, monitor coordinate.

Works on plain arrays, so it serves simulated and real camera images alike. Conventions
(``docs/conventions.md``): images are ``(frames, height, width)``; a fringe of width (period)
``w`` monitor px with shift ``delta_k = 2 pi k / K`` shows ``0.5 + 0.5 cos(2 pi u / w + delta_k)``
at monitor pixel centre ``u`` (0-based, centres at integers); frames
``I_k = A + B cos(phi + delta_k)`` decode as

    Z = sum_k I_k exp(-i delta_k),  phi = arg Z in (-pi, pi],
    B = 2 |Z| / K (amplitude),  A = sum_k I_k / K (offset),  modulation = B / A,

and the absolute phase ``Phi = 2 pi u / w`` gives ``u = Phi w / (2 pi)``.

Names: ``amplitude`` is the fringe amplitude ``B`` (intensity units), ``modulation`` is
``B / A`` as in the conventions (NaN where ``A <= 0``), ``offset`` is ``A``.

Unwrapping methods (one fringe direction at a time; ``widths`` in any order):

``"hierarchical"`` (multi-frequency, Zuo et al. 2016)
    Needs distinct widths, the widest ``>= extent_px``: its phase is already absolute. Each
    finer width takes the order ``m = round((Phi_c w_c / w_f - phi_f) / (2 pi))`` from the
    next coarser one. Robust while the coarse phase error times ``w_c / w_f`` stays well
    below ``pi / 2`` (ratios of about 8 are common).
``"heterodyne"`` (multi-wavelength beat)
    Needs at least two distinct widths; sorted ascending, adjacent phases are subtracted into
    beat phases of synthetic wavelength ``w_a w_b / |w_a - w_b|``, level after level, until one
    beat is left, whose wavelength must be ``>= extent_px``; every beat must be longer than
    the finer of its two parents (widths within a factor < 2 of each other). The beats then
    unwrap each other down to the finest width. Noise is amplified by each beat ratio.
``"number_theoretic"`` (coprime periods)
    Needs integer widths ``w_j = p_j * g`` (``g`` their greatest common divisor) with
    pairwise coprime ``p_j``, and ``lcm(widths) = g * prod(p_j) >= extent_px``. The orders are
    the unique solution of the remainder equations (Chinese remainder theorem), computed
    exactly; a rounding residual measures the consistency. Tolerates phase errors up to
    about ``pi / (2 max p_j)``.

For every method the widest (synthetic) period ``L`` is cut where no monitor pixel lies: its
positions are wrapped into ``[(extent_px - L - 1) / 2, (extent_px + L - 1) / 2)`` (with
``L == extent_px`` this is exactly the monitor, ``[-0.5, extent_px - 0.5)``). When ``L`` is a
multiple of the finest width (number-theoretic: always) the cut is applied to the final, precise
position, so pixels at the monitor edges do not alias by ``L`` even when the coarse phase is
noisy; otherwise keep ``L`` clearly larger than ``extent_px``.

What flags can and cannot catch: an unwrapping step whose order error is ``e`` orders has the
residual ``|e|`` for ``|e| < 0.5`` and ``1 - |e|`` beyond, so with ``max_order_residual = 0.25``
every order error between 0.25 and 0.75 is flagged; a larger one (a gross phase error, or a far
Gaussian tail) cannot be told from a correct order by that step. A phase error that makes the
phases of all widths consistent with another position is invisible to every method: e.g. for
heterodyne widths ``[48, 54, 60]`` a contrast reversal (phase pi) of the 48 px fringes is exactly
the pattern at ``u + 1080`` (1080 = 22.5 * 48 = 20 * 54 = 18 * 60); it is flagged only when
that position is off the monitor. To be safe against contrast reversal, no multiple of the
least common multiple of the other widths (below ``L``) should be an odd multiple of half the
finest width (true for ``[50, 400, 3200]`` and ``[96, 128, 160]``).

Reliability flags (``uint8`` bit field, :class:`DecodeFlag`; ``valid = flags == 0``):

=====  ====================  ===========================================================
bit    name                  meaning
=====  ====================  ===========================================================
1      ``NAN_INPUT``         a frame (or input phase) of the pixel is NaN or infinite;
                             all outputs of the pixel are NaN
2      ``LOW_AMPLITUDE``     the amplitude ``B`` of some width is below
                             ``max(min_amplitude, min_relative_amplitude * median B)``
4      ``ORDER_RESIDUAL``    an unwrapping step's order residual exceeded
                             ``max_order_residual`` (0 = perfect, 0.5 = ambiguous)
8      ``OUT_OF_RANGE``      the monitor coordinate lies outside the monitor,
                             ``[-0.5, extent_px - 0.5)`` monitor px
16     ``SATURATED``         a frame of the pixel reached ``saturation_level`` (the camera's
                             full well or ADC maximum): its phase is biased
=====  ====================  ===========================================================
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..kernels import decode as _k
from .decode_plan import (
    _Plan, _check_frames, _check_out_dtype, _check_positive, _check_shifts,
    _check_thresholds, _check_widths, _plan,
)

__all__ = [
    "DecodeFlag",
    "DecodeResult",
    "PhaseShiftResult",
    "UnwrapResult",
    "decode_sequence",
    "monitor_px_to_mm",
    "phase_shift",
    "phase_to_monitor_px",
    "unwrap_phase",
]

# median of the amplitude is taken over a regular grid of at most this many pixels
_MEDIAN_SAMPLES = 1 << 16


class DecodeFlag(enum.IntFlag):
    """Bits of the per-pixel ``flags`` (uint8); a pixel is valid when no bit is set."""

    NAN_INPUT = int(_k.FLAG_NAN_INPUT)
    LOW_AMPLITUDE = int(_k.FLAG_LOW_AMPLITUDE)
    ORDER_RESIDUAL = int(_k.FLAG_ORDER_RESIDUAL)
    OUT_OF_RANGE = int(_k.FLAG_OUT_OF_RANGE)
    SATURATED = 16


@dataclass(frozen=True, eq=False)
class PhaseShiftResult:
    """Phase shifting of one fringe width.

    Attributes
    ----------
    wrapped_phase : (H, W) ndarray, rad
        ``phi`` in (-pi, pi]; NaN where an input frame is not finite.
    amplitude : (H, W) ndarray, intensity units
        Fringe amplitude ``B = 2 |Z| / K``.
    offset : (H, W) ndarray, intensity units
        ``A = mean_k I_k``.
    modulation : (H, W) ndarray, 1
        ``B / A``; NaN where ``A <= 0``.
    valid : (H, W) ndarray of bool
        All K frames finite.
    """

    wrapped_phase: np.ndarray
    amplitude: np.ndarray
    offset: np.ndarray
    modulation: np.ndarray
    valid: np.ndarray


@dataclass(frozen=True, eq=False)
class UnwrapResult:
    """Temporal unwrapping of one direction.

    Attributes
    ----------
    absolute_phase : (H, W) ndarray of float64, rad
        Absolute phase ``Phi`` of the finest width.
    monitor_coord_px : (H, W) ndarray of float64, monitor px
        ``u = Phi w_finest / (2 pi)`` (0-based, pixel centres at integers).
    order_residual : (H, W) ndarray of float64, 1
        Largest order residual of the unwrapping steps (0 = perfect, 0.5 = ambiguous).
    flags : (H, W) ndarray of uint8
        :class:`DecodeFlag` bits.
    valid : (H, W) ndarray of bool
        ``flags == 0``.
    finest_width_px : float
        Width whose absolute phase is returned, monitor px.
    """

    absolute_phase: np.ndarray
    monitor_coord_px: np.ndarray
    order_residual: np.ndarray
    flags: np.ndarray
    valid: np.ndarray
    finest_width_px: float


@dataclass(frozen=True, eq=False)
class DecodeResult:
    """Everything decoded from the fringe images of one direction.

    Per-width arrays follow the order of ``widths_px`` (the order the caller gave).

    Attributes
    ----------
    absolute_phase : (H, W) ndarray of float64, rad
        Absolute phase of the finest width.
    monitor_coord_px : (H, W) ndarray of float64, monitor px
        Monitor coordinate ``u = Phi w_finest / (2 pi)`` (0-based, centres at integers).
    wrapped_phase : (n_widths, H, W) ndarray, rad
        Wrapped phase of each width, in (-pi, pi].
    modulation : (n_widths, H, W) ndarray, 1
        ``B / A`` of each width (NaN where ``A <= 0``).
    amplitude : (n_widths, H, W) ndarray, intensity units
        Fringe amplitude ``B`` of each width (None where the caller dropped it:
        :func:`pmdsim.measure.chain.decode_fringes` with ``keep_amplitude=False``).
    offset : (n_widths, H, W) ndarray, intensity units
        Offset ``A`` of each width (None with ``amplitude``).
    order_residual : (H, W) ndarray of float64, 1
        Largest order residual of the unwrapping steps.
    flags : (H, W) ndarray of uint8
        :class:`DecodeFlag` bits.
    valid : (H, W) ndarray of bool
        ``flags == 0``.
    widths_px : tuple of float
        The fringe widths, monitor px, in the caller's order.
    finest_width_px : float
        Width of ``absolute_phase``, monitor px.
    method : str
        Unwrapping method used.
    """

    absolute_phase: np.ndarray
    monitor_coord_px: np.ndarray
    wrapped_phase: np.ndarray
    modulation: np.ndarray
    amplitude: np.ndarray
    offset: np.ndarray
    order_residual: np.ndarray
    flags: np.ndarray
    valid: np.ndarray
    widths_px: tuple
    finest_width_px: float
    method: str


# --------------------------------------------------------------------------- phase shifting


def _shift_tables(n_shifts: int):
    delta = 2.0 * np.pi * np.arange(n_shifts) / n_shifts
    return np.cos(delta), np.sin(delta)


def phase_shift(frames, *, dtype=np.float64) -> PhaseShiftResult:
    """Wrapped phase, amplitude, offset and modulation of K equally shifted frames.

    Parameters
    ----------
    frames : (K, H, W) ndarray, intensity units
        ``I_k = A + B cos(phi + 2 pi k / K)``, ``K >= 3``; float32, float64 or integer
        (converted to float). Not modified.
    dtype : {float64, float32}, optional
        Dtype of the returned maps (sums are always accumulated in float64).

    Returns
    -------
    PhaseShiftResult
        ``wrapped_phase`` (H, W) rad in (-pi, pi], ``amplitude`` ``B``, ``offset`` ``A``,
        ``modulation`` ``B / A``, ``valid`` (all frames finite). Pixels with a non-finite
        frame are NaN and invalid.

    Raises
    ------
    ValueError
        If ``frames`` is not (K, H, W) with ``K >= 3``, or ``dtype`` is not a float dtype.
    """
    arr = _check_frames(frames, "frames", 3, "(K, H, W)")
    dt = _check_out_dtype(dtype)
    n_shifts, height, width = arr.shape
    if n_shifts < 3:
        raise ValueError(f"frames needs K >= 3 phase shifts along axis 0, got K = {n_shifts}")
    cos_d, sin_d = _shift_tables(n_shifts)
    out = [np.empty((height, width), dt) for _ in range(4)]
    _k.phase_shift(arr, cos_d, sin_d, *out)
    return PhaseShiftResult(out[0], out[1], out[2], out[3], np.isfinite(out[0]))


# --------------------------------------------------------------------------- unwrapping


def _amplitude_thresholds(amplitude: np.ndarray, min_amplitude: float, min_relative: float):
    """max(absolute, relative * median) per width; median over a regular pixel grid."""
    n, height, width = amplitude.shape
    thresholds = np.full(n, min_amplitude)
    if min_relative > 0:
        step = max(1, math.ceil(math.sqrt(height * width / _MEDIAN_SAMPLES)))
        for j in range(n):
            sample = amplitude[j, ::step, ::step]
            sample = sample[np.isfinite(sample)]
            if sample.size:
                thresholds[j] = max(min_amplitude, min_relative * float(np.median(sample)))
    return thresholds


def _run_unwrap(plan: _Plan, phase, extent, max_residual, abs_phase, coord, residual, flags):
    if plan.method == "number_theoretic":
        _k.unwrap_coprime(phase, plan.order, plan.widths, plan.step_factor, plan.step_inverse,
                          plan.step_period, plan.unit, plan.window_lo, extent, max_residual,
                          abs_phase, coord, residual, flags)
    else:
        _k.unwrap_chain(phase, plan.coef, plan.chain_w, plan.window_lo, plan.rewrap_period,
                        extent, max_residual, abs_phase, coord, residual, flags)


def unwrap_phase(
    wrapped_phase,
    widths: Sequence[float],
    extent_px: float,
    method: str = "hierarchical",
    *,
    amplitude=None,
    min_amplitude: float = 0.0,
    min_relative_amplitude: float = 0.1,
    max_order_residual: float = 0.25,
) -> UnwrapResult:
    """Temporal unwrapping of the wrapped phases of several fringe widths (one direction).

    Parameters
    ----------
    wrapped_phase : (n_widths, H, W) ndarray, rad
        Wrapped phase of each width, in the order of ``widths``. Not modified.
    widths : sequence of float, monitor px
        Fringe widths (periods), any order; what each method needs is described in the
        module docstring.
    extent_px : float, monitor px
        Monitor extent along this direction (number of monitor pixels).
    method : {"hierarchical", "heterodyne", "number_theoretic"}
        Unwrapping method.
    amplitude : (n_widths, H, W) ndarray, intensity units, optional
        Fringe amplitude ``B`` of each width; without it no pixel gets ``LOW_AMPLITUDE``.
    min_amplitude : float, intensity units
        Absolute amplitude threshold.
    min_relative_amplitude : float, 1
        Threshold relative to the median amplitude of each width (median over a regular grid
        of at most 65536 pixels); the larger of the two thresholds applies.
    max_order_residual : float, 1
        Order residual above which a pixel is flagged, in (0, 0.5].

    Returns
    -------
    UnwrapResult
        Absolute phase of the finest width (rad), monitor coordinate (monitor px), order
        residual, flags and valid mask, all (H, W).

    Raises
    ------
    ValueError
        If the shapes disagree, or the widths do not fit the method (the message names the
        argument and the fix).
    """
    phase = _check_frames(wrapped_phase, "wrapped_phase", 3, "(n_widths, H, W)")
    plan = _plan(widths, extent_px, method)
    extent = float(extent_px)
    a_min, rel, res = _check_thresholds(min_amplitude, min_relative_amplitude, max_order_residual)
    if phase.shape[0] != plan.n_widths:
        raise ValueError(
            f"wrapped_phase has {phase.shape[0]} widths along axis 0 but widths has "
            f"{plan.n_widths} entries"
        )
    amp = None
    if amplitude is not None:
        amp = _check_frames(amplitude, "amplitude", 3, "(n_widths, H, W)")
        if amp.shape != phase.shape:
            raise ValueError(
                f"amplitude must have the shape of wrapped_phase {phase.shape}, got {amp.shape}"
            )
    height, width = phase.shape[1:]
    abs_phase = np.empty((height, width))
    coord = np.empty((height, width))
    residual = np.empty((height, width))
    flags = np.empty((height, width), np.uint8)
    _run_unwrap(plan, phase, extent, res, abs_phase, coord, residual, flags)
    if amp is not None:
        _k.flag_low_amplitude(amp, _amplitude_thresholds(amp, a_min, rel), flags)
    return UnwrapResult(abs_phase, coord, residual, flags, flags == 0, plan.finest_width)


def decode_sequence(
    frames,
    widths: Sequence[float],
    shifts: int,
    extent_px: float,
    method: str = "hierarchical",
    *,
    min_amplitude: float = 0.0,
    min_relative_amplitude: float = 0.1,
    max_order_residual: float = 0.25,
    dtype=np.float64,
    saturation_level: float | None = None,
) -> DecodeResult:
    """Decode the fringe images of one direction to absolute phase and monitor coordinate.

    One fused pass over the frames (parallel over rows) computes the wrapped phase, amplitude,
    offset and modulation of every width, unwraps, and flags the pixels.

    Parameters
    ----------
    frames : (n_widths, K, H, W) ndarray, intensity units
        Frame ``[j, k]`` shows width ``widths[j]`` with shift ``2 pi k / K``; float32,
        float64 or integer. Not modified.
    widths : sequence of float, monitor px
        Fringe widths (periods), any order (the order of ``frames``).
    shifts : int or (K,) array_like, rad
        Number K >= 3 of equal phase shifts per width, or the shifts themselves (they must be
        ``2 pi k / K``, k = 0..K-1); K must equal ``frames.shape[1]``.
    extent_px : float, monitor px
        Monitor extent along this direction (number of monitor pixels).
    method : {"hierarchical", "heterodyne", "number_theoretic"}
        Unwrapping method; see the module docstring for the widths each needs.
    min_amplitude : float, intensity units
        Absolute amplitude threshold for ``LOW_AMPLITUDE``.
    min_relative_amplitude : float, 1
        Amplitude threshold relative to the median amplitude of each width; the larger of
        the two thresholds applies.
    max_order_residual : float, 1
        Order residual above which a pixel gets ``ORDER_RESIDUAL``, in (0, 0.5].
    dtype : {float64, float32}, optional
        Dtype of the per-width maps (wrapped phase, amplitude, offset, modulation). Absolute
        phase, monitor coordinate and order residual are always float64.
    saturation_level : float, optional
        Grey value at which the camera saturates (e.g. ``2**bits - 1``): pixels with a frame
        at or above it get ``SATURATED``. None: no check.

    Returns
    -------
    DecodeResult
        Named fields; see :class:`DecodeResult`.

    Raises
    ------
    ValueError
        If shapes, ``shifts`` or thresholds are inconsistent, or the widths do not fit the
        method (the message names the argument and the fix).
    """
    arr = _check_frames(frames, "frames", 4, "(n_widths, K, H, W)")
    dt = _check_out_dtype(dtype)
    plan = _plan(widths, extent_px, method)
    extent = float(extent_px)
    a_min, rel, res = _check_thresholds(min_amplitude, min_relative_amplitude, max_order_residual)
    w = _check_widths(widths)
    n, n_shifts, height, width = arr.shape
    if n != w.size:
        raise ValueError(
            f"frames has {n} widths along axis 0 but widths has {w.size} entries ({w.tolist()})"
        )
    shifts = _check_shifts(shifts)
    if n_shifts != shifts:
        raise ValueError(
            f"shifts = {shifts} but frames has {n_shifts} phase-shifted frames along axis 1"
        )
    cos_d, sin_d = _shift_tables(n_shifts)
    wrapped = np.empty((n, height, width), dt)
    amplitude = np.empty((n, height, width), dt)
    offset = np.empty((n, height, width), dt)
    modulation = np.empty((n, height, width), dt)
    abs_phase = np.empty((height, width))
    coord = np.empty((height, width))
    residual = np.empty((height, width))
    flags = np.empty((height, width), np.uint8)
    if plan.method == "number_theoretic":
        _k.decode_coprime(arr, cos_d, sin_d, plan.order, plan.widths, plan.step_factor,
                          plan.step_inverse, plan.step_period, plan.unit, plan.window_lo,
                          extent, res, wrapped, amplitude, offset, modulation,
                          abs_phase, coord, residual, flags)
    else:
        _k.decode_chain(arr, cos_d, sin_d, plan.coef, plan.chain_w, plan.window_lo,
                        plan.rewrap_period, extent, res, wrapped, amplitude, offset, modulation,
                        abs_phase, coord, residual, flags)
    if a_min > 0 or rel > 0:
        _k.flag_low_amplitude(amplitude, _amplitude_thresholds(amplitude, a_min, rel), flags)
    if saturation_level is not None:
        sat = np.any(arr >= saturation_level, axis=(0, 1))
        flags[sat] |= np.uint8(DecodeFlag.SATURATED)
    return DecodeResult(
        absolute_phase=abs_phase,
        monitor_coord_px=coord,
        wrapped_phase=wrapped,
        modulation=modulation,
        amplitude=amplitude,
        offset=offset,
        order_residual=residual,
        flags=flags,
        valid=flags == 0,
        widths_px=tuple(float(x) for x in w),
        finest_width_px=plan.finest_width,
        method=plan.method,
    )


# --------------------------------------------------------------------------- coordinates


def phase_to_monitor_px(absolute_phase, width_px: float) -> np.ndarray:
    """Monitor coordinate of an absolute phase: ``u = Phi w / (2 pi)``.

    Parameters
    ----------
    absolute_phase : (H, W) ndarray, rad
        Absolute phase ``Phi`` of fringe width ``width_px``.
    width_px : float, monitor px
        Fringe width (period).

    Returns
    -------
    coord : (H, W) ndarray of float64, monitor px
        0-based, monitor pixel centres at integers.
    """
    w = _check_positive(width_px, "width_px")
    return np.asarray(absolute_phase, dtype=np.float64) * (w / (2.0 * np.pi))


def monitor_px_to_mm(coord_px, pixel_pitch_mm: float) -> np.ndarray:
    """Monitor coordinate in mm from the centre of monitor pixel 0: ``x = u * pitch``.

    Parameters
    ----------
    coord_px : (H, W) ndarray, monitor px
        Monitor coordinate (0-based, centres at integers).
    pixel_pitch_mm : float, mm
        Monitor pixel pitch along this direction.

    Returns
    -------
    coord_mm : (H, W) ndarray of float64, mm
    """
    pitch = _check_positive(pixel_pitch_mm, "pixel_pitch_mm")
    return np.asarray(coord_px, dtype=np.float64) * pitch


# --------------------------------------------------------------------------- file input





