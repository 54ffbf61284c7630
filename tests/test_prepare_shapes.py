"""`mesh2tex prepare shapes`: folders, ShapeNet layout, bad inputs, index.json, resume, exit status."""

from __future__ import annotations

import json

import numpy as np
import trimesh

from mesh2tex.cli import main
from mesh2tex.geometry.prepared import PreparedShape


def make_inputs(root):
    """A small mixed folder: plain files in sub-folders, a ShapeNet-style shape, a scene and bad files."""
    (root / "misc" / "deeper").mkdir(parents=True)
    trimesh.creation.icosphere(2).export(root / "misc" / "ball.ply")
    trimesh.creation.torus(1.0, 0.4, major_sections=32, minor_sections=12).export(root / "misc" / "deeper" / "ring.off")
    shapenet = root / "03001627" / "1a2b3c" / "models"
    shapenet.mkdir(parents=True)
    trimesh.creation.box((1.0, 0.5, 0.8)).export(shapenet / "model_normalized.obj")
    trimesh.creation.box().export(shapenet / "model_normalized_extra.stl")  # ShapeNet side files are not shapes
    trimesh.Scene([trimesh.creation.box(), trimesh.creation.box().apply_translation((2, 0, 0))]).export(
        root / "pair.glb"
    )
    (root / "empty.obj").write_text("")
    (root / "garbage.ply").write_bytes(b"\x89 definitely not a ply file \x00\xff" * 8)
    (root / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n")
    (root / "notes.txt").write_text("not a mesh suffix, ignored")


def test_prepare_shapes_folder_reports_failures_and_resumes(tmp_path, capsys):
    make_inputs(tmp_path / "in")
    out = tmp_path / "out"
    argv = [
        "prepare",
        "shapes",
        "--input",
        str(tmp_path / "in"),
        "--out",
        str(out),
        "--faces",
        "96",
        "--levels",
        "2",
        "--workers",
        "2",
    ]
    assert main(argv) == 2, "a failed input gives exit status 2"

    index = json.loads((out / "index.json").read_text())
    by_name = {entry["file"]: entry for entry in index["shapes"]}
    assert set(by_name) == {
        "ball.npz",
        "ring.npz",
        "03001627_1a2b3c.npz",
        "pair.npz",
        "empty.npz",
        "garbage.npz",
        "points.npz",
    }
    for name in ("ball.npz", "ring.npz", "03001627_1a2b3c.npz", "pair.npz"):
        entry = by_name[name]
        assert entry["status"] == "ok" and len(entry["face_counts"]) == 2 and entry["seconds"] > 0
        with np.load(out / name, allow_pickle=False) as data:  # loads without pickle
            assert {
                "vertices_0",
                "quads_0",
                "neighbors_0",
                "pool_0",
                "vertices_1",
                "quads_1",
                "neighbors_1",
                "face_features",
                "feature_names",
                "metadata",
            } <= set(data.files)
            assert "pool_1" not in data.files
            assert json.loads(str(data["metadata"]))["schema_version"] == 1
        shape = PreparedShape.load(out / name)
        assert shape.face_counts == entry["face_counts"]
        assert shape.metadata["source"] == entry["source"] and "transform" in shape.metadata
    assert "empty file" in by_name["empty.npz"]["reason"]
    assert "point cloud" in by_name["points.npz"]["reason"]
    assert by_name["garbage.npz"]["reason"].startswith(str(tmp_path / "in" / "garbage.ply"))
    for name in ("empty.npz", "garbage.npz", "points.npz"):
        assert by_name[name]["status"] == "failed" and not (out / name).exists()
    assert not list(out.glob(".*partial*")), "no half-written files left"
    assert "failed" in capsys.readouterr().err

    # re-run: finished shapes are skipped (their files untouched), the bad ones are tried again
    before = {p.name: p.stat().st_mtime_ns for p in out.glob("*.npz")}
    assert main(argv) == 2
    after = {p.name: p.stat().st_mtime_ns for p in out.glob("*.npz")}
    assert before == after
    assert "4 already done" in capsys.readouterr().out


def test_prepare_shapes_all_good_exits_zero_and_files_are_named_after_inputs(tmp_path):
    trimesh.creation.box().export(tmp_path / "cube.stl")
    trimesh.creation.icosphere(2).export(tmp_path / "ball.obj")
    out = tmp_path / "out"
    code = main(
        [
            "prepare",
            "shapes",
            "--input",
            str(tmp_path / "cube.stl"),
            str(tmp_path / "ball.obj"),
            "--out",
            str(out),
            "--faces",
            "96",
            "--levels",
            "2",
            "--seed",
            "3",
        ]
    )
    assert code == 0
    assert sorted(p.name for p in out.glob("*.npz")) == ["ball.npz", "cube.npz"]
    assert PreparedShape.load(out / "cube.npz").metadata["seed"] == 3


def test_prepare_shapes_missing_input_is_one_line_error(tmp_path, capsys):
    code = main(["prepare", "shapes", "--input", str(tmp_path / "nowhere"), "--out", str(tmp_path / "out")])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("mesh2tex: error:") and "nowhere" in err


def test_two_invocations_into_one_folder_keep_every_entry(tmp_path):
    """index.json is merged under a lock: runs at once, and one after another, keep each other's shapes."""
    import os
    import subprocess
    import sys

    for name, mesh in (
        ("a1", trimesh.creation.box()),
        ("a2", trimesh.creation.icosphere(1)),
        ("b1", trimesh.creation.box((1.0, 0.5, 0.3))),
        ("b2", trimesh.creation.cylinder(0.5, 1.0, sections=12)),
    ):
        (tmp_path / name[0]).mkdir(exist_ok=True)
        mesh.export(tmp_path / name[0] / f"{name}.obj")
    out = tmp_path / "out"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MESH2TEX_PROGRESS": "0"}
    runs = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "mesh2tex",
                "prepare",
                "shapes",
                "--input",
                str(tmp_path / group),
                "--out",
                str(out),
                "--faces",
                "96",
                "--levels",
                "2",
            ],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        for group in ("a", "b")
    ]
    for run in runs:
        _, err = run.communicate(timeout=300)
        assert run.returncode == 0, err.decode()
    index = json.loads((out / "index.json").read_text())
    assert sorted(entry["file"] for entry in index["shapes"]) == ["a1.npz", "a2.npz", "b1.npz", "b2.npz"]
    assert index["ok"] == 4
    # one after another, too: a run over one group keeps the other's entries
    (tmp_path / "c").mkdir()
    trimesh.creation.box((0.3, 0.6, 0.9)).export(tmp_path / "c" / "c1.obj")
    assert (
        main(["prepare", "shapes", "--input", str(tmp_path / "c"), "--out", str(out), "--faces", "96", "--levels", "2"])
        == 0
    )
    index = json.loads((out / "index.json").read_text())
    assert sorted(entry["file"] for entry in index["shapes"]) == ["a1.npz", "a2.npz", "b1.npz", "b2.npz", "c1.npz"]
    # a later input of a name already taken gets another, and the first keeps its file
    (tmp_path / "d").mkdir()
    before = (out / "a1.npz").read_bytes()
    trimesh.creation.icosphere(2).export(tmp_path / "d" / "a1.obj")
    assert (
        main(["prepare", "shapes", "--input", str(tmp_path / "d"), "--out", str(out), "--faces", "96", "--levels", "2"])
        == 0
    )
    assert (out / "a1.npz").read_bytes() == before and (out / "d_a1.npz").is_file()
    assert (
        main(["prepare", "shapes", "--input", str(tmp_path / "a"), "--out", str(out), "--faces", "96", "--levels", "2"])
        == 0
    )
    assert (out / "a1.npz").read_bytes() == before, "a re-run keeps the names (and skips the shapes) it made"
    assert not (out / ".mesh2tex-partial").exists(), "no half-written files left"


