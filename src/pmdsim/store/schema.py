"""The run dataset: its schema (variables, units, descriptions), building it from the
rendered and measured arrays, and loading it back (:func:`load_run`)."""

from __future__ import annotations

import datetime as _dt
import json
import platform
from pathlib import Path

import numpy as np

from .. import patterns as pat
from ..config import RunConfig
from ..measure.chain import (QUANTITIES, STATISTICS, ChainResult, DOT_THRESHOLD_FRACTION,
                             direction_quantity_stats)
from ..render import FringeResult, Geometry
from .folder import MANIFEST


DATASET_NAME = "run.zarr"



CONFIG_NAME = "config.json"



def _version() -> str:
    from .._version import __version__

    return __version__



def complex_parts_float32(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(z.real, z.imag)`` as float32 arrays of ``z``'s shape; complex128 in one compiled
    pass (:func:`pmdsim.kernels.images.parts_float32`)."""
    z = np.asarray(z)
    if z.dtype != np.complex128:
        return z.real.astype(np.float32), z.imag.astype(np.float32)
    from ..kernels.images import parts_float32

    re, im = np.empty(z.shape, np.float32), np.empty(z.shape, np.float32)
    parts_float32(np.ascontiguousarray(z).reshape(-1), re.reshape(-1), im.reshape(-1))
    return re, im


def build_dataset(cfg: RunConfig, geometry: Geometry, fringes: FringeResult | None,
                  dots: list[pat.Dot], dot_images: np.ndarray | None,
                  image_files: list[str], images: np.ndarray | None, exposure: float,
                  rays_per_pixel: int):
    """The run's xarray Dataset (in memory): see the module docstring for its contents."""
    import xarray as xr

    from .lazy_arrays import xarray_without_dask_import

    xarray_without_dask_import()  # xarray would import dask.array for each variable

    h, w = geometry.surface_mask.shape
    estimator = cfg.sampling.estimator
    value_units = (
        "camera value: (1/N) sum_p f_p L_p, BRDF units (1/sr) x monitor luminance"
        if estimator == "paper" else
        "camera value: sum_p f_p L_p / sum_p f_p, monitor luminance units"
    )
    pix = {"row": ("row", np.arange(h)), "col": ("col", np.arange(w))}
    ds = xr.Dataset(coords=pix)
    ds["row"].attrs = {"units": "camera px", "description": "camera pixel row (0-based, centre)"}
    ds["col"].attrs = {"units": "camera px", "description": "camera pixel column (0-based, centre)"}
    ds["surface_mask"] = (("row", "col"), geometry.surface_mask, {
        "description": "True where the vision ray hits the front of the surface"})
    ds["monitor_mask"] = (("row", "col"), geometry.monitor_mask, {
        "description": "True where the principal reflection P also hits the monitor"})
    ds["specular_u"] = (("row", "col"), geometry.specular_u, {
        "units": "monitor px", "description": "exact monitor column u hit by P (NaN: misses)"})
    ds["specular_v"] = (("row", "col"), geometry.specular_v, {
        "units": "monitor px", "description": "exact monitor row v hit by P (NaN: misses)"})
    if fringes is not None:
        ds = ds.assign_coords(
            direction=("direction", np.array(fringes.directions, dtype=object)),
            width=("width", np.asarray(fringes.widths, np.float64)),
            shift=("shift", np.asarray(fringes.shifts, np.float64)),
        )
        ds["direction"].attrs = {"description": "x: phase along monitor columns u (vertical "
                                 "fringe lines); y: along rows v"}
        ds["width"].attrs = {"units": "monitor px", "description": "fringe width = period"}
        ds["shift"].attrs = {"units": "rad", "description": "phase shift delta_k = 2 pi k / K; "
                             "pattern 0.5 + 0.5 cos(2 pi c / width + delta_k)"}
        ds["fringes"] = (("direction", "width", "shift", "row", "col"), fringes.images, {
            "units": value_units, "description": "camera fringe images; NaN: no surface"})
        ds["f_total"] = (("row", "col"), fringes.f_total, {
            "description": "normalised sum of the BRDF weights of all rays of the bundle"})
        ds["f_hit"] = (("row", "col"), fringes.f_hit, {
            "description": "normalised sum of the weights of the rays that hit the monitor"})
        if fringes.sums is not None:
            desc = ("normalised sum_p f_p exp(i 2 pi c_p / width), c = u (x) or v (y) in "
                    "monitor px; arg = decoded phase, |.|/f_hit = modulation (gamma 1)")
            # float32 (as stored): half the memory of float64 copies (240 MB at 5 MP)
            re, im = complex_parts_float32(fringes.sums)
            ds["fringe_sums_real"] = (("direction", "width", "row", "col"), re,
                                      {"description": "real part of " + desc})
            ds["fringe_sums_imag"] = (("direction", "width", "row", "col"), im,
                                      {"description": "imaginary part of " + desc})
    if dot_images is not None:
        ds = ds.assign_coords(
            dot_u=("dot", np.array([d.u for d in dots])),
            dot_v=("dot", np.array([d.v for d in dots])),
            dot_size=("dot", np.array([d.size for d in dots])),
        )
        ds["dot_u"].attrs = {"units": "monitor px", "description": "dot centre column"}
        ds["dot_v"].attrs = {"units": "monitor px", "description": "dot centre row"}
        ds["dot_size"].attrs = {"units": "monitor px", "description": "dot side length"}
        ds["dots"] = (("dot", "row", "col"), dot_images, {
            "units": value_units, "description": "camera images of white square dots on black"})
    if images is not None:
        ds = ds.assign_coords(image_file=("image", np.array(image_files, dtype=object)))
        ds["images"] = (("image", "row", "col"), images, {
            "units": value_units, "description": "camera images of the monitor images"})
    ds["exposure"] = ((), float(exposure), {
        "units": "image integer per camera value",
        "description": "image file pixel = round(clip(value * exposure, 0, 2**bit_depth - 1))"})
    ds.attrs = {
        "title": f"pmdsim run {cfg.name}",
        "pmdsim_version": _version(),
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "config_json": cfg.model_dump_json(),
        "estimator": estimator,
        "rays_per_pixel": int(rays_per_pixel),
        "exposure": float(exposure),
        "bit_depth": int(cfg.output.bit_depth),
        "image_format": cfg.output.image_format,
        "conventions": "pmdsim docs/conventions.md: lengths mm, angles rad, monitor and "
                       "camera pixel centres at integers, images (frames, height, width)",
        "python": platform.python_version(),
        "numpy": np.__version__,
    }
    return ds


def dataset_path(path: str | Path, variant: str | None = None) -> Path:
    """Where :func:`load_run` looks: ``path`` (a run folder or its ``run.zarr``), its
    ``variant`` subfolder if given, and its ``run.zarr`` where that exists."""
    path = Path(path)
    if variant is not None:
        path = path / variant
    return path / DATASET_NAME if (path / DATASET_NAME).is_dir() else path


def load_run(path: str | Path, variant: str | None = None, *, dask: bool = True):
    """Open the dataset of a run (lazily, Dask-backed; with ``dask=False`` each variable
    is read with NumPy once, on first use, and kept: what a figure needs).

    ``path`` is a run folder or its ``run.zarr``. For a run with variants, ``variant``
    selects one (the same as opening ``<path>/<variant>``); without it the variants are
    concatenated along a new leading ``variant`` dimension and ``attrs["config_json"]`` is
    the whole configuration (variants included).

    ``RunConfig.model_validate_json(ds.attrs["config_json"])`` gives the configuration that
    reproduces the dataset (:func:`run_config`).
    """
    path = dataset_path(path, variant)
    if path.name == DATASET_NAME or (path / "zarr.json").is_file():
        if not path.is_dir():
            raise FileNotFoundError(f"no pmdsim run dataset at {path}")
        import xarray as xr

        if not dask:
            return xr.open_dataset(path, engine="zarr", chunks=None, cache=True,
                                   consolidated=False)
        return xr.open_zarr(path, consolidated=False)
    manifest = path / MANIFEST
    if not manifest.is_file():
        raise FileNotFoundError(f"no pmdsim run at {path} (no {DATASET_NAME}, no {MANIFEST})")
    names = json.loads(manifest.read_text()).get("variants", [])
    if not names:
        raise FileNotFoundError(f"no pmdsim run dataset in {path}")
    import xarray as xr

    parts = [load_run(path / n, dask=dask) for n in names]
    # The geometry and the specular reference are the same for every variant.
    shared = {"surface_mask", "monitor_mask", "specular_u", "specular_v", "surface_to_monitor_mm"}
    shared |= {v for v in parts[0].data_vars if str(v).startswith("reference_")}
    # A variable some variants lack (the diagnostics of a mirror variant) is NaN for them.
    templates: dict = {}
    for p in parts:
        for v in p.data_vars:
            templates.setdefault(v, p[v])
    parts = [p.assign({v: xr.full_like(t, np.nan, dtype=np.float64)
                       for v, t in templates.items() if v not in p.data_vars}) for p in parts]
    per_variant = [v for v in templates if v not in shared]
    ds = xr.concat(parts, dim=xr.DataArray(np.array(names, dtype=object), dims="variant",
                                           name="variant"),
                   data_vars=per_variant,
                   coords="minimal", compat="override", combine_attrs="drop_conflicts",
                   join="exact")
    ds.attrs["config_json"] = (path / CONFIG_NAME).read_text()
    return ds



def run_config(ds) -> RunConfig:
    """The resolved configuration stored with a run dataset."""
    return RunConfig.model_validate_json(ds.attrs["config_json"])


def dataset_variables(chain: ChainResult) -> dict:
    """xarray variables ``{name: (dims, data, attrs)}`` of a chain (to assign to a run
    dataset with ``direction``, ``width``, ``row``, ``col`` coordinates)."""
    dirs = list(chain.directions)
    dcs = [chain.directions[d] for d in dirs]
    pitch = chain.pitch_mm

    from .lazy_arrays import lazy_stack

    def per(fn, dtype=None, scale=None):
        # stacked lazily over the chain's own arrays (no Dask): no second copy of the
        # chain in memory (1.2 GB at 5 MP); read when written or drawn
        return lazy_stack([fn(dc) for dc in dcs], dtype, scale)

    D, DW = ("direction", "row", "col"), ("direction", "width", "row", "col")
    v = {}
    for prefix, get in (("", lambda dc: dc.decoded), ("reference_", lambda dc: dc.reference)):
        who = "surface" if not prefix else "ideal specular reference (mirror BRDF)"
        v[prefix + "wrapped_phase"] = (DW, per(lambda dc: get(dc).wrapped_phase, np.float32), {
            "units": "rad", "description": f"wrapped phase of each width, (-pi, pi], {who}"})
        v[prefix + "absolute_phase"] = (D, per(lambda dc: get(dc).absolute_phase), {
            "units": "rad", "description": f"absolute phase of the finest width, {who}"})
        v[prefix + "modulation"] = (DW, per(lambda dc: get(dc).modulation, np.float32), {
            "units": "1", "description": f"fringe modulation B/A of each width, {who}"})
        v[prefix + "decode_flags"] = (D, per(lambda dc: get(dc).flags, np.uint8), {
            "description": f"decode reliability flags, {who}: 1 NAN_INPUT, 2 LOW_AMPLITUDE, "
                           "4 ORDER_RESIDUAL, 8 OUT_OF_RANGE, 16 SATURATED; 0 = valid"})
        v[prefix + "order_residual"] = (D, per(lambda dc: get(dc).order_residual, np.float32), {
            "units": "1", "description": f"largest fringe-order residual of the unwrapping, {who}"})
        v[prefix + "monitor_coord_px"] = (D, per(lambda dc: get(dc).monitor_coord_px), {
            "units": "monitor px", "description": f"decoded monitor coordinate (u for x, v for "
                                                  f"y; 0-based, centres at integers), {who}"})
        v[prefix + "monitor_coord_mm"] = (D, per(lambda dc: get(dc).monitor_coord_px, scale=pitch), {
            "units": "mm", "description": f"decoded monitor coordinate from the centre of "
                                          f"monitor pixel 0 (coord_px x pitch), {who}"})
    v["phase_deviation"] = (D, per(lambda dc: dc.deviation.phase), {
        "units": "rad", "description": "absolute phase (finest width) minus the reference's; "
                                       "NaN where not valid"})
    v["coord_deviation_px"] = (D, per(lambda dc: dc.deviation.coord_px), {
        "units": "monitor px", "description": "decoded monitor coordinate minus the reference's"})
    v["coord_deviation_mm"] = (D, per(lambda dc: dc.deviation.coord_mm), {
        "units": "mm", "description": "coord_deviation_px x monitor pixel pitch"})
    v["slope_deviation_urad"] = (D, per(lambda dc: dc.slope_urad), {
        "units": "urad", "description": "slope deviation: tilt of the bisector normal that moves "
                                        "the exact specular monitor point by the coordinate "
                                        "deviation (full 3-D geometry; not coord / (2 d), which "
                                        "is cos(theta_i) short across the plane of incidence)"})
    v["modulation_ratio"] = (DW, per(lambda dc: dc.deviation.modulation_ratio, np.float32), {
        "units": "1", "description": "modulation / reference modulation, per width"})
    v["valid"] = (D, per(lambda dc: dc.deviation.valid), {
        "description": "True where surface and reference decode without flags and the "
                       "modulation ratio reaches min_modulation_ratio: the deviation pixels"})
    v["low_modulation"] = (D, per(lambda dc: dc.deviation.low_modulation), {
        "description": "True where the reference is valid but the modulation ratio of some "
                       "width is below min_modulation_ratio (masked and counted)"})
    v["surface_to_monitor_mm"] = (("row", "col"), chain.distance_mm, {
        "units": "mm", "description": "distance from the surface point to the monitor point of "
                                      "the principal reflection P"})
    if all(dc.numerical is not None for dc in dcs):
        for q, name, units in (("phase_mrad", "phase_deviation_error", "rad"),
                               ("coord_px", "coord_deviation_px_error", "monitor px"),
                               ("coord_mm", "coord_deviation_mm_error", "mm"),
                               ("slope_urad", "slope_deviation_urad_error", "urad")):
            scale = 1e-3 if q == "phase_mrad" else None
            v[name] = (D, per(lambda dc, q=q: dc.numerical[q], np.float32, scale), {
                "units": units, "description": f"numerical (quadrature) error of "
                f"{name[:-6]}: the render's stated error of the finest width's sums, "
                "propagated (pmdsim.measure.numerical); NaN where not valid"})
    qs = list(QUANTITIES)
    table = np.array([[[float("nan") if (x := direction_quantity_stats(dc)[q][s]) is None
                        else x for s in STATISTICS] for q in qs] for dc in dcs])
    v["deviation_stats"] = (("direction", "quantity", "statistic"), table, {
        "description": "deviation statistics over the valid pixels; units per quantity: "
                       + ", ".join(f"{q}: {u}" for q, u in QUANTITIES.items())})
    return v



def assign_to_dataset(ds, chain: ChainResult, stats: dict):
    """Return ``ds`` with the chain's variables, coordinates ``quantity``/``statistic`` and
    attrs ``decode_method``, ``statistics_json``."""
    import json

    ds = ds.assign_coords(quantity=("quantity", np.array(list(QUANTITIES), dtype=object)),
                          statistic=("statistic", np.array(STATISTICS, dtype=object)))
    ds = ds.assign(dataset_variables(chain))  # one merge, not one per variable
    ds.attrs["decode_method"] = chain.method
    ds.attrs["min_modulation_ratio"] = chain.min_modulation_ratio
    ds.attrs["statistics_json"] = json.dumps(stats)
    return ds



def dot_dataset_variables(table: list[dict]) -> dict:
    """xarray variables ``{name: (dims, data, attrs)}`` along ``dot`` from :func:`dot_table`."""
    def col(k):
        return np.array([r[k] for r in table], np.float64)

    thr = f"moments above {DOT_THRESHOLD_FRACTION:g} x the dot image's maximum"
    return {
        "dot_centroid_col": (("dot",), col("centroid_col"), {
            "units": "camera px", "description": f"dot image centroid column ({thr})"}),
        "dot_centroid_row": (("dot",), col("centroid_row"), {
            "units": "camera px", "description": f"dot image centroid row ({thr})"}),
        "dot_sigma_major": (("dot",), col("sigma_major_px"), {
            "units": "camera px", "description": f"standard deviation along the major axis ({thr})"}),
        "dot_sigma_minor": (("dot",), col("sigma_minor_px"), {
            "units": "camera px", "description": f"standard deviation along the minor axis ({thr})"}),
        "dot_elongation": (("dot",), col("elongation"), {
            "units": "1", "description": "sigma_major / sigma_minor"}),
        "dot_angle": (("dot",), col("angle_deg"), {
            "units": "deg", "description": "major axis angle from +col towards +row, (-90, 90]"}),
        "dot_peak": (("dot",), col("peak"), {"description": "maximum camera value of the dot image"}),
        **{f"dot_{name}_error": (("dot",), col(key), {
            "units": units, "description": f"numerical error of dot_{name} (first-order bound "
            "from the rendered images' error; NaN without one, e.g. after a sensor)"})
           for name, key, units in (("centroid_col", "centroid_col_err", "camera px"),
                                    ("centroid_row", "centroid_row_err", "camera px"),
                                    ("sigma_major", "sigma_major_px_err", "camera px"),
                                    ("sigma_minor", "sigma_minor_px_err", "camera px"),
                                    ("elongation", "elongation_err", "1"),
                                    ("angle", "angle_deg_err", "deg"))},
    }