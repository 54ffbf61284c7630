import sys

from mesh2tex.cli import main

sys.exit(main())