def test_a_symlink_loop_fails_alone_and_the_mesh_beside_it_is_prepared(tmp_path, capsys):
    folder = tmp_path / "in"
    folder.mkdir()
    trimesh.creation.box().export(folder / "good.obj")
    (folder / "a.obj").symlink_to(folder / "b.obj")
    (folder / "b.obj").symlink_to(folder / "a.obj")
    out = tmp_path / "out"
    assert main(["prepare", "shapes", "--input", str(folder), "--out", str(out), "--faces", "96", "--levels", "2"]) == 2
    index = {entry["file"]: entry for entry in json.loads((out / "index.json").read_text())["shapes"]}
    assert index["good.npz"]["status"] == "ok"
    assert index["a.npz"]["status"] == "failed" and "symbolic link" in index["a.npz"]["reason"]
    assert "Traceback" not in capsys.readouterr().err


def test_a_shape_past_its_time_budget_fails_with_that_reason(tmp_path, capsys):
    trimesh.creation.icosphere(3).export(tmp_path / "ball.obj")
    out = tmp_path / "out"
    assert (
        main(
            [
                "prepare",
                "shapes",
                "--input",
                str(tmp_path / "ball.obj"),
                "--out",
                str(out),
                "--faces",
                "96",
                "--levels",
                "2",
                "--max-seconds",
                "0.001",
            ]
        )
        == 2
    )
    entry = json.loads((out / "index.json").read_text())["shapes"][0]
    assert entry["status"] == "failed" and "time budget of 0.001 s" in entry["reason"]
    assert entry["seconds"] < 30
    assert (
        main(["prepare", "shapes", "--input", str(tmp_path / "ball.obj"), "--out", str(out), "--max-seconds", "-1"])
        == 2
    )
    assert "--max-seconds -1.0: must be a positive number" in capsys.readouterr().err


