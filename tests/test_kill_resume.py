"""Interrupted runs continue, and ``--resume`` says what it has to start from.

* ``--resume FOLDER`` of a run with no checkpoint yet (or of a folder holding none) is one line
  saying so, for every trainer, and ``--out`` is not touched;
* a run started from another run's checkpoint (``--resume PATH``) and stopped before its own first
  checkpoint starts from PATH again when the same command is re-run, and says so;
* ``train nca`` and ``infer transfer`` killed with SIGKILL at moments in their work, then re-run
  with the same command (the one the interrupt message prints for SIGTERM), finish with every file
  whole: checkpoints at the last iteration, one metric line per iteration, no half-written file, no
  lock left (slow: real processes).
"""

from __future__ import annotations

import json
import os
import random
import shlex
import signal
import subprocess
import sys
import time

import pytest
import yaml
from conftest import TINY_GAN, TINY_NCA
from PIL import Image

from mesh2tex.cli import main
from mesh2tex.io.atomic import PARTIAL_DIR
from mesh2tex.io.checkpoint import load_checkpoint
from mesh2tex.io.outputs import LOCK_NAME
from mesh2tex.synthetic.exemplars import exemplar_image

ENV = {**os.environ, "OMP_NUM_THREADS": "1", "MESH2TEX_PROGRESS": "0"}
TINY_NCA_RUN = {**TINY_NCA, "iters": 8}


@pytest.fixture(scope="module")
def files(tiny_gan, tmp_path_factory):
    root = tmp_path_factory.mktemp("kill")
    Image.fromarray(exemplar_image("stripes", 48)).save(root / "stripes.png")
    (root / "nca.yaml").write_text(yaml.safe_dump(TINY_NCA_RUN))
    (root / "gan.yaml").write_text(yaml.safe_dump(TINY_GAN))
    (root / "view.yaml").write_text("width: 4\n")
    query = Image.new("RGBA", (48, 48), (0, 0, 0, 0))
    query.paste((220, 180, 30, 255), (14, 10, 34, 40))
    query.save(root / "query.png")
    return {"root": root, "gan": tiny_gan}


def train_argv(files, kind: str, out, *extra) -> list[str]:
    root, gan = files["root"], files["gan"]
    if kind == "nca":
        return [
            "train",
            "nca",
            "--exemplar",
            str(root / "stripes.png"),
            "--out",
            str(out),
            "--config",
            str(root / "nca.yaml"),
            "--device",
            "cpu",
            *extra,
        ]
    if kind == "gan":
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
            str(root / "gan.yaml"),
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
    return [
        "train",
        kind,
        "--shapes",
        str(gan / "shapes"),
        "--out",
        str(out),
        "--config",
        str(root / "view.yaml"),
        "--samples",
        "8",
        "--resolution",
        "32",
        "--batch",
        "4",
        "--device",
        "cpu",
        *extra,
    ]


@pytest.mark.parametrize("kind", ["gan", "pose", "noc", "nca"])
def test_resume_from_a_run_without_a_checkpoint_yet_is_one_line(kind, files, tmp_path, capsys):
    starting = tmp_path / "starting"
    starting.mkdir()
    (starting / "config.yaml").write_text("iters: 100\n")  # a run before its first checkpoint
    out = tmp_path / "out"
    assert main(train_argv(files, kind, out, "--iters", "1", "--resume", str(starting))) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{starting}: this run has no checkpoint.safetensors yet" in err, err
    (starting / "config.yaml").unlink()
    assert main(train_argv(files, kind, out, "--iters", "1", "--resume", str(starting))) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{starting}: no checkpoint.safetensors in this folder" in err, err
    assert not out.exists()


