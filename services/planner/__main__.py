"""``python -m services.planner [options]`` is ``arroch planner [options]``."""

import sys

from services.cli import main

if __name__ == "__main__":
    sys.exit(main(["planner", *sys.argv[1:]]))
