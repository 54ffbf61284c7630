"""One run per output folder, and no file lost (mesh2tex/io/outputs.py).

* a second run into a folder in use stops at once, naming the first, and the first finishes intact;
* a lock left by a killed process (``kill -9``) is taken over;
* the same command re-run after an interruption continues (its own half-finished outputs are
  replaced); a finished run's results and a user's files are kept without ``--overwrite``;
* a failed run adds nothing to ``--out``; the system's refusals (a full disk, a file too large) are
  one line naming the path;
* the interrupt message prints the command that continues.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap

import pytest
import yaml
from conftest import TINY_GAN

from mesh2tex.cli import main
from mesh2tex.io.outputs import LOCK_NAME, MANIFEST_NAME, REPLACED_NAME, guard_outputs, move_aside, output_run

ENV = {**os.environ, "MESH2TEX_PROGRESS": "0", "OMP_NUM_THREADS": "1"}


def holder(folder, seconds: float = 60.0) -> subprocess.Popen:
    """A process holding ``folder`` as a run does, until killed; returns once it holds it."""
    code = textwrap.dedent(f"""
        import sys, time
        from mesh2tex.io.outputs import output_run
        with output_run({str(folder)!r}, ["prepare", "synthetic"], "mesh2tex prepare synthetic --out {folder}"):
            print("held", flush=True)
            time.sleep({seconds})
    """)
    process = subprocess.Popen([sys.executable, "-c", code], env=ENV, stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "held"
    return process


def generate_argv(gan, out, *extra):
    return [
        "infer",
        "generate",
        "--checkpoint",
        str(gan / "run" / "checkpoint.safetensors"),
        "--mesh",
        str(gan / "shapes" / "box0.npz"),
        "--out",
        str(out),
        "--seeds",
        "0,1",
        "--views",
        "1",
        "--resolution",
        "16",
        "--texture-size",
        "32",
        "--device",
        "cpu",
        *extra,
    ]


def test_a_second_run_into_a_folder_in_use_stops_at_once_and_names_the_first(tmp_path, capsys):
    out = tmp_path / "out"
    first = holder(out)
    try:
        (out / "mine.txt").write_text("the user's")
        assert main(["prepare", "synthetic", "--out", str(out), "--shapes", "3"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "in use by another mesh2tex run" in err and f"PID {first.pid}" in err, err
        assert "mesh2tex prepare synthetic" in err
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME, "mine.txt"], "the refused run wrote nothing"
    finally:
        first.kill()
        first.wait()


def test_the_lock_of_a_killed_run_is_taken_over(tmp_path):
    out = tmp_path / "out"
    first = holder(out)
    first.send_signal(signal.SIGKILL)
    first.wait()
    assert (out / LOCK_NAME).exists(), "kill -9 leaves the lock file"
    with output_run(out, ["x"], "mesh2tex x"):
        assert json.loads((out / LOCK_NAME).read_text())["pid"] == os.getpid()
    assert not (out / LOCK_NAME).exists()


def test_a_failed_run_leaves_a_new_folder_absent(tmp_path, capsys):
    out = tmp_path / "new" / "out"
    assert main(["prepare", "synthetic", "--out", str(out), "--shapes", "1"]) == 2
    assert not (tmp_path / "new").exists()


def project_with_a_users_config(tmp_path):
    out = tmp_path / "project"
    out.mkdir()
    (out / "config.yaml").write_text("my: own settings\n")
    return out


def train_argv(gan, tmp_path, out, *extra):
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(TINY_GAN))
    return [
        "train",
        "gan",
        "--shapes",
        str(gan / "shapes"),
        "--images",
        str(gan / "photos"),
        "--out",
        str(out),
        "--config",
        str(config),
        "--batch",
        "2",
        "--views",
        "2",
        "--resolution",
        "16",
        "--device",
        "cpu",
        *extra,
    ]


def test_the_same_command_continues_an_interrupted_run_and_keeps_a_finished_one(
    tiny_gan, tmp_path, capsys, monkeypatch
):
    import mesh2tex.infer.generate as stage

    out = tmp_path / "out"
    argv = generate_argv(tiny_gan, out)
    real_write = stage.TexturedMeshWriter.write
    calls = []

    def interrupted(self, *args, **kwargs):  # the first seed's files are written, then Ctrl-C
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real_write(self, *args, **kwargs)

    monkeypatch.setattr(stage.TexturedMeshWriter, "write", interrupted)
    assert main(argv) == 130
    err = capsys.readouterr().err
    assert "interrupted; re-run the same command to resume: mesh2tex infer generate" in err and "--seeds 0,1" in err
    assert (out / "seed0_view0.png").is_file() and not (out / LOCK_NAME).exists()
    monkeypatch.setattr(stage.TexturedMeshWriter, "write", real_write)
    assert main(argv) == 0, "the same command continues: the files it wrote are its own"
    assert (out / "seed1.glb").is_file()
    assert main(argv) == 2, "a finished run's results are kept"
    assert "already holds seed0" in capsys.readouterr().err
    other = generate_argv(tiny_gan, out, "--truncation", "0.5")
    assert main(other) == 2, "another command line does not own them either"
    before = (out / "seed0.glb").read_bytes()
    assert main(other + ["--overwrite"]) == 0
    err = capsys.readouterr().err
    assert "--overwrite moved seed0" in err and "aside to" in err
    # the replaced files are kept, at their own names, in the folder the warning names
    aside = err.rsplit("aside to ", 1)[1].strip()
    assert (
        os.path.dirname(aside) == str(out / REPLACED_NAME)
        and (out / REPLACED_NAME / os.path.basename(aside) / "seed0.glb").read_bytes() == before
    )


def test_train_keeps_a_users_config_yaml_and_continues_its_own_interrupted_run(tiny_gan, tmp_path, capsys):
    out = project_with_a_users_config(tmp_path)
    argv = train_argv(tiny_gan, tmp_path, out, "--iters", "2")
    assert main(argv) == 2
    assert "already holds config.yaml" in capsys.readouterr().err
    assert (out / "config.yaml").read_text() == "my: own settings\n" and sorted(p.name for p in out.iterdir()) == [
        "config.yaml"
    ]


def test_train_overwrite_moves_a_users_file_and_the_replaced_run_aside(tiny_gan, tmp_path, capsys):
    out = project_with_a_users_config(tmp_path)
    argv = train_argv(tiny_gan, tmp_path, out, "--iters", "1", "--overwrite")
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "--overwrite moved config.yaml (not written by this command) aside to" in err, err
    [first] = (out / REPLACED_NAME).iterdir()
    assert (first / "config.yaml").read_text() == "my: own settings\n"
    checkpoint = (out / "checkpoint.safetensors").read_bytes()
    assert main(argv[:-1] + ["--seed", "3", "--overwrite"]) == 0, "another run replaces this one"
    err = capsys.readouterr().err
    assert "were moved aside to" in err
    second = sorted(set((out / REPLACED_NAME).iterdir()) - {first})
    assert len(second) == 1 and (second[0] / "checkpoint.safetensors").read_bytes() == checkpoint
    assert (second[0] / "metrics.jsonl").is_file() and (out / "checkpoint.safetensors").is_file()


def test_move_aside_keeps_relative_paths_links_and_one_folder_per_run(tmp_path):
    (tmp_path / "images").mkdir()
    (tmp_path / "images" / "a.png").write_text("a")
    (tmp_path / "index.json").write_text("{}")
    os.symlink("/nonexistent/target", tmp_path / "link.png")
    with output_run(tmp_path, ["x"], "mesh2tex x"):
        first = move_aside(tmp_path, ["images/a.png", "missing.png", "link.png"])
        assert move_aside(tmp_path, ["index.json"]) == first, "one folder per run"
    assert (first / "images" / "a.png").read_text() == "a" and (first / "index.json").read_text() == "{}"
    assert os.readlink(first / "link.png") == "/nonexistent/target", "a link is moved, not followed"
    assert not (tmp_path / "images" / "a.png").exists() and not (tmp_path / "index.json").exists()
    assert move_aside(tmp_path, ["missing.png"]) is None
    (tmp_path / "index.json").write_text("{}")
    other = move_aside(tmp_path, ["index.json"])
    assert other != first and other.parent == tmp_path / REPLACED_NAME, (
        "another run (the same second) gets its own folder"
    )


def test_what_overwrite_moved_aside_is_not_taken_for_input(tmp_path, capsys):
    """A folder of photos that was once an --out: the photos moved aside are not prepared again."""
    from PIL import Image

    photos = tmp_path / "photos"
    (photos / REPLACED_NAME / "20250101-000000").mkdir(parents=True)
    Image.new("RGB", (32, 32), (200, 30, 30)).save(photos / "a.png")
    Image.new("RGB", (32, 32), (200, 30, 30)).save(photos / REPLACED_NAME / "20250101-000000" / "old.png")
    out = tmp_path / "out"
    main(["prepare", "images", "--input", str(photos), "--out", str(out), "--size", "16"])
    names = [record["name"] for record in json.loads((out / "index.json").read_text())["images"]]
    assert names == ["a"]


def test_prepare_shapes_keeps_a_users_index_json(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "index.json").write_text('{"my": "list"}')
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    assert (
        main(
            [
                "prepare",
                "shapes",
                "--input",
                str(tmp_path / "m.obj"),
                "--out",
                str(out),
                "--faces",
                "96",
                "--levels",
                "2",
            ]
        )
        == 2
    )
    assert "already holds index.json" in capsys.readouterr().err
    assert (out / "index.json").read_text() == '{"my": "list"}' and sorted(p.name for p in out.iterdir()) == [
        "index.json"
    ]


def test_guard_outside_a_run_refuses_every_existing_file(tmp_path):
    (tmp_path / "a.png").write_text("x")
    with pytest.raises(ValueError, match="already holds a.png"):
        guard_outputs(tmp_path, ["a.png", "b.png"], overwrite=False)
    assert not (tmp_path / MANIFEST_NAME).exists()


@pytest.mark.parametrize(
    "code, cause",
    [
        (errno.ENOSPC, "No space left on device"),
        (errno.EFBIG, "File too large"),
        (errno.EROFS, "Read-only file system"),
    ],
)
def test_the_systems_refusals_are_one_line_naming_the_path(code, cause, tmp_path, capsys, monkeypatch):
    """A write that fails inside an atomic write (no file name of its own) names the file being written."""
    import mesh2tex.io.atomic as atomic

    def refuse(self, data):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(atomic.Path, "write_bytes", refuse)
    renders, images = tmp_path / "r", tmp_path / "i"
    for folder in (renders, images):
        folder.mkdir()
        from PIL import Image

        Image.new("RGB", (16, 16), 128).save(folder / "a.png")
    assert (
        main(
            ["evaluate", "--renders", str(renders), "--images", str(images), "--pairs", "--out", str(tmp_path / "out")]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("mesh2tex: error: ") and str(tmp_path / "out") in err and cause in err, err


def test_a_trainer_rerun_with_the_same_command_continues_its_checkpoint(tiny_gan, tmp_path, capsys, monkeypatch):
    from mesh2tex.train import runs

    from mesh2tex.io.checkpoint import load_checkpoint

    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump({**TINY_GAN, "log_every": 1}))
    out = tmp_path / "run"
    argv = [
        "train",
        "gan",
        "--shapes",
        str(tiny_gan / "shapes"),
        "--images",
        str(tiny_gan / "photos"),
        "--out",
        str(out),
        "--config",
        str(config),
        "--iters",
        "3",
        "--batch",
        "2",
        "--views",
        "2",
        "--resolution",
        "16",
        "--device",
        "cpu",
    ]
    real_log = runs.RunDirectory.log

    def interrupted(self, record):
        real_log(self, record)
        raise KeyboardInterrupt  # after the first logged iteration: the trainer saves its checkpoint

    monkeypatch.setattr(runs.RunDirectory, "log", interrupted)
    assert main(argv) == 130
    assert "re-run the same command to resume: mesh2tex train gan" in capsys.readouterr().err
    _, meta = load_checkpoint(out / "checkpoint.safetensors")
    assert meta["iteration"] < 3
    monkeypatch.setattr(runs.RunDirectory, "log", real_log)
    assert main(argv) == 0
    assert "continuing the interrupted run" in capsys.readouterr().err
    _, meta = load_checkpoint(out / "checkpoint.safetensors")
    assert meta["iteration"] == 3
    assert main(argv) == 2, "a finished run is not started again over itself"