@pytest.mark.parametrize("kind", ["nca", "pose"])
def test_a_run_from_another_checkpoint_stopped_before_its_first_starts_from_it_again(
    kind, files, tmp_path, capsys, monkeypatch
):
    from mesh2tex.train import runs

    parent = tmp_path / "parent"
    assert main(train_argv(files, kind, parent, "--iters", "2")) == 0
    child = tmp_path / "child"
    argv = train_argv(files, kind, child, "--iters", "4", "--resume", str(parent))
    real_start = runs.RunDirectory.start

    def stopped(self, *args, **kwargs):  # its config written, no checkpoint yet: where a kill -9 can land
        real_start(self, *args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(runs.RunDirectory, "start", stopped)
    assert main(argv) == 130
    assert (child / "config.yaml").is_file() and not (child / "checkpoint.safetensors").exists()
    monkeypatch.setattr(runs.RunDirectory, "start", real_start)
    capsys.readouterr()
    assert main(argv) == 0, "the same command runs again"
    err = capsys.readouterr().err
    assert (
        f"{child}: the interrupted run of this command saved no checkpoint yet; starting from "
        f"{parent / 'checkpoint.safetensors'} again" in err
    )
    _, meta = load_checkpoint(child / "checkpoint.safetensors", kind=kind)
    assert meta["iteration"] == 4


# ------------------------------------------------------------------------------- kill -9
def python_argv(argv: list[str]) -> list[str]:
    return [sys.executable, "-m", "mesh2tex", *argv]


def killed(argv: list[str], when, timeout: float = 120.0) -> bool:
    """Run ``argv`` in a process and SIGKILL it once ``when()`` is true; False if it ended first (then
    it must have ended well)."""
    process = subprocess.Popen(python_argv(argv), env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + timeout
    while process.poll() is None and time.monotonic() < deadline:
        if when():
            process.send_signal(signal.SIGKILL)
            process.communicate()
            return True
        time.sleep(0.01)
    err = process.communicate()[1]
    assert process.returncode == 0, err
    return False


def after(path, delay: float):
    """True ``delay`` seconds after ``path`` first exists."""
    seen = []

    def ready() -> bool:
        if not seen and path.exists():
            seen.append(time.monotonic())
        return bool(seen) and time.monotonic() - seen[0] >= delay

    return ready


def no_leftovers(out) -> None:
    assert not list(out.rglob(PARTIAL_DIR)), "no half-written file left"
    assert not (out / LOCK_NAME).exists()


def lines_of(path) -> int:
    try:
        return len(path.read_text().splitlines())
    except OSError:
        return 0


@pytest.mark.slow
def test_train_nca_killed_and_rerun_with_the_same_command_finishes_whole(files, tmp_path):
    out = tmp_path / "run"
    iters = 60
    argv = train_argv(files, "nca", out, "--iters", str(iters))
    rng = random.Random(0)
    for _ in range(3):  # each re-run continues the last checkpoint and is killed a random number of iterations later
        target = lines_of(out / "metrics.jsonl") + rng.randint(1, 12)
        assert killed(argv, lambda: lines_of(out / "metrics.jsonl") >= target), "the kill lands while it trains"
    done = subprocess.run(python_argv(argv), env=ENV, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "continuing the interrupted run of this command" in done.stderr
    _, meta = load_checkpoint(out / "checkpoint.safetensors", kind="nca")
    assert meta["iteration"] == iters
    lines = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert [line["iteration"] for line in lines] == list(range(1, iters + 1)), "one line per iteration, none twice"
    assert load_checkpoint(out / "model.safetensors", kind="nca")[1]
    no_leftovers(out)


@pytest.mark.slow
def test_train_nca_stopped_by_sigterm_continues_with_the_printed_command(files, tmp_path):
    out = tmp_path / "run"
    argv = train_argv(files, "nca", out, "--iters", "40")
    process = subprocess.Popen(python_argv(argv), env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    while process.poll() is None and lines_of(out / "metrics.jsonl") < 3:
        time.sleep(0.01)
    process.send_signal(signal.SIGTERM)
    err = process.communicate()[1]
    assert process.returncode == 130, err
    printed = err.rsplit("re-run the same command to resume: ", 1)[1].splitlines()[0]
    words = shlex.split(printed)
    assert words[0] == "mesh2tex" and words[1:] == argv
    done = subprocess.run(python_argv(words[1:]), env=ENV, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert load_checkpoint(out / "checkpoint.safetensors", kind="nca")[1]["iteration"] == 40
    no_leftovers(out)


@pytest.mark.slow
def test_infer_transfer_killed_and_rerun_with_the_same_command_finishes_whole(files, tmp_path):
    import trimesh

    gan = files["gan"]
    out = tmp_path / "out"
    argv = [
        "infer",
        "transfer",
        "--checkpoint",
        str(gan / "run" / "checkpoint.safetensors"),
        "--mesh",
        str(gan / "shapes" / "box0.npz"),
        "--image",
        str(files["root"] / "query.png"),
        "--pose",
        "30,20",
        "--no-noc",
        "--out",
        str(out),
        "--resolution",
        "64",
        "--latent-iters",
        "4",
        "--refine-iters",
        "4",
        "--device",
        "cpu",
    ]
    # once mid-way (its first files written), once as it writes its last ones
    assert killed(argv, after(out / "photo_crop.png", 0.0))
    killed(argv, after(out / "turntable_00.png", 0.05))
    done = subprocess.run(python_argv(argv), env=ENV, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    report = json.loads((out / "report.json").read_text())
    assert report and trimesh.load(out / "textured.glb", force="mesh").faces.shape[0] > 0
    with Image.open(out / "comparison.png") as image:
        image.load()
    no_leftovers(out)
    again = subprocess.run(python_argv(argv), env=ENV, capture_output=True, text=True)
    assert again.returncode == 2 and "already holds" in again.stderr, "a finished run's results are kept"
