"""The bench application: command line, configuration, storage, reports.

``__version__`` is looked up when first asked for: importlib.metadata costs about 0.1 s,
and `bench` catches the ending signals only once this package is imported (decision 0051).
"""


def __getattr__(name: str) -> str:
    if name != "__version__":
        raise AttributeError(f"module 'bench' has no attribute {name!r}")
    from importlib import metadata

    try:
        version = metadata.version("guideway-bench")
    except metadata.PackageNotFoundError:      # a source tree that was never installed
        version = "unknown"
    globals()["__version__"] = version
    return version