def test_quadriflow_past_its_memory_budget_is_a_quad_remesh_error():
    import pytest

    from mesh2tex.geometry.quadremesh import QuadRemeshError, quadriflow

    ball = trimesh.creation.icosphere(3)
    with pytest.raises(QuadRemeshError, match="memory budget of 0.01 GiB"):
        quadriflow(ball.vertices, ball.faces, 96, memory_gb=0.01)


def test_a_hierarchy_too_coarse_for_a_chair_is_one_warning_and_recorded(tmp_path, capsys):
    """At 96 quads a chair loses parts (its seat melts into a blob): one warning line naming the file, the
    face count and a larger count to use, and the measure in index.json and the .npz; at 1536 none."""
    from mesh2tex.geometry.prepare import DEVIATION_LIMIT
    from mesh2tex.synthetic.shapes import generate_shape

    chair = generate_shape("chair", np.random.default_rng(0))
    mesh = tmp_path / "chair.obj"
    trimesh.Trimesh(chair.vertices, chair.faces, process=False).export(mesh)
    for faces, levels in ((96, 3), (1536, 3)):
        out = tmp_path / f"shapes{faces}"
        assert (
            main(
                [
                    "prepare",
                    "shapes",
                    "--input",
                    str(mesh),
                    "--out",
                    str(out),
                    "--faces",
                    str(faces),
                    "--levels",
                    str(levels),
                ]
            )
            == 0
        )
        coarse = [line for line in capsys.readouterr().err.splitlines() if "too coarse" in line]
        index = json.loads((out / "index.json").read_text())
        record = index["shapes"][0]["coarseness"]
        assert PreparedShape.load(out / "chair.npz").metadata["coarseness"] == record
        if faces == 96:
            assert len(coarse) == 1 and coarse[0].startswith(f"mesh2tex: warning: {mesh}: 96 faces are too coarse"), (
                coarse
            )
            assert f"at least {record['suggested_faces']} faces" in coarse[0] and record["suggested_faces"] > 96
            assert record["too_coarse"] and record["deviation"] > DEVIATION_LIMIT and index["too_coarse"] == 1
        else:
            assert coarse == [] and not record["too_coarse"] and record["deviation"] < DEVIATION_LIMIT / 2
            assert record["suggested_faces"] is None and index["too_coarse"] == 0


def test_overwrite_prepares_every_shape_again(tmp_path):
    """Without --overwrite a shape already prepared in --out is skipped; with it, it is prepared again
    and its file replaced (a file of the user's beside them stays)."""
    import trimesh

    trimesh.creation.box().export(tmp_path / "cube.stl")
    out = tmp_path / "out"
    args = [
        "prepare",
        "shapes",
        "--input",
        str(tmp_path / "cube.stl"),
        "--out",
        str(out),
        "--faces",
        "96",
        "--levels",
        "2",
    ]
    assert main(args) == 0
    (out / "notes.txt").write_text("mine")
    first = (out / "cube.npz").stat().st_mtime_ns
    assert main(args) == 0 and (out / "cube.npz").stat().st_mtime_ns == first
    assert main([*args, "--overwrite"]) == 0
    assert (out / "cube.npz").stat().st_mtime_ns != first and (out / "notes.txt").read_text() == "mine"
    assert json.loads((out / "index.json").read_text())["ok"] == 1


def _die_on_second(source: str, *rest):
    """A stand-in for prepare_one whose worker is killed (as by the system) on the shape named "b"."""
    import os
    import time

    if source == "b":
        time.sleep(0.5)  # let "a" finish first
        os._exit(9)
    return {"source": source, "status": "ok"}


def test_a_worker_killed_from_outside_is_one_error_naming_the_shape_and_keeps_the_finished_ones():
    import pytest

    from data_prep.shapes import _prepare_all
    from mesh2tex.errors import UserError

    finished = []

    class Bar:
        def update(self, n):
            pass

    with pytest.raises(UserError) as caught:
        _prepare_all([("a",), ("b",)], 2, lambda record, bar: finished.append(record["source"]), Bar(), _die_on_second)
    assert finished == ["a"]
    message = str(caught.value)
    assert "preparing b " in message and "killed" in message and "run the same command again" in message
