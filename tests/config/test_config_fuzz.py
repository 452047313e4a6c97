"""Property-based test of the configuration: the example configurations, mutated at random
(a value replaced by NaN, inf, a boolean, a huge or negative number, a string, a list, a
table; a key deleted or added; a section replaced by a scalar), either validate or fail
with a :class:`ConfigError` whose message names a field by its dotted path. No other
exception may escape ``load_config``/``parse_config``/``check_resources``.

The mutated mappings go through both doors: ``parse_config`` (a mapping, as Python users
build it) and ``load_config`` (written as TOML text first, as a user writes it). Pure
validation, no rendering: 500 derandomised examples take a few seconds.
"""

from __future__ import annotations

import copy
import json
import math
import re
import tempfile
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pmdsim.config import (
    ConfigError,
    RunConfig,
    check_resources,
    estimate_resources,
    load_config,
    parse_config,
)

EXAMPLES = sorted((Path(__file__).parents[2] / "examples").glob("*.toml"))
BASES = [tomllib.loads(p.read_text()) for p in EXAMPLES]
#: A line of a ConfigError that names a field: "  camera.position_mm.0: ..." (or the top
#: level, for a document that is not a table of sections at all).
FIELD_LINE = re.compile(r"^  (\(top level\)|[A-Za-z_][\w]*(\.[\w]+)*):", re.M)
_DELETE = object()


