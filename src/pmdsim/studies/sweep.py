"""Parameter studies: the points of a ``[sweep]`` and the measurement chain of one point.

A sweep takes a run configuration as its base and a :class:`~pmdsim.config.SweepConfig`
naming configuration fields by dotted path (``brdf.alpha_y``,
``patterns.fringes.widths_px.0`` for the first element of a list) with their values.
:func:`plan_sweep` checks every path against the base configuration and validates the
configuration of every point *before anything runs* (a bad field name or value is a
:class:`~pmdsim.config.ConfigError` naming the path, the point and the fix).

Designs:

- ``grid``: every combination; one dimension per parameter, in the order given;
- ``zip``: the i-th values of every parameter together; one ``point`` dimension;
- ``random``: ``points`` draws seeded by ``[sweep] seed`` (uniform in ``[min, max]``,
  log-uniform with ``scale = "log"``, or uniform over a list of choices); one ``point``
  dimension.

Each point's random streams are keyed by (seed, point index): its ``sampling.seed`` is
``SeedSequence([sampling.seed, index])``'s first word (unless ``sampling.seed`` is itself
swept, or ``common_random_numbers = true``), and with an enabled ``[sensor]`` its
``sensor.seed`` likewise, so any point recomputes bit-identically on its own, on any
worker, in any order.

:func:`measure_point` runs the measurement chain of one point (render the fringes, decode
them and the ideal specular reference, compare) in memory, without writing a run folder,
and returns its statistics and decimated maps as plain arrays
(:data:`POINT_VARIABLES` says what each is). Writing them is :mod:`pmdsim.run.sweep`'s job.
"""

from __future__ import annotations

import copy
import json
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..measure.chain import QUANTITIES, STATISTICS, decode_problem
from ..config import ConfigError, RunConfig, SweepConfig, SweepRange, parse_config, physical_estimator
from ..config.resources import check_sweep_size
from ..measure.deviation import finite_median

#: Variables of a point: name -> (dimensions after the sweep's own, dtype, attributes).
#: ``width`` is the index into ``patterns.fringes.widths_px`` (as given), ``row``/``col``
#: the camera pixels of the decimated maps.
POINT_VARIABLES = {
    "deviation_stats": (("direction", "quantity", "statistic"), np.float64, {
        "description": "deviation statistics over the valid pixels of the finest width; "
                       "units per quantity: phase_mrad mrad, coord_px monitor px, coord_mm mm, "
                       "slope_urad urad (see pmdsim.measure.chain.statistics)"}),
    "modulation_median": (("direction", "width"), np.float64, {
        "units": "1", "description": "median fringe modulation B/A of the surface over its "
                                     "validly decoded pixels, per width"}),
    "modulation_ratio_median": (("direction", "width"), np.float64, {
        "units": "1", "description": "median modulation ratio surface / specular reference "
                                     "over the pixels the reference decodes, per width"}),
}
MAP_VARIABLES = {
    "phase_deviation": (("direction", "row", "col"), np.float32, {
        "units": "rad", "description": "absolute phase (finest width) minus the reference's; "
                                       "NaN where not valid; decimated"}),
    "slope_deviation_urad": (("direction", "row", "col"), np.float32, {
        "units": "urad", "description": "slope deviation coord_deviation_mm / (2 d); NaN where "
                                        "not valid; decimated"}),
    "modulation": (("direction", "width", "row", "col"), np.float32, {
        "units": "1", "description": "fringe modulation B/A of the surface per width; "
                                     "decimated"}),
}


# ----------------------------------------------------------------------------- plan
@dataclass(frozen=True)
class SweepPoint:
    """One point of a sweep.

    ``index``: flat index (C order over the sweep's dimensions; keys the random streams);
    ``position``: its index along each dimension of the store; ``values``: {path: value};
    ``config``: the point's full configuration (no ``sweep``, its own ``sampling.seed``).
    """

    index: int
    position: tuple[int, ...]
    values: dict
    config: RunConfig


@dataclass(frozen=True)
class SweepPlan:
    """Every point of a sweep and the layout of its store.

    ``dims``/``shape``: the sweep's dimensions (the parameter paths for a grid, ``("point",)``
    otherwise); ``coords``: {parameter path: (dims, values)}; ``directions``, ``widths``
    (count), ``map_rows``/``map_cols`` (camera pixels of the decimated maps; empty without
    maps).
    """

    base: RunConfig
    sweep: SweepConfig
    dims: tuple[str, ...]
    shape: tuple[int, ...]
    coords: dict
    points: tuple[SweepPoint, ...]
    directions: tuple[str, ...]
    n_widths: int
    map_rows: np.ndarray
    map_cols: np.ndarray

    @property
    def parameters(self) -> tuple[str, ...]:
        return tuple(self.sweep.parameters)

    def identity(self) -> str:
        """JSON of what determines the results (the base configuration without ``compute``
        and ``output``, and the sweep): a resumed sweep must have the same."""
        d = self.base.model_dump(mode="json", exclude={"compute", "output"})
        return json.dumps(d, sort_keys=True)


