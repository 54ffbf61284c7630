"""Pipeline stage package: data_prep (reads and writes files, calls the mesh2tex library)."""
