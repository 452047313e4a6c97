"""Is a run folder whole? Checks that name the array and the file that is damaged.

``pmdsim report`` redraws a run from its dataset alone; a damaged folder (a truncated or
zeroed chunk, a missing or invalid ``config_json``, a truncated ``zarr.json``, a deleted
variable) must say what is broken and where, not fail inside Blosc or pydantic.
:func:`open_run_checked` opens a run's ``run.zarr`` after checking, in this order:

1. every ``zarr.json`` of the store parses as JSON (else: that file);
2. the root's attributes hold a valid ``config_json`` (else: the attribute and its file);
3. every variable the root's consolidated metadata lists is on disk (else: the variable);
4. every chunk of every variable decodes (else: the variable and the chunk file); a chunk
   whose ``crc32c`` checksum (the last codec of every array the run writer writes,
   :mod:`pmdsim.store.writer`) does not match its bytes is named as such: the file changed
   after the run wrote it (a flipped byte still decompresses, to wrong numbers).

A run written before the checksums (its arrays without the ``crc32c`` codec) is read as
before: its chunks are decoded, but a byte changed inside one cannot be seen;
:func:`unchecked_arrays` lists such arrays, and the commands say so in a note.

Every failure is an :class:`~pmdsim.config.InputError` (exit code 2 on the command line).
"""

from __future__ import annotations

import json
from pathlib import Path

from ..config import InputError, RunConfig
from .schema import DATASET_NAME

_AGAIN = "the run folder is damaged: run pmdsim simulate again (or restore it)"


def _metadata_files(store: Path) -> list[Path]:
    return sorted(store.rglob("zarr.json"))


