"""``python -m services.sim [options]`` is ``arroch sim [options]``."""

import sys

from services.cli import main

if __name__ == "__main__":
    sys.exit(main(["sim", *sys.argv[1:]]))
