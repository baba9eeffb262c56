"""The toolkit's version (one place: ``observer.__version__``, and the results' metadata
:func:`observer.result.package_versions`, read it)."""

__version__ = "0.1.0"
