"""``python -m services.study ...`` is ``arroch study ...``."""

import sys

from services.cli import main

if __name__ == "__main__":
    sys.exit(main(["study", *sys.argv[1:]]))
