import sys

from mesh2tex.cli import console

sys.exit(console())
