"""Command-line interface: ``rangesim scan | sensors | info``.

The entry point is :func:`rangesim.cli.main.main` (not re-exported here, so that
``rangesim.cli.main`` stays the module).
"""