# ----------------------------------------------------------------------------- TOML text
def _toml_string(s: str) -> str:
    # JSON's escapes of control characters are TOML basic-string escapes; TOML also wants
    # DEL escaped and takes non-ASCII characters as they are (not as surrogate pairs)
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _toml_string(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_toml_string(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def _is_table_array(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def to_toml(data: dict, prefix: str = "") -> str:
    """A minimal TOML writer: scalars and arrays inline, tables as [a.b], arrays of tables
    as [[a]] (enough for every shape the fuzzer makes)."""
    lines = []
    for k, v in data.items():
        if not isinstance(v, dict) and not _is_table_array(v):
            lines.append(f"{_toml_string(k)} = {_toml_value(v)}")
    for k, v in data.items():
        name = f"{prefix}{_toml_string(k)}"
        if isinstance(v, dict):
            lines.append(f"\n[{name}]")
            lines.append(to_toml(v, name + "."))
        elif _is_table_array(v):
            for item in v:
                lines.append(f"\n[[{name}]]")
                lines.append(to_toml(item, name + "."))
    return "\n".join(lines)


def test_the_toml_writer_round_trips_the_examples():
    for base in BASES:
        assert tomllib.loads(to_toml(base)) == base


# ----------------------------------------------------------------------------- mutations
def _paths(node, prefix=()):
    """Every (path) to a key or list item of a nested mapping."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(prefix + (k,))
            out += _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append(prefix + (i,))
            out += _paths(v, prefix + (i,))
    return out


def _set(data, path, value):
    parent = data
    for p in path[:-1]:
        parent = parent[p]
    if value is _DELETE:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value


def _get(data, path):
    for p in path:
        data = data[p]
    return data


scalars = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, -1, 1, 2, 3, 10**6, 10**9, 2**63, 10**12]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([float("nan"), float("inf"), -float("inf"), 0.0, -0.0, 1e-300, 1e300,
                     -1.0, 0.5, 89.999, 90.0]),
    st.text(max_size=8),
    st.sampled_from(["", "auto", "x", "flat", "ward", "mirror", "a\x00b", "../x"]),
)
values = st.one_of(
    scalars,
    st.lists(scalars, max_size=4),
    st.dictionaries(st.sampled_from(["x", "files", "model", "type", "name", "n_rays"]),
                    scalars, max_size=2),
    st.just(_DELETE),
)
#: Keys a user might add (typos, real keys in the wrong section).
new_keys = st.sampled_from(["sise_mm", "n_rays", "patterns", "images", "files", "model",
                            "fringes", "gamma", "type", "variants", "x"])


@st.composite
def mutated_example(draw):
    data = copy.deepcopy(draw(st.sampled_from(BASES)))
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(data)
        op = draw(st.sampled_from(["replace", "replace", "scale", "add", "top"]))
        if op == "top":
            # a top-level key of any shape: `patterns = 5` before the first table
            _set(data, (draw(st.sampled_from(list(data) + ["patterns", "sampling"])),),
                 draw(values))
        elif op == "add" or not paths:
            parents = [()] + [p for p in paths if isinstance(_get(data, p), dict)]
            parent = draw(st.sampled_from(parents))
            value = draw(values)
            if value is not _DELETE:
                _set(data, parent + (draw(new_keys),), value)
        elif op == "scale":
            numeric = [p for p in paths if isinstance(_get(data, p), (int, float))
                       and not isinstance(_get(data, p), bool)]
            if numeric:
                p = draw(st.sampled_from(numeric))
                factor = draw(st.sampled_from([-1, 0, 1e-9, 1e3, 1e6, 1e12]))
                old = _get(data, p)
                _set(data, p, type(old)(old * factor) if isinstance(old, float) else old * int(factor or 0))
        else:
            _set(data, draw(st.sampled_from(paths)), draw(values))
    return data


def _assert_field_named(err: ConfigError, data) -> None:
    msg = str(err)
    assert FIELD_LINE.search(msg), f"no field named in:\n{msg}\nfor {data!r}"


def _check(data, tmp: Path) -> None:
    results = []
    # the mapping door
    try:
        results.append(parse_config(copy.deepcopy(data)))
    except ConfigError as err:
        _assert_field_named(err, data)
    # the file door
    path = tmp / "fuzz.toml"
    try:
        text = to_toml(data)
    except TypeError:
        text = None
    if text is not None:
        path.write_text(text, encoding="utf-8")
        try:
            results.append(load_config(path))
        except ConfigError as err:
            _assert_field_named(err, data)
            assert str(path) in str(err)
    for cfg in results:
        assert isinstance(cfg, RunConfig)
        # a valid config round-trips through its stored form (how a run folder keeps it)
        assert parse_config(json.loads(cfg.model_dump_json())) == cfg
        # and its resources are estimated without error (finite, positive) or refused
        est = estimate_resources(cfg)
        assert math.isfinite(est.memory_bytes) and est.memory_bytes > 0
        assert math.isfinite(est.cpu_seconds) and est.cpu_seconds >= 0
        try:
            check_resources(cfg, available_bytes=8 * 2**30)
        except ConfigError as err:
            _assert_field_named(err, data)


_TMP = Path(tempfile.mkdtemp(prefix="pmdsim-fuzz-"))


@settings(derandomize=True, max_examples=500, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(mutated_example())
def test_mutated_examples_validate_or_name_a_field(data):
    _check(data, _TMP)


# ----------------------------------------------------------------------------- known cases
FIG3 = EXAMPLES[[p.name for p in EXAMPLES].index("paper_fig3.toml")].read_text()
_NO_CAMERA = re.sub(r"(?ms)^\[camera\].*?(?=^\[monitor\])", "", FIG3)
_NO_PATTERNS = re.sub(r"(?ms)^\[patterns\.fringes\].*?(?=^\[compute\])", "", FIG3)
MALFORMED = {
    # prepended: top-level keys come before the first table
    "a section as a number before the first table": "patterns = 5\n" + _NO_PATTERNS,
    "camera as a list": "camera = [1, 2]\n" + _NO_CAMERA,
    "the whole file one list": "x = [1, 2]\n",
    # appended tables
    "image files as numbers": FIG3 + "\n[patterns.images]\nfiles = [1]\n",
    "image files as one string": FIG3 + '\n[patterns.images]\nfiles = "a.png"\n',
    "images as a number": FIG3 + "\n[patterns]\nimages = 3\n",
    "a NUL in a file name": FIG3 + '\n[patterns.images]\nfiles = ["a\\u0000b.png"]\n',
    "n_rays a boolean": FIG3.replace("target_error_mrad = 0.1", "n_rays = true"),
    "gamma NaN": FIG3.replace("gamma = 1.0", "gamma = nan"),
    "position inf": FIG3.replace("position_mm = [-845.236523481399", "position_mm = [-inf"),
}
EXPECTED_FIELD = {
    "a section as a number before the first table": "patterns",
    "camera as a list": "camera",
    "the whole file one list": "x",
    "image files as numbers": "patterns.images.files.0",
    "image files as one string": "patterns.images.files",
    "images as a number": "patterns.images",
    "a NUL in a file name": "patterns.images.files",
    "n_rays a boolean": "sampling.n_rays",
    "gamma NaN": "monitor.gamma",
    "position inf": "camera.position_mm.0",
}


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed_sections_fail_with_a_config_error(case, tmp_path):
    assert MALFORMED[case] != FIG3, "the edit did not apply: the example's text changed"
    path = tmp_path / "bad.toml"
    path.write_text(MALFORMED[case])
    with pytest.raises(ConfigError) as info:
        load_config(path)
    msg = str(info.value)
    assert FIELD_LINE.search(msg), msg
    assert f"  {EXPECTED_FIELD[case]}:" in msg, msg
