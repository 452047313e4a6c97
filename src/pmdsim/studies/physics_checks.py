"""The physics sanity of a whole run configuration, before any ray is traced
(:func:`check_physics`: the sensor, display and BRDF checks of :mod:`pmdsim.scene.sanity`
on its sections), and of every configuration of a study, each distinct one once
(:func:`check_each`, which names the configuration of a refusal)."""

from __future__ import annotations

import numpy as np

from ..config import ConfigError, RunConfig
from ..scene.sanity import check_brdf, check_display, check_sensor


def check_physics(cfg: RunConfig, scene=None) -> list[str]:
    """The checks of :mod:`pmdsim.scene.sanity` for a run configuration (and its
    :class:`~pmdsim.scene.Scene`, when built: only its monitor is used; without one the
    monitor is built from ``cfg``); raises :class:`ConfigError` naming the field, returns
    notes (each naming the field and the share it affects)."""
    from ..scene.monitor import Monitor
    from ..scene.sensor import Sensor

    notes = check_sensor(Sensor.from_config(cfg.sensor))
    target = cfg.camera.look_at_mm
    if target is None:
        target = getattr(cfg.surface, "centre_mm", (0.0, 0.0, 0.0))
    monitor = scene.monitor if scene is not None else Monitor.from_config(cfg.monitor)
    notes += check_display(monitor, np.asarray(target, np.float64))
    notes += check_brdf(cfg.brdf, getattr(cfg.diagnostics, "allow_albedo_above_one", False))
    return notes


def physics_key(cfg: RunConfig) -> str:
    """What :func:`check_physics` reads of ``cfg`` (configurations with the same key get the
    same answer): the sensor (but its seed), monitor, BRDF, camera target, surface and the
    diagnostics' overrides."""
    d = cfg.model_dump(mode="json", include={"sensor", "monitor", "brdf", "camera", "surface",
                                               "diagnostics"})
    (d.get("sensor") or {}).pop("seed", None)
    return repr(sorted(d.items()))


def check_each(configs, labels) -> list[str]:
    """:func:`check_physics` of every configuration of a study (sweep points, ...), each
    distinct one once; a refusal names the configuration by its label
    (``invalid configuration (<label>):``); returns the notes, each with its label."""
    seen: dict[str, list[str]] = {}
    notes: list[str] = []
    for cfg, label in zip(configs, labels):
        key = physics_key(cfg)
        if key not in seen:
            try:
                seen[key] = check_physics(cfg)
            except ConfigError as err:
                head, _, rest = str(err).partition("\n")
                raise ConfigError(f"invalid configuration ({label}):\n{rest or head}") from None
            notes += [f"{label}: {n}" for n in seen[key]]
    return notes
