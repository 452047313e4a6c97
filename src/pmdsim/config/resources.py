"""Memory and CPU time of a run, estimated from its configuration alone, and the check
that refuses a run which cannot fit this machine before anything is allocated."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from .base import ConfigError
from .brdf import MirrorConfig
from .monitor import GAMMA_HARMONICS
from .run import RunConfig

# ----------------------------------------------------------------------------- resources
#: Scattered rays per CPU-second of a whole run (geometry, rendering, decoding, diagnostics,
#: writing and figures), counted as :func:`estimate_resources` counts them. Measured
#: 2026-12-02 on the 2-core machine, Fig. 3 (1.3 MP) with 16, 100 and 256 rays per pixel:
#: 2.1e6, 1.1e7 and 2.4e7 (19.5, 23.0 and 26.4 CPU-s): at few rays per pixel the per-pixel
#: work (decoding, reconstruction, writing, figures), not the rays, sets the time, so a
#: rate near the low end keeps the estimate from falling far short (0.7 x the CPU time at
#: 16 rays, 3.5 x at 100, 8 x at 256; the kernels alone trace 1e8 per CPU-second,
#: ``benchmarks/bench_render.py``).
RAYS_PER_CPU_SECOND = 3.0e6
#: Resident memory of the interpreter with NumPy, Numba, xarray and Dask loaded.
BASE_MEMORY_BYTES = 400 * 2**20
#: Grid pixels of the diagnostics' ray transport keep every ray: float64 u, v, weight,
#: a 3-vector direction and scratch, per ray.
_TRANSPORT_BYTES_PER_RAY = 64


@dataclass(frozen=True)
class ResourceEstimate:
    """The memory and CPU time a run of a configuration needs, estimated from the
    configuration alone (before anything is allocated).

    ``memory_bytes`` is the peak working set (the largest step, plus what stays resident);
    ``parts`` names each contribution in bytes by the setting that drives it (the field to
    change); ``rays`` counts the scattered rays of all render passes (every camera pixel
    counted, an upper bound) and ``cpu_seconds`` their time at ``RAYS_PER_CPU_SECOND``.
    """

    memory_bytes: int
    rays: float
    cpu_seconds: float
    parts: dict

    def seconds(self, cores: int | None = None) -> float:
        """Wall time on ``cores`` cores (default: this machine's)."""
        return self.cpu_seconds / max(1, cores or os.cpu_count() or 1)

    def describe(self) -> str:
        return (f"about {_human_bytes(self.memory_bytes)} of memory and "
                f"{_human_seconds(self.cpu_seconds)} of CPU time "
                f"({self.rays:.3g} scattered rays)")


def _human_bytes(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if abs(n) < 1024 or unit == "TB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.3g} TB"  # pragma: no cover


def _human_seconds(s: float) -> str:
    if s < 120:
        return f"{s:.2g} s"
    if s < 7200:
        return f"{s / 60:.3g} min"
    return f"{s / 3600:.3g} h"


def _member_estimate(cfg: "RunConfig", n_px: float, width: int) -> tuple[dict, float]:
    """(memory parts in bytes, scattered rays) of one configuration without variants."""
    mirror = isinstance(cfg.brdf, MirrorConfig)
    rpp = 1 if mirror else rays_per_bundle(cfg.sampling, cfg.monitor.pixel_model)
    mon_w, mon_h = cfg.monitor.resolution
    render: dict[str, float] = {}
    after: dict[str, float] = {}
    passes = 0
    fr = cfg.patterns.fringes
    workers = cfg.compute.num_workers or os.cpu_count() or 1
    tile_px = min(cfg.compute.tile_rows, cfg.camera.rendered_resolution[1]) * width
    tiles = 0.0
    if fr is not None:
        nd, nw, k = len(fr.directions), len(fr.widths_px), fr.shifts
        linear = cfg.monitor.gamma == 1.0
        if cfg.monitor.pixel_model == "continuous":
            ncols = 2 + 2 * nd * nw * (1 if linear else GAMMA_HARMONICS)
        else:
            ncols = 2 + nd * nw * (2 if linear else k)
        # the tiles' float64 outputs and their concatenation, the float32 images, the
        # complex sums; then the decoded maps (phases, coordinates, modulation, flags)
        render["patterns.fringes"] = n_px * (16 * ncols + 4 * nd * nw * k + 16 * nd * nw)
        after["patterns.fringes"] = n_px * (8 * nd * nw * k + 16 * nd * nw + 48 * nd * nw + 96 * nd)
        tiles = max(tiles, tile_px * ncols * 8 * workers)
        passes += 1
    dots = cfg.patterns.dots
    if dots is not None:
        q = len(dots.positions_px) + (dots.grid[0] * dots.grid[1] if dots.grid else 0)
        render["patterns.dots"] = n_px * (16 * (2 + q) + 4 * q)
        after["patterns.dots"] = n_px * 8 * q
        tiles = max(tiles, tile_px * (2 + q) * 8 * workers)
        passes += 1
    images = cfg.patterns.images
    if images is not None:
        q = len(images.files)
        levels = q * mon_w * mon_h * 8
        render["patterns.images"] = n_px * (16 * (2 + q) + 4 * q) + levels
        after["patterns.images"] = n_px * 8 * q + levels
        tiles = max(tiles, tile_px * (2 + q) * 8 * workers)
        passes += 1
    parts = {k: max(render.get(k, 0.0), after.get(k, 0.0)) for k in set(render) | set(after)}
    if tiles:
        parts["compute.tile_rows"] = tiles
    if not mirror:
        # per-thread ray buffers of the kernels, and the diagnostics' ray transport
        gx, gy = cfg.diagnostics.grid
        parts["sampling.n_rays"] = rpp * (48 * workers + _TRANSPORT_BYTES_PER_RAY * gx * gy)
    return parts, n_px * rpp * passes


#: Rays of a Gauss rule plus its two embedded rules (about 3/4 and 1/2 of the order in
#: each of two dimensions: ~0.56 + 0.25 more nodes), rounded up: the error-estimating
#: passes of mode "rule" where the integrand is not smooth.
RULE_WITH_EMBEDDED = 1.85
#: Mode "rule" on a continuous monitor: the rule once, and its pilot (a rule 4 x finer on
#: 1/64 of the pixels, the local pilots where a lobe leaves the monitor), rounded up.
RULE_WITH_PILOT = 1.15
#: The rule a target is expected to pick, per node it starts from, for the estimate (the
#: pilot picks it; Fig. 3's 0.1 mrad: 64-128 nodes from 16), and at least this many nodes.
TARGET_TYPICAL_NODES = 256


def rays_per_bundle(sampling, pixel_model: str = "continuous") -> float:
    """Rays per vision ray over all the sample sets of one render: ``n_rays`` (with
    ``target_error_mrad``: :data:`TARGET_TYPICAL_NODES`, at least ``n_rays`` and at most
    ``max_rays``, and the doubling renders of a target on a nearest-pixel monitor); mode
    ``rule`` with its error estimate adds its pilot on a smooth (continuous-monitor)
    integrand and the embedded rules elsewhere (its ``rqmc`` replicates share n_rays)."""
    n = float(sampling.n_rays)
    if sampling.target_error_mrad is not None:
        n = float(min(sampling.max_rays, max(sampling.n_rays, TARGET_TYPICAL_NODES)))
        if pixel_model != "continuous":
            n *= 2.0  # the doubling full renders (1 + 1/2 + 1/4 ...)
    if sampling.mode == "rule" and sampling.error_estimate:
        return (RULE_WITH_PILOT if pixel_model == "continuous" else RULE_WITH_EMBEDDED) * n
    return n


def estimate_resources(cfg: "RunConfig") -> ResourceEstimate:
    """Estimate the peak memory and the CPU time of running ``cfg`` (see
    :class:`ResourceEstimate`); pure arithmetic on the configuration."""
    # the rendered pixels: the camera's region of interest (camera.roi), else the sensor
    width, height = cfg.camera.rendered_resolution
    n_px = float(width) * float(height)
    cam = cfg.camera
    # vision rays per pixel (sub-pixels x thin-lens aperture samples): every one carries a
    # bundle of scattered rays
    vision = cam.vision_rays_per_pixel
    # the vision-ray geometry of the whole camera (25 float64 per vision ray and the
    # specular monitor coordinates), the masks and the dataset's copies of the maps
    parts = {"camera.resolution": n_px * (25 * 8 + 16 + 64)}
    if vision > 1:  # the extra vision rays, named by the factor that makes most of them
        parts[_vision_field(cam)] = n_px * 25 * 8 * (vision - 1)
    rays = 0.0
    member_parts = []
    for _, member in cfg.expand():
        p, r = _member_estimate(member, n_px, width)
        member_parts.append(p)
        rays += r * vision
    # the members run one after the other: the largest counts
    biggest = max(member_parts, key=lambda p: sum(p.values()))
    for k, v in biggest.items():
        parts[k] = parts.get(k, 0.0) + v
    if cfg.patterns.fringes is not None and cfg.decode.enabled is not False:
        # the ideal specular reference: rendered (one ray per pixel) and kept decoded
        fr = cfg.patterns.fringes
        nd, nw = len(fr.directions), len(fr.widths_px)
        parts["patterns.fringes"] = parts.get("patterns.fringes", 0.0) + n_px * (48 * nd * nw + 96 * nd)
        rays += n_px * vision
    nodes = reconstruction_nodes(cfg)
    if nodes:
        parts["reconstruct.spacing_mm"] = nodes * RECONSTRUCTION_BYTES_PER_NODE
    memory = BASE_MEMORY_BYTES + sum(parts.values())
    return ResourceEstimate(int(memory), rays, rays / RAYS_PER_CPU_SECOND,
                            {k: int(v) for k, v in parts.items()})


def _vision_field(cam) -> str:
    """The camera setting that multiplies the vision rays per pixel most."""
    lens = cam.aperture_samples if cam.has_aperture else 1
    return "camera.aperture_samples" if lens >= cam.subpixels ** 2 else "camera.subpixels"


#: Working memory per node of the reconstruction grid (measured on the base scene: 432 B of
#: NumPy arrays per node at its peak (tracemalloc), plus the sparse LU factor of the
#: integration, 48-75 non-zeros of 12 B per node for 3e4-5e5 nodes): the coordinates, nominal and
#: reconstructed heights, slopes and masks (~20 float64) and the sparse least-squares system
#: (two slope equations per node with up to 5 neighbours, its normal matrix and the solver's
#: factor), rounded up.
RECONSTRUCTION_BYTES_PER_NODE = 2048


def _aperture_box(surface) -> tuple[float, float] | None:
    """(width, height) mm of the bounding box of a surface's measured area, or None."""
    ap = getattr(surface, "aperture", None)
    if ap is not None:
        if ap.shape == "rectangular":
            return float(ap.size_mm[0]), float(ap.size_mm[1])
        return 2.0 * ap.radius_mm, 2.0 * ap.radius_mm
    size = getattr(surface, "size_mm", None)
    if size is not None:
        return float(size[0]), float(size[1])
    return None  # a height map without aperture: its grid (not known without the file)


def reconstruction_nodes(cfg: "RunConfig") -> float:
    """Nodes of the reconstruction grid of a run (0 when it does not reconstruct): the
    prior's aperture box at ``reconstruct.spacing_mm``."""
    rc, fr = cfg.reconstruct, cfg.patterns.fringes
    if (rc.enabled is False or fr is None or cfg.decode.enabled is False
            or not {"x", "y"} <= set(fr.directions) or len(fr.widths_px) < 2):
        # (one width cannot be unwrapped: the run does not decode, so no reconstruction)
        return 0.0
    box = _aperture_box(rc.prior if rc.prior is not None else cfg.surface)
    if box is None:
        return 0.0
    s = rc.spacing_mm
    return (math.floor(box[0] / s) + 1.0) * (math.floor(box[1] / s) + 1.0)


def available_memory_bytes() -> int | None:
    """Memory this process may still use: ``MemAvailable`` of ``/proc/meminfo`` (Linux),
    else the physical memory; None when unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


_FIX = {
    "camera.resolution": "a smaller camera.resolution or a window camera.roi (\"auto\": the "
                         "pixels that see the part) (or fewer patterns: "
                         "patterns.fringes.widths_px/shifts/directions, dots, images)",
    "patterns.fringes": "fewer fringe images (patterns.fringes.widths_px, .shifts, .directions)",
    "patterns.dots": "fewer dots (patterns.dots.positions_px / grid) per run",
    "patterns.images": "fewer monitor images (patterns.images.files) per run",
    "compute.tile_rows": "a smaller compute.tile_rows or compute.num_workers",
    "sampling.n_rays": "fewer sampling.n_rays (or a coarser diagnostics.grid)",
    "camera.aperture_samples": "fewer camera.aperture_samples (thin-lens samples per sub-pixel)",
    "camera.subpixels": "fewer camera.subpixels",
    "reconstruct.spacing_mm": "a coarser reconstruct.spacing_mm (or a smaller aperture; or "
                              "reconstruct.enabled = false)",
}


def check_resources(cfg: "RunConfig", available_bytes: int | None = None,
                    *, max_cpu_hours: float | None = None) -> ResourceEstimate:
    """Stop a run that cannot fit this machine before anything is allocated.

    Raises :class:`ConfigError` naming the setting that drives the memory (the largest part
    of :func:`estimate_resources`) when the estimate exceeds ``available_bytes`` (default:
    :func:`available_memory_bytes`), or the one that drives the time when the CPU time
    exceeds ``max_cpu_hours`` (default ``compute.max_cpu_hours``). Returns the estimate.
    """
    est = estimate_resources(cfg)
    avail = available_memory_bytes() if available_bytes is None else available_bytes
    if avail is not None and est.memory_bytes > avail:
        field, part = max(est.parts.items(), key=lambda kv: kv[1])
        width, height = cfg.camera.rendered_resolution
        if field.startswith("patterns.") and width * height > 4096 * 4096:
            # the images of an enormous camera, not too many patterns
            field = "camera.resolution"
        raise ConfigError(
            f"invalid configuration:\n  {field}: this run needs {est.describe()}, but this "
            f"machine has {_human_bytes(avail)} of memory available ({field} alone takes "
            f"{_human_bytes(part)}); use {_FIX[field]}, or split the run (variants, "
            f"separate runs) or run it on a machine/cluster with more memory "
            f"(compute.scheduler = \"distributed\")")
    limit = cfg.compute.max_cpu_hours if max_cpu_hours is None else max_cpu_hours
    if est.cpu_seconds > limit * 3600:
        cam = cfg.camera
        vision = cam.vision_rays_per_pixel
        field = ("sampling.n_rays" if cfg.sampling.n_rays > 1 and cfg.sampling.n_rays >= vision
                 else _vision_field(cam) if vision > 1 else "camera.resolution")
        raise ConfigError(
            f"invalid configuration:\n  {field}: this run needs {est.describe()}, more than "
            f"compute.max_cpu_hours = {limit:g}; use fewer {field} or raise "
            f"compute.max_cpu_hours if you mean it (or run on a cluster: "
            f"compute.scheduler = \"distributed\")")
    return est


# ----------------------------------------------------------------------------- studies
#: Points of one sweep: planning validates every point before anything runs (about a
#: millisecond each), and the store holds one chunk per point and variable.
MAX_SWEEP_POINTS = 100_000


def sweep_point_count(sweep) -> int:
    """Points of a :class:`~pmdsim.config.SweepConfig` (grid: the product of the lists)."""
    if sweep.design == "random":
        return int(sweep.points)
    lengths = [len(v) for v in sweep.parameters.values()]
    return int(math.prod(lengths)) if sweep.design == "grid" else max(lengths)


def check_sweep_size(cfg: "RunConfig") -> int:
    """Refuse a sweep of more than :data:`MAX_SWEEP_POINTS` points before its points are
    planned (naming ``sweep.parameters``); returns the count."""
    n = sweep_point_count(cfg.sweep)
    if n > MAX_SWEEP_POINTS:
        sizes = " x ".join(str(len(v)) for v in cfg.sweep.parameters.values())
        raise ConfigError(
            f"invalid configuration:\n  sweep.parameters: the {cfg.sweep.design} design has "
            f"{n:,} points ({sizes}), more than {MAX_SWEEP_POINTS:,}; sweep fewer values (or "
            "design = 'random' with fewer points), or split the study into several sweeps")
    return n


@dataclass(frozen=True)
class StudyEstimate:
    """Memory and time of a study of many runs: ``largest`` (the largest single run's
    :class:`ResourceEstimate`, index ``largest_index``), ``memory_bytes`` (the peak with
    ``concurrent`` runs at once) and ``cpu_seconds`` (all runs together)."""

    largest: ResourceEstimate
    largest_index: int
    concurrent: int
    memory_bytes: int
    cpu_seconds: float

    def describe(self) -> str:
        return (f"about {_human_bytes(self.memory_bytes)} of memory ({self.concurrent} at once) "
                f"and {_human_seconds(self.cpu_seconds)} of CPU time")


def estimate_study(configs, concurrent: int = 1) -> StudyEstimate:
    """Memory and CPU time of running every configuration of ``configs`` (e.g. a sweep's
    points), ``concurrent`` of them at once (each a full run: :func:`estimate_resources`)."""
    ests = [estimate_resources(c) for c in configs]
    k = max(range(len(ests)), key=lambda i: ests[i].memory_bytes)
    n = max(1, min(int(concurrent), len(ests)))
    peak = BASE_MEMORY_BYTES + n * (ests[k].memory_bytes - BASE_MEMORY_BYTES)
    return StudyEstimate(ests[k], k, n, int(peak), float(sum(e.cpu_seconds for e in ests)))


def check_study(configs, what: str, *, concurrent: int = 1, labels=None,
                available_bytes: int | None = None,
                max_cpu_hours: float | None = None) -> StudyEstimate:
    """Refuse a study (``what``: e.g. ``"sweep.parameters"``) whose largest run does not
    fit the memory with ``concurrent`` runs at once, or whose runs together exceed
    ``compute.max_cpu_hours`` (of the first configuration); the message names the study,
    the run (``labels[i]``) and the setting that drives it. Returns the estimate."""
    configs = list(configs)
    est = estimate_study(configs, concurrent)
    label = labels[est.largest_index] if labels else f"run {est.largest_index}"
    avail = available_memory_bytes() if available_bytes is None else available_bytes
    if avail is not None and est.memory_bytes > avail:
        field, part = max(est.largest.parts.items(), key=lambda kv: kv[1])
        raise ConfigError(
            f"invalid configuration:\n  {what}: {label} needs {est.largest.describe()}; with "
            f"{est.concurrent} at once that is {_human_bytes(est.memory_bytes)}, but this "
            f"machine has {_human_bytes(avail)} available ({field} alone takes "
            f"{_human_bytes(part)}); use {_FIX.get(field, 'smaller settings')} at that point"
            + (" or fewer workers (--workers)" if est.concurrent > 1 else ""))
    limit = configs[0].compute.max_cpu_hours if max_cpu_hours is None else max_cpu_hours
    if est.cpu_seconds > limit * 3600:
        raise ConfigError(
            f"invalid configuration:\n  {what}: its {len(configs)} runs need "
            f"{_human_seconds(est.cpu_seconds)} of CPU time together, more than "
            f"compute.max_cpu_hours = {limit:g} (the largest, {label}: "
            f"{est.largest.describe()}); use fewer points or cheaper settings, or raise "
            "compute.max_cpu_hours if you mean it")
    return est


def convergence_configs(cfg: "RunConfig", n_values, theta_values, estimators,
                        camera_size: tuple[int, int]) -> list:
    """The runs of a convergence study (``pmdsim converge``) as configurations for
    :func:`check_study`: the reduced camera, every estimator x N (x theta_max for the cone
    estimators), plus the configured N and theta_max and the converged reference (the
    largest N, radiometric)."""
    cam = cfg.camera.model_copy(update={"resolution": tuple(int(v) for v in camera_size)})
    ns = sorted({int(n) for n in n_values} | {int(cfg.sampling.n_rays)})
    thetas = sorted({float(t) for t in theta_values} | {float(cfg.sampling.theta_max_deg)})
    out = []
    for est in estimators:
        for n in ns:
            for t in (thetas if est != "radiometric" else thetas[:1]):
                samp = cfg.sampling.model_copy(update={"n_rays": n, "theta_max_deg": t,
                                                       "estimator": est})
                out.append(cfg.model_copy(update={"camera": cam, "sampling": samp,
                                                  "variants": ()}))
    return out
