"""``python -m services.restrictor [options]`` is ``arroch restrictor [options]``."""

import sys

from services.cli import main

if __name__ == "__main__":
    sys.exit(main(["restrictor", *sys.argv[1:]]))
