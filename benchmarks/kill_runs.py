"""``kill -9`` at random moments of ``train gan`` and ``prepare shapes``; then every re-run must finish
with nothing damaged, no half-written file left and no duplicate metric line.

    python benchmarks/kill_runs.py [--kills 20] [--seed 0] [--work DIR]

A tiny world is made under ``--work`` (two prepared boxes, four photos, meshes). Each round starts
a command in a fresh process on the same folders and sends it SIGKILL after a random delay; the
rounds alternate between the two commands, and each round asks for more work (``train gan``: 6 more
iterations, resumed; ``prepare shapes``: one more mesh), so that a kill lands while it works, in
start-up, in a step, a checkpoint, a sample or a shape. Rounds go on until ``--kills`` kills landed.
Then each command is run once more to the end. Printed: the kills, the re-runs that finished, the checkpoints and prepared shapes that
load, the half-written files left (``.mesh2tex-partial`` folders), and duplicate or out-of-order
``metrics.jsonl`` lines. Exit status 0 when every count is as it should be.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import trimesh
import yaml
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mesh2tex.geometry.prepare import prepare_shape  # noqa: E402
from mesh2tex.geometry.prepared import PreparedShape  # noqa: E402
from mesh2tex.io.atomic import PARTIAL_DIR  # noqa: E402
from mesh2tex.io.checkpoint import load_checkpoint  # noqa: E402

TINY = {"sample_every": 2, "checkpoint_every": 2, "log_every": 1, "sample_shapes": 2,
        "generator": {"z_dim": 16, "w_dim": 16, "mapping_layers": 2, "encoder_channels": [8, 8, 8], "synthesis_channels": [8, 8, 8],
                      "field_hidden": 16, "aux_latent_dim": 8},
        "discriminator": {"channel_base": 64, "channel_max": 16}, "loss": {"r1_interval": 2, "pl_interval": 2}}


def make_world(work: Path) -> None:
    (work / "shapes").mkdir(parents=True, exist_ok=True)
    for i, extents in enumerate([(1.0, 0.6, 0.4), (0.5, 1.0, 0.5)]):
        box = trimesh.creation.box(extents)
        prepare_shape(box.vertices, box.faces, face_count=96, levels=3, seed=0).save(work / "shapes" / f"box{i}.npz")
    (work / "photos").mkdir(exist_ok=True)
    for i in range(4):
        rgba = np.zeros((16, 16, 4), np.uint8)
        rgba[4:12, 4:12] = (200, 40 * i, 30, 255)
        Image.fromarray(rgba).save(work / "photos" / f"{i}.png")
    (work / "tiny.yaml").write_text(yaml.safe_dump(TINY))
    (work / "meshes").mkdir(exist_ok=True)


def add_mesh(work: Path, index: int) -> None:
    """One more input mesh for ``prepare shapes``."""
    rng = np.random.default_rng(index)
    mesh = [trimesh.creation.box(rng.uniform(0.3, 1.0, 3)), trimesh.creation.icosphere(1), trimesh.creation.cylinder(0.5, 1.0, sections=12),
            trimesh.creation.capsule(0.6, 0.3)][index % 4]
    mesh.export(work / "meshes" / f"m{index:03d}.obj")


def commands(work: Path, iters: int) -> dict[str, list[str]]:
    python = [sys.executable, "-m", "mesh2tex"]
    return {
        "train gan": python + ["train", "gan", "--shapes", str(work / "shapes"), "--images", str(work / "photos"), "--out", str(work / "run"),
                               "--config", str(work / "tiny.yaml"), "--iters", str(iters), "--batch", "2", "--views", "2",
                               "--resolution", "16", "--device", "cpu", "--resume"],
        "prepare shapes": python + ["prepare", "shapes", "--input", str(work / "meshes"), "--out", str(work / "prepared"),
                                    "--faces", "96", "--levels", "2"],
    }


def run(argv: list[str], kill_after: float | None) -> int | None:
    """The exit status, or None when the process was killed."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MESH2TEX_PROGRESS": "0"}
    process = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        process.wait(timeout=kill_after)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGKILL)
        process.wait()
        return None
    if process.returncode != 0:
        print(process.stderr.read().decode(errors="replace").strip().splitlines()[-1:], file=sys.stderr)
    return process.returncode


def audit(work: Path, iters: int, meshes: int) -> dict[str, int]:
    leftovers = sum(1 for _ in work.rglob(PARTIAL_DIR))
    lines = [json.loads(line) for line in (work / "run" / "metrics.jsonl").read_text().splitlines() if line.strip()]
    iterations = [record["iteration"] for record in lines]
    duplicates = len(iterations) - len(set(iterations)) + sum(b <= a for a, b in zip(iterations, iterations[1:]))
    _, meta = load_checkpoint(work / "run" / "checkpoint.safetensors", kind="gan")
    index = json.loads((work / "prepared" / "index.json").read_text())
    shapes = sum(1 for path in (work / "prepared").glob("*.npz") if PreparedShape.load(path).num_levels == 2)
    assert meshes == len(list((work / "meshes").glob("*.obj")))
    return {"half-written files left": leftovers, "duplicate or out-of-order metric lines": duplicates,
            "checkpoint at the last iteration": int(meta["iteration"] == iters), "metric lines": len(lines),
            "prepared shapes that load": shapes, "index entries ok": index["ok"]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--work", default="kill_runs_work")
    args = parser.parse_args()
    work = Path(args.work)
    if work.exists():
        raise SystemExit(f"{work}: exists; give a new --work folder")
    make_world(work)
    rng = random.Random(args.seed)
    killed = {"train gan": 0, "prepare shapes": 0}
    iters, meshes, rounds = 0, 0, 0
    start = time.perf_counter()
    while sum(killed.values()) < args.kills and rounds < 4 * args.kills:
        name = list(killed)[rounds % 2]
        if name == "train gan":
            iters += 6
        else:
            add_mesh(work, meshes)
            meshes += 1
        if run(commands(work, iters)[name], rng.uniform(1.0, 10.0)) is None:
            killed[name] += 1
        rounds += 1
    finished = {name: int(run(commands(work, iters)[name], None) == 0) for name in killed}
    counts = {**{f"killed: {name}": n for name, n in killed.items()}, **{f"re-run finished: {name}": n for name, n in finished.items()},
              **audit(work, iters, meshes)}
    for key, value in counts.items():
        print(f"{key:42s} {value}")
    print(f"({time.perf_counter() - start:.0f} s; {rounds} rounds; train gan to {iters} iterations, {meshes} meshes)")
    good = (all(finished.values()) and counts["half-written files left"] == 0 and counts["duplicate or out-of-order metric lines"] == 0
            and counts["checkpoint at the last iteration"] == 1 and counts["metric lines"] == iters
            and counts["prepared shapes that load"] == meshes and counts["index entries ok"] == meshes)
    return 0 if good else 1


if __name__ == "__main__":
    sys.exit(main())