def check_metadata(store: Path) -> dict:
    """Parse every ``zarr.json`` of ``store``; return the root's. InputError naming the
    first file that is missing or not JSON."""
    root = store / "zarr.json"
    if not root.is_file():
        raise InputError(f"{root}: missing; {store} is not a complete Zarr store ({_AGAIN})")
    out = None
    for f in _metadata_files(store):
        try:
            meta = json.loads(f.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            what = f.parent.name if f.parent != store else "the dataset's root"
            raise InputError(f"{f}: metadata of {what} is unreadable ({type(err).__name__}: "
                             f"{err}); {_AGAIN}") from None
        if f == root:
            out = meta
    return out


def check_config(root_meta: dict, store: Path) -> RunConfig:
    """The run's configuration from the root attribute ``config_json``."""
    where = store / "zarr.json"
    text = (root_meta.get("attributes") or {}).get("config_json")
    if not isinstance(text, str):
        raise InputError(f"{where}: the attribute config_json is missing, so the run's "
                         f"configuration is unknown; {_AGAIN}")
    try:
        return RunConfig.model_validate_json(text)
    except ValueError as err:
        first = str(err).splitlines()
        brief = "; ".join(line.strip() for line in first[:3])
        raise InputError(f"{where}: the attribute config_json is not a valid pmdsim "
                         f"configuration ({brief}); {_AGAIN}") from None


def _listed_arrays(root_meta: dict) -> list[str]:
    cons = root_meta.get("consolidated_metadata") or {}
    meta = cons.get("metadata") or {}
    return sorted(k for k, v in meta.items()
                  if isinstance(v, dict) and v.get("node_type") == "array" and "/" not in k)


def unchecked_arrays(root_meta: dict, names: list[str] | None = None) -> list[str]:
    """The variables (of ``names`` only, if given) that the root's consolidated metadata
    lists without a ``crc32c`` codec: a run written before the checksums."""
    meta = ((root_meta.get("consolidated_metadata") or {}).get("metadata") or {})
    out = []
    for name in _listed_arrays(root_meta):
        if names is not None and name not in names:
            continue
        codecs = meta[name].get("codecs") or []
        if not any(isinstance(c, dict) and c.get("name") == "crc32c" for c in codecs):
            out.append(name)
    return out


def unchecked_note(store: Path, root_meta: dict, names: list[str] | None = None) -> str | None:
    """A note for a run whose arrays (of ``names``) have no checksums, else None."""
    old = unchecked_arrays(root_meta, names)
    if not old:
        return None
    return (f"{store}: written without checksums (by a pmdsim before they were added), so a "
            f"byte changed inside a chunk of {', '.join(old[:3])}{' ...' if len(old) > 3 else ''} "
            "cannot be detected; run pmdsim simulate again for a checked run")


def _checksum_mismatch(arr, path: Path) -> tuple[str, str] | None:
    """(stored, computed) crc32c of the chunk file ``path`` of ``arr`` when the array has a
    ``crc32c`` codec (the last one: the file ends with the checksum of the bytes before it)
    and they differ; None otherwise."""
    from zarr.codecs import Crc32cCodec

    from .writer import crc32c_checksum

    codecs = getattr(arr.metadata, "codecs", ())
    if not codecs or not isinstance(codecs[-1], Crc32cCodec):
        return None
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if len(data) < 4:
        return data.hex() or "nothing", "a 4-byte checksum"
    stored = data[-4:]
    computed = crc32c_checksum(data[:-4])
    return None if stored == computed else (stored.hex(), computed.hex())


def check_arrays(store: Path, root_meta: dict, names: list[str] | None = None) -> None:
    """Every listed variable exists; every chunk of every array (of ``names`` only, if
    given) decodes."""
    import zarr

    for name in _listed_arrays(root_meta):
        if names is not None and name not in names:
            continue
        if not (store / name / "zarr.json").is_file():
            raise InputError(f"{store / name}: the variable {name!r} of the run's dataset is "
                             f"missing (listed in {store / 'zarr.json'}); {_AGAIN}")
    try:
        group = zarr.open_group(store, mode="r")
    except Exception as err:  # noqa: BLE001 - zarr raises many kinds
        raise InputError(f"{store}: cannot be opened as a Zarr store ({type(err).__name__}: "
                         f"{err}); {_AGAIN}") from None
    for name, arr in sorted(group.arrays()):
        if names is not None and name not in names:
            continue
        grid = arr.cdata_shape
        import itertools

        for idx in itertools.product(*(range(n) for n in grid)):
            try:
                arr.get_block_selection(idx)
            except Exception as err:  # noqa: BLE001 - codecs raise many kinds
                key = arr.metadata.encode_chunk_key(idx)
                bad = _checksum_mismatch(arr, store / name / key)
                if bad is not None:
                    raise InputError(
                        f"{store / name / key}: chunk {idx} of the variable {name!r} fails its "
                        f"checksum (crc32c stored {bad[0]}, computed {bad[1]}): the file changed "
                        f"after pmdsim wrote it, so the run {store.parent} is damaged: run "
                        "pmdsim simulate again (or restore it)") from None
                raise InputError(f"{store / name / key}: chunk {idx} of the variable {name!r} "
                                 f"cannot be decoded ({type(err).__name__}: {err}); "
                                 f"{_AGAIN}") from None


def open_run_checked(folder: str | Path, *, chunks: bool = True,
                     notes: list[str] | None = None):
    """(dataset, configuration) of a run (or variant) folder after the checks of the module
    docstring (``chunks=False`` skips decoding every chunk). ``notes`` (a list) receives
    :func:`unchecked_note` for a run written without checksums."""
    from .schema import load_run

    folder = Path(folder)
    store = folder / DATASET_NAME
    root = check_metadata(store)
    cfg = check_config(root, store)
    if chunks:
        check_arrays(store, root)
    note = unchecked_note(store, root)
    if note is not None and notes is not None:
        notes.append(note)
    try:
        ds = load_run(store, dask=False)
    except Exception as err:  # noqa: BLE001 - xarray/zarr: name the store
        raise InputError(f"{store}: cannot be opened ({type(err).__name__}: {err}); "
                         f"{_AGAIN}") from None
    return ds, cfg


__all__ = ["open_run_checked", "check_metadata", "check_config", "check_arrays",
           "unchecked_arrays", "unchecked_note"]
