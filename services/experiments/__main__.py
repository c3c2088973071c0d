"""``python -m services.experiments [robots|laziness|report] ...`` is ``arroch experiment ...``."""

import sys

from services.cli import main

if __name__ == "__main__":
    sys.exit(main(["experiment", *sys.argv[1:]]))
