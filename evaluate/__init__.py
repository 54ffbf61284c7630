"""Pipeline stage package: evaluate (reads the folders, worlds and checkpoints, writes the tables; the
protocols themselves are :mod:`mesh2tex.evaluation`)."""