def _fields_at(node) -> str:
    if isinstance(node, dict):
        return "fields here: " + ", ".join(sorted(node))
    if isinstance(node, list):
        return f"a list of {len(node)}: give an index 0..{len(node) - 1}"
    return "a value, not a table"


def _resolve(base: dict, path: str):
    """(container, key) of ``path`` in the dumped base configuration; ConfigError when the
    path names no field."""
    parts = path.split(".")
    node, where = base, []
    for k, part in enumerate(parts):
        last = k == len(parts) - 1
        if isinstance(node, dict):
            if part not in node:
                at = ".".join(where) or "the top level"
                raise ConfigError(
                    f"sweep.parameters: {path!r} is not a configuration field ({part!r} is "
                    f"not a field of {at}; {_fields_at(node)})")
            key = part
        elif isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise ConfigError(
                    f"sweep.parameters: {path!r}: {'.'.join(where)} is {_fields_at(node)}")
            key = int(part)
        else:
            raise ConfigError(
                f"sweep.parameters: {path!r}: {'.'.join(where)} is a value, not a table")
        if last:
            return node, key
        nxt = node[key]
        if nxt is None:
            raise ConfigError(
                f"sweep.parameters: {path!r}: {'.'.join(where + [part])} is not set in the "
                f"base configuration; give it there (e.g. a [{'.'.join(where + [part])}] "
                "table) and sweep its fields")
        node = nxt
        where.append(part)
    raise AssertionError("unreachable")


def _draw(sweep: SweepConfig) -> dict:
    """The values of a random design: {path: list of ``points`` values}."""
    rng = np.random.default_rng(sweep.seed)
    out = {}
    for path, spec in sweep.parameters.items():
        if isinstance(spec, SweepRange):
            if spec.scale == "log":
                x = np.exp(rng.uniform(np.log(spec.min), np.log(spec.max), sweep.points))
            else:
                x = rng.uniform(spec.min, spec.max, sweep.points)
            out[path] = [float(v) for v in x]
        else:
            pick = rng.integers(0, len(spec), sweep.points)
            out[path] = [spec[i] for i in pick]
    return out


def _coordinate(values) -> np.ndarray:
    """Store coordinate of a parameter's values: numbers as numbers, anything else (lists,
    strings, booleans) as its JSON text."""
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        if all(isinstance(v, int) for v in values):
            return np.array(values, np.int64)
        return np.array(values, np.float64)
    return np.array([v if isinstance(v, str) else json.dumps(v) for v in values], dtype=str)


