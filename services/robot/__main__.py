import sys

from services.cli import main

sys.exit(main(["robot", *sys.argv[1:]]))
