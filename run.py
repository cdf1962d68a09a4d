"""Entry point: ``python run.py [SCENE] [options]``; see ``python run.py --help``."""

import sys

from pbf.app.cli import main

if __name__ == "__main__":
    sys.exit(main())
