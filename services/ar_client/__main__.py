"""``python -m services.ar_client [options]`` is ``arroch ar [options]``."""

import sys

from services.cli import main

if __name__ == "__main__":
    sys.exit(main(["ar", *sys.argv[1:]]))
