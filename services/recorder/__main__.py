import sys

from services.cli import main

sys.exit(main(["record", *sys.argv[1:]]))
