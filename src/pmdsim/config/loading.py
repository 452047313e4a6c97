"""Reading and validating a configuration: TOML files (paths resolved against the file's
folder) and mappings; errors name the field as written in the file."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import get_args

from pydantic import ValidationError

from .base import ConfigError
from .surface import SurfaceConfig
from .brdf import BrdfConfig
from .run import RunConfig


def _union_tags(union, field: str) -> set:
    inner = get_args(union)[0]  # Annotated[X | Y, Field(discriminator=...)] -> X | Y
    return {t for m in (get_args(inner) or (inner,)) for t in get_args(m.model_fields[field].annotation)}


#: Tagged unions (field name -> its tags): pydantic puts the tag into error locations
#: (``brdf.ward.alpha_x``); the messages show the path as written in the file (``brdf.alpha_x``).
_UNION_TAGS = {"surface": _union_tags(SurfaceConfig, "type"), "prior": _union_tags(SurfaceConfig, "type"),
               "brdf": _union_tags(BrdfConfig, "model")}


def _error_path(loc) -> list:
    return [p for k, p in enumerate(loc)
            if not (k > 0 and isinstance(loc[k - 1], str) and p in _UNION_TAGS.get(loc[k - 1], ()))]


def _member_tag(p) -> bool:
    """A location part that names a member of a union in pydantic's own notation
    (``tuple[...]``, ``literal['auto']``, ``function-after[...]``): not a field."""
    return isinstance(p, str) and "[" in p


def _format_errors(err: ValidationError, source: str) -> str:
    lines = [f"invalid configuration ({source}):"]
    errors = err.errors()
    # a union (e.g. camera.roi: a tuple or "auto"): pydantic reports every member's error
    # under its own tag; keep the errors of the members the input got furthest into
    plain = [tuple(p for p in e["loc"] if not _member_tag(p)) for e in errors]
    deeper = {loc[:k] for loc in plain for k in range(1, len(loc))}
    for e, bare in zip(errors, plain):
        if len(bare) < len(e["loc"]) and bare in deeper:
            continue  # the member the input's shape did not fit (e.g. "should be 'auto'")
        e = dict(e, loc=bare)
        path = _error_path(e["loc"])
        msg = e["msg"].removeprefix("Value error, ")
        if e["type"] in ("union_tag_not_found", "union_tag_invalid"):
            path.append(str(e.get("ctx", {}).get("discriminator", "")).strip("'\""))
            if e["type"] == "union_tag_not_found":
                msg = "required field is missing"
        loc = ".".join(str(p) for p in path) or "(top level)"
        if e["type"] == "extra_forbidden":
            msg = "unknown field (check the spelling; see docs/configuration.md)"
        elif e["type"] == "missing":
            msg = "required field is missing"
        inp = e.get("input")
        text = repr(inp)
        text = text if len(text) <= 80 else text[:77] + "..."
        shown = "" if e["type"] in ("missing",) or isinstance(inp, dict) else f" (got {text})"
        hint = _HINTS.get(".".join(str(p) for p in path[:2]), "")
        lines.append(f"  {loc}: {msg}{shown}{hint}")
    return "\n".join(dict.fromkeys(lines))


#: What a field holds, said after its error where the bare message does not.
_HINTS = {"camera.roi": "; camera.roi = [col0, row0, width, height] in sensor px (from 0), "
                        "or 'auto'"}


def parse_config(data: dict, source: str = "<dict>") -> RunConfig:
    """Validate a configuration mapping; raises :class:`ConfigError` naming every bad field."""
    try:
        return RunConfig.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_errors(err, source)) from None


def load_config(path: str | Path) -> RunConfig:
    """Read and validate a TOML configuration file.

    Relative image paths in ``patterns.images.files`` are resolved against the file's folder.
    Every problem (a missing or unreadable file, bad TOML, a section of the wrong shape, a
    bad value) is a :class:`ConfigError` naming the file and the field.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"configuration file not found: {path} (check the path)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: cannot read the configuration file ({err})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None
    mon = data.get("monitor")
    if isinstance(mon, dict):
        for key in ("response_lut", "flatness_map"):
            if isinstance(mon.get(key), str):
                mon[key] = str((path.parent / mon[key]).resolve())
    surf = data.get("surface")
    if isinstance(surf, dict) and surf.get("type") == "height_map":
        surf["file"] = _resolve_file(path.parent, surf.get("file"))
    prior = (data.get("reconstruct") or {}).get("prior") if isinstance(data.get("reconstruct"), dict) else None
    if isinstance(prior, dict) and prior.get("type") == "height_map":
        prior["file"] = _resolve_file(path.parent, prior.get("file"))
    patterns = data.get("patterns")
    images = patterns.get("images") if isinstance(patterns, dict) else None
    if isinstance(images, dict) and isinstance(images.get("files"), list):
        images["files"] = [_resolve_file(path.parent, f) for f in images["files"]]
    brdf = data.get("brdf")
    if isinstance(brdf, dict) and "file" in brdf:
        brdf["file"] = _resolve_file(path.parent, brdf["file"])
    if isinstance(brdf, dict) and isinstance(brdf.get("variation"), dict) and "file" in brdf["variation"]:
        brdf["variation"]["file"] = _resolve_file(path.parent, brdf["variation"]["file"])
    variants = data.get("variants")
    for var in variants if isinstance(variants, list) else ():  # a variant's own BRDF file
        vb = var.get("brdf") if isinstance(var, dict) else None
        if isinstance(vb, dict) and "file" in vb:
            vb["file"] = _resolve_file(path.parent, vb["file"])
    return parse_config(data, str(path))


def _resolve_file(folder: Path, name):
    """``folder / name`` resolved; anything that is not a usable path string is left as it
    is for the validation to name (``patterns.images.files.<k>``)."""
    if not isinstance(name, str) or not name or "\x00" in name:
        return name
    try:
        return str((folder / name).resolve())
    except (OSError, ValueError, RuntimeError):
        return name
