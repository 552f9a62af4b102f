"""``python -m reachconf``: the command line, the same as the ``reachconf`` script (:func:`reachconf.cli.main`)."""

import sys

from reachconf.cli import main

if __name__ == "__main__":
    sys.exit(main())