def point_seed(seed: int, index: int) -> int:
    """The ``sampling.seed`` of point ``index`` of a sweep whose base seed is ``seed``."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1, np.uint32)[0])


def plan_sweep(cfg: RunConfig, sweep: SweepConfig | None = None) -> SweepPlan:
    """Every point of the sweep of ``cfg`` (``cfg.sweep`` unless ``sweep`` is given),
    validated.

    Raises
    ------
    ConfigError
        No sweep; a path that names no configuration field; a point whose configuration is
        invalid (the message names the point, its values and the field); a point whose
        fringes cannot be decoded; points that differ in what the store's layout needs
        (fringe directions, number of widths, camera resolution with maps).
    """
    sweep = sweep or cfg.sweep
    if sweep is None:
        raise ConfigError("no [sweep] table in the configuration: add one naming the fields "
                          "to sweep (see docs/sweeps.md)")
    cfg = physical_estimator(cfg)  # the rendering integral unless the configuration names one
    base = cfg.model_copy(update={"sweep": sweep})
    check_sweep_size(base)  # before planning (validating) every point
    dump = cfg.model_dump(mode="json", exclude={"sweep"})
    for path in sweep.parameters:
        if path.split(".")[0] in ("sweep", "variants", "name", "compute", "output"):
            raise ConfigError(f"sweep.parameters: {path!r} cannot be swept (only what changes "
                              "the simulated measurement)")
        _resolve(dump, path)

    params = list(sweep.parameters)
    if sweep.design == "grid":
        lists = {p: list(sweep.parameters[p]) for p in params}
        dims = tuple(params)
        shape = tuple(len(lists[p]) for p in params)
        positions = list(np.ndindex(*shape))
        values = [{p: lists[p][i] for p, i in zip(params, pos)} for pos in positions]
        coords = {p: ((p,), _coordinate(lists[p])) for p in params}
    else:
        lists = ({p: list(sweep.parameters[p]) for p in params} if sweep.design == "zip"
                 else _draw(sweep))
        n = len(next(iter(lists.values())))
        dims, shape = ("point",), (n,)
        positions = [(i,) for i in range(n)]
        values = [{p: lists[p][i] for p in params} for i in range(n)]
        coords = {p: (("point",), _coordinate(lists[p])) for p in params}

    seed_swept = "sampling.seed" in sweep.parameters
    points = []
    for index, (pos, vals) in enumerate(zip(positions, values)):
        d = copy.deepcopy(dump)
        for path, v in vals.items():
            node, key = _resolve(d, path)
            node[key] = v
        if not seed_swept and not sweep.common_random_numbers:
            d["sampling"]["seed"] = point_seed(cfg.sampling.seed, index)
        if (d.get("sensor") or {}).get("enabled") and "sensor.seed" not in sweep.parameters \
                and not sweep.common_random_numbers:  # the camera noise: keyed the same way
            d["sensor"]["seed"] = point_seed(cfg.sensor.seed, index)
        shown = ", ".join(f"{p} = {v!r}" for p, v in vals.items())
        pc = parse_config(d, f"sweep point {index} ({shown})")
        points.append(SweepPoint(index, tuple(int(i) for i in pos), vals, pc))

    first = points[0].config
    for p in points:
        c = p.config
        if c.variants:
            raise ConfigError("a sweep runs one configuration per point: remove [[variants]] "
                              "(sweep brdf/anisotropy/sampling fields instead)")
        problem = decode_problem(c.patterns.fringes, c.decode, c.monitor.resolution)
        if problem is not None:
            raise ConfigError(f"sweep point {p.index} ({p.values}): the measurement chain "
                              f"cannot decode it: {problem}")
        fr, fr0 = c.patterns.fringes, first.patterns.fringes
        if fr.directions != fr0.directions or len(fr.widths_px) != len(fr0.widths_px):
            raise ConfigError("sweep: every point needs the same patterns.fringes.directions "
                              "and number of widths_px (sweep a width by index, e.g. "
                              "'patterns.fringes.widths_px.0')")
        if sweep.decimation and c.camera.resolution != first.camera.resolution:
            raise ConfigError("sweep: camera.resolution changes between points, so the maps "
                              "cannot share a store; set sweep.decimation = 0 (statistics "
                              "only)")
    w, h = first.camera.resolution
    dec = sweep.decimation
    rows = np.arange(h)[dec // 2::dec] if dec else np.zeros(0, np.int64)
    cols = np.arange(w)[dec // 2::dec] if dec else np.zeros(0, np.int64)
    return SweepPlan(base, sweep, dims, shape, coords, tuple(points),
                     tuple(first.patterns.fringes.directions),
                     len(first.patterns.fringes.widths_px), rows, cols)


# ----------------------------------------------------------------------------- one point
#: Sections of a configuration that the vision-ray geometry (:meth:`Simulation.geometry`:
#: surface and monitor masks, exact specular points, surface points) does not depend on.
#: Every other section (camera, monitor, surface, and any section added later) is part of
#: :func:`geometry_key`: a new section is never wrongly shared, at worst shared less.
NOT_GEOMETRY = frozenset({"name", "brdf", "anisotropy", "sampling", "patterns", "decode",
                          "reconstruct", "sensor", "diagnostics", "compute", "output",
                          "variants", "sweep"})
#: Sections the decoded ideal specular reference does not depend on (it is the mirror,
#: one ray per pixel: no BRDF, frame or sampling).
NOT_REFERENCE = frozenset({"name", "brdf", "anisotropy", "sampling", "diagnostics",
                           "compute", "output", "variants", "sweep"})


def _key(cfg: RunConfig, exclude: frozenset) -> str:
    import hashlib

    text = json.dumps(cfg.model_dump(mode="json", exclude=set(exclude)), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def geometry_key(cfg: RunConfig) -> str:
    """The hash (SHA-256 of the JSON) of the configuration sections the vision-ray geometry
    depends on: points with the same key share one :class:`~pmdsim.render.Geometry`."""
    return _key(cfg, NOT_GEOMETRY)


def reference_key(cfg: RunConfig) -> str:
    """The hash of the configuration sections the decoded ideal specular reference depends
    on (everything but the BRDF, its frame, the sampling and what only says how to run):
    points with the same key share it."""
    return _key(cfg, NOT_REFERENCE)


class KeyedCache:
    """The last ``size`` values by key, each made once per process (threads that ask for a
    key being made wait for it), with counts of what was made and what was reused."""

    def __init__(self, size: int):
        self.size = size
        self._items: "OrderedDict[str, object]" = OrderedDict()
        self._lock = threading.Lock()
        self._making: dict[str, threading.Lock] = {}
        self.made = self.reused = 0

    def get(self, key: str, make):
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                self.reused += 1
                return self._items[key]
            making = self._making.setdefault(key, threading.Lock())
        with making:
            with self._lock:
                if key in self._items:
                    self.reused += 1
                    return self._items[key]
            value = make()
            with self._lock:
                self._items[key] = value
                self.made += 1
                self._making.pop(key, None)
                while len(self._items) > self.size:
                    self._items.popitem(last=False)
        return value

    def clear(self) -> None:
        with self._lock:
            self._items.clear()
            self.made = self.reused = 0


#: Per process (a sweep worker keeps them from point to point): the vision-ray geometries
#: and the decoded specular references of the last two distinct set-ups. Points sharing
#: them are scheduled next to each other (:mod:`pmdsim.run.sweep`).
GEOMETRIES = KeyedCache(2)
REFERENCES = KeyedCache(2)


def measure_point(cfg: RunConfig, decimation: int = 8, scheduler: str = "synchronous") -> dict:
    """The measurement chain of one configuration, in memory: render its fringes, decode
    them and those of the ideal specular reference, compare.

    Parameters
    ----------
    cfg : RunConfig
        One point (no variants; fringes that can be decoded).
    decimation : int
        Maps at camera pixels ``[d//2::d, d//2::d]``; 0: no maps.
    scheduler : str
        Dask scheduler of the point's own tiles (a sweep runs its points in parallel, so
        each point runs its tiles one after the other by default).

    Returns
    -------
    dict
        {name: ndarray} with the dimensions of :data:`POINT_VARIABLES` (and
        :data:`MAP_VARIABLES` when ``decimation``); bit-identical for the same ``cfg``.
    """
    import warnings

    from ..measure import chain
    from ..render import Simulation
    from .specular_reference import decode_specular_reference

    from dataclasses import replace

    from ..scene.sensor import Sensor, capture_dn

    sim = Simulation.from_config(cfg)
    sim = Simulation(sim.scene, sim.tile_rows, scheduler, None)
    geometry = GEOMETRIES.get(geometry_key(cfg), sim.geometry)
    ref_decoded, distance = REFERENCES.get(
        reference_key(cfg), lambda: decode_specular_reference(cfg, sim, geometry))
    fr_cfg = cfg.patterns.fringes
    fringes = sim.render_fringes(fr_cfg.widths_px, fr_cfg.directions, fr_cfg.shifts)
    sensor = Sensor.from_config(cfg.sensor)
    if sensor.enabled:  # as a run: what the camera writes (stream 0)
        fringes = replace(fringes, images=capture_dn(sensor, fringes.images, 0))
    decoded = chain.decode_fringes(fringes, cfg.monitor.resolution, cfg.decode,
                                   sensor.saturation_dn if sensor.enabled else None,
                                   keep_amplitude=False)
    from .coverage import off_monitor_mask  # as simulate: lobes off the monitor are not valid

    off = off_monitor_mask(fringes.f_total, fringes.f_hit, geometry.surface_mask,
                           cfg.diagnostics.max_off_monitor_fraction)
    del fringes
    measured = chain.compare(decoded, ref_decoded, geometry, distance,
                             cfg.monitor.pixel_pitch_mm, cfg.decode, fr_cfg.shifts,
                             slope_geometry=chain.SlopeGeometry(
                                 geometry.points, sim.scene.camera.viewpoint, sim.scene.monitor),
                             off_monitor=off)
    dcs = [measured.directions[d] for d in fr_cfg.directions]
    per_direction = [chain.direction_quantity_stats(dc) for dc in dcs]  # once each
    stats = np.array([[[np.nan if (x := st[q][s]) is None else x for s in STATISTICS]
                       for q in QUANTITIES] for st in per_direction], np.float64)

    def median(a, where):
        m = finite_median(a, where)
        return np.nan if m is None else m

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mod = np.array([[median(m, dc.decoded.valid) for m in dc.decoded.modulation]
                        for dc in dcs])
        ratio = np.array([[median(r, np.asarray(dc.reference.valid, bool))
                           for r in dc.deviation.modulation_ratio] for dc in dcs])
    out = {"deviation_stats": stats, "modulation_median": mod,
           "modulation_ratio_median": ratio}
    if decimation:
        s = np.s_[decimation // 2::decimation, decimation // 2::decimation]
        out["phase_deviation"] = np.stack([dc.deviation.phase[s] for dc in dcs]).astype(np.float32)
        out["slope_deviation_urad"] = np.stack([dc.slope_urad[s] for dc in dcs]).astype(np.float32)
        out["modulation"] = np.stack([np.asarray(dc.decoded.modulation)[(slice(None),) + s]
                                      for dc in dcs]).astype(np.float32)
    return out


__all__ = ["SweepPoint", "SweepPlan", "plan_sweep", "point_seed", "measure_point", "reference_key",
           "geometry_key", "KeyedCache", "GEOMETRIES", "REFERENCES",
           "POINT_VARIABLES", "MAP_VARIABLES"]
