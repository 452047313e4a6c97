"""Strict JSON files (NaN written as null) and the dots' CSV table of a run folder."""

from __future__ import annotations
import json
import math
from pathlib import Path
import numpy as np
from ..measure import chain


def json_safe(obj):
    """NaN/inf -> None and NumPy scalars -> Python numbers, recursively (strict JSON: a
    result file never holds NaN, which strict parsers refuse; None reads as "undefined")."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def write_json(path: str | Path, content, indent: int | None = 2) -> Path:
    """Write ``content`` as strict JSON (:func:`json_safe`; ``allow_nan=False``)."""
    path = Path(path)
    path.write_text(json.dumps(json_safe(content), indent=indent, allow_nan=False) + "\n")
    return path


def write_dot_csv(path, table: list[dict]) -> None:
    """Write :func:`dot_table` rows as CSV (header :data:`DOT_COLUMNS`)."""
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(chain.DOT_COLUMNS))
        w.writeheader()
        for r in table:
            w.writerow({k: (f"{r[k]:.6g}" if isinstance(r[k], float) else r[k])
                        for k in chain.DOT_COLUMNS})
