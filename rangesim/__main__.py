"""``python -m rangesim``: the same as the ``rangesim`` command."""
import sys

from rangesim.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
