"""The installed version of pmdsim (``0+unknown`` in a source tree that is not installed)."""

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("pmdsim")
except _metadata.PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0+unknown"
