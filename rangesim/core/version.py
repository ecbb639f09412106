"""The package version, defined once (``rangesim.__version__`` re-exports it).

It lives in core so that any layer can stamp files with it without importing the
package root. Keep it equal to ``version`` in ``pyproject.toml``.
"""
__version__ = "0.1.0"
