"""A native crash of xatlas (it dies on some meshes, for instance a perfectly regular subdivided icosphere of
82k faces) does not take the command with it: the atlas is cut again on a slightly shaken copy, with a
warning, and when that dies too the user gets one line naming the file."""

from __future__ import annotations

import os
import signal
import sys

import numpy as np
import pytest
import trimesh
import xatlas

import mesh2tex.render.bake as bake
from mesh2tex.errors import InputError
from mesh2tex.geometry.mesh_io import UserMesh

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="xatlas runs apart only where it forks")


def crash(points, faces):
    os.kill(os.getpid(), signal.SIGSEGV)


def test_a_crash_on_the_mesh_as_it_is_is_retried_on_a_shaken_copy_with_a_warning(monkeypatch):
    mesh = trimesh.creation.icosphere(subdivisions=2)
    original = xatlas.parametrize
    as_given = np.unique(mesh.vertices, axis=0).astype(np.float32)  # what new_atlas hands xatlas

    def crash_unless_shaken(points, faces):
        if np.array_equal(points, as_given):
            crash(points, faces)
        return original(points, faces)

    monkeypatch.setattr(xatlas, "parametrize", crash_unless_shaken)
    with pytest.warns(UserWarning, match="xatlas crashed on the mesh as it is"):
        vertex_index, faces, uv = bake.new_atlas(mesh.vertices, mesh.faces)
    np.testing.assert_array_equal(vertex_index[faces], mesh.faces)  # the user's faces and corners kept
    assert uv.min() >= 0 and uv.max() <= 1


def test_when_every_try_crashes_the_user_gets_one_line_naming_the_file(monkeypatch):
    mesh = trimesh.creation.icosphere(subdivisions=1)
    monkeypatch.setattr(xatlas, "parametrize", crash)
    user = UserMesh("chair.obj", mesh.vertices, np.asarray(mesh.faces, dtype=np.int64), None, None)
    with pytest.raises(InputError, match=r"^chair\.obj: xatlas crashed on this mesh .*--uv keep"):
        bake.mesh_atlas(user)
