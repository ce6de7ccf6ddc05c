"""The bench application: command line, configuration, storage, reports."""

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("guideway-bench")
except _metadata.PackageNotFoundError:      # a source tree that was never installed
    __version__ = "unknown"
