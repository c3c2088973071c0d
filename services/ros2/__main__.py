import sys

from services.cli import main

sys.exit(main(["ros2", *sys.argv[1:]]))
