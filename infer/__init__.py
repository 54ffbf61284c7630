"""Pipeline stage package: infer (reads and writes files, calls the mesh2tex library)."""
