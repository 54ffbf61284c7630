"""Pipeline stage package: train (reads and writes files, calls the mesh2tex library)."""
