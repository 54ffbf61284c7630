"""Geometry: loading and cleaning meshes, quad remeshing, hierarchies, neighbourhoods, features."""
