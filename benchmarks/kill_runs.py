"""``kill -9`` at random moments of every long command (``prepare shapes``, ``train gan``, ``train nca``,
``infer transfer``); every re-run of the same command must continue, and nothing may be damaged.

    python benchmarks/kill_runs.py [--kills 20] [--seed 0] [--work DIR]

A tiny world is made under ``--work``: two prepared boxes and four photos (``train gan``), a tiny GAN
checkpoint trained for 2 iterations and a query photo (``infer transfer``), an exemplar and a small
automaton config on a sphere (``train nca``), and a folder of meshes (``prepare shapes``).

Rounds alternate among the four commands. A round starts one command in a fresh process and sends
it SIGKILL: in half the rounds at a random moment up to the time of its last output in its last whole
run (start-up, a step, the transfer's optimisation, a write), in the other half at a random moment
between its first output and its last (checkpoints, metric lines, samples, shapes, the transfer's
files). A command killed is re-run in its next round with exactly the same command line, the one the
interrupt message prints, which must continue its work. A command that finished is given more work:
``train gan`` 6 more iterations and ``train nca`` 20 more (``--resume``), ``prepare shapes`` two more
meshes, ``infer transfer`` the same transfer again into the same folder (``--overwrite``: the folder
holds a finished result, which is kept without it). A kill that lands after the run recorded itself
finished (as the process exits) is counted apart: its re-run may say the results are kept. Rounds go
on until ``--kills`` kills landed in EACH command; then each command runs once more to the end, and
a transfer without ``--overwrite`` must be refused (the finished result is kept).

Printed per command: the kills landed (and how many after the round had written a file), the runs
not killed that finished, the outputs that load (checkpoints at the last iteration, prepared shapes
and their ``index.json`` entries, the transfer's ``textured.glb`` through trimesh, ``report.json``,
``comparison.png``), half-written files left (``.mesh2tex-partial`` folders), duplicate or
out-of-order ``metrics.jsonl`` lines, and locks left behind (``.mesh2tex-lock``). Exit status 0 when
every count is as it should be.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
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
from mesh2tex.io.outputs import LOCK_NAME, MANIFEST_NAME, REPLACED_NAME, run_key  # noqa: E402
from mesh2tex.synthetic.exemplars import exemplar_image  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tiny_configs import TINY_DISCRIMINATOR, TINY_GAN, TINY_GENERATOR, TINY_NCA  # noqa: E402  (this folder)

NAMES = ("prepare shapes", "train gan", "train nca", "infer transfer")
TINY_GAN_RUN = {**TINY_GAN, "sample_every": 2}
# the checkpoint the transfer starts from: trained once, never killed
TRANSFER_GAN = {
    "sample_every": 0,
    "checkpoint_every": 0,
    "generator": TINY_GENERATOR,
    "discriminator": TINY_DISCRIMINATOR,
}
# a checkpoint every iteration and a sample every 5: a kill lands in a write as often as in a step
TINY_NCA_RUN = {**TINY_NCA, "sample_every": 5}
GAN_STEP, NCA_STEP = 6, 20  # iterations asked for by each new job
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "MESH2TEX_PROGRESS": "0"}


def mesh2tex(*words) -> list[str]:
    return [sys.executable, "-m", "mesh2tex", *map(str, words)]


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
    (work / "tiny.yaml").write_text(yaml.safe_dump(TINY_GAN_RUN))
    (work / "transfer_gan.yaml").write_text(yaml.safe_dump(TRANSFER_GAN))
    (work / "nca.yaml").write_text(yaml.safe_dump(TINY_NCA_RUN))
    Image.fromarray(exemplar_image("stripes", 48)).save(work / "stripes.png")
    query = Image.new("RGBA", (48, 48), (0, 0, 0, 0))
    query.paste((220, 180, 30, 255), (14, 10, 34, 40))
    query.save(work / "query.png")
    (work / "meshes").mkdir(exist_ok=True)
    done = subprocess.run(
        mesh2tex(
            "train",
            "gan",
            "--shapes",
            work / "shapes",
            "--images",
            work / "photos",
            "--out",
            work / "transfer_gan",
            "--config",
            work / "transfer_gan.yaml",
            "--iters",
            2,
            "--batch",
            2,
            "--views",
            2,
            "--resolution",
            16,
            "--device",
            "cpu",
        ),
        env=ENV,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise SystemExit(f"the transfer's GAN checkpoint: {done.stderr.strip()}")


def add_mesh(work: Path, index: int) -> None:
    """One more input mesh for ``prepare shapes``."""
    rng = np.random.default_rng(index)
    mesh = [
        trimesh.creation.box(rng.uniform(0.3, 1.0, 3)),
        trimesh.creation.icosphere(1),
        trimesh.creation.cylinder(0.5, 1.0, sections=12),
        trimesh.creation.capsule(0.6, 0.3),
    ][index % 4]
    mesh.export(work / "meshes" / f"m{index:03d}.obj")


class Jobs:
    """The command line of each command's current job, and the next job once one finished."""

    def __init__(self, work: Path):
        self.work = work
        self.gan_iters = self.nca_iters = self.meshes = self.transfers = 0
        self.argv: dict[str, list[str]] = {}
        for name in NAMES:
            self.next(name)

    def out(self, name: str) -> Path:
        return (
            self.work
            / {"prepare shapes": "prepared", "train gan": "run", "train nca": "nca", "infer transfer": "transfer"}[name]
        )

    def next(self, name: str) -> None:
        """More work for ``name`` (its last job finished)."""
        work, out = self.work, self.out(name)
        if name == "prepare shapes":
            for _ in range(2):  # two: a kill can land between the two shapes' writes
                add_mesh(work, self.meshes)
                self.meshes += 1
            argv = mesh2tex("prepare", "shapes", "--input", work / "meshes", "--out", out, "--faces", 96, "--levels", 2)
        elif name == "train gan":
            self.gan_iters += GAN_STEP  # the first job a new run, later ones continue the finished run
            resume = ["--resume"] if self.gan_iters > GAN_STEP else []
            argv = mesh2tex(
                "train",
                "gan",
                "--shapes",
                work / "shapes",
                "--images",
                work / "photos",
                "--out",
                out,
                "--config",
                work / "tiny.yaml",
                "--iters",
                self.gan_iters,
                *"--batch 2 --views 2 --resolution 16 --device cpu".split(),
                *resume,
            )
        elif name == "train nca":
            self.nca_iters += NCA_STEP
            argv = mesh2tex(
                "train",
                "nca",
                "--exemplar",
                work / "stripes.png",
                "--out",
                out,
                "--config",
                work / "nca.yaml",
                "--iters",
                self.nca_iters,
                "--device",
                "cpu",
                *(["--resume"] if self.nca_iters > NCA_STEP else []),
            )
        else:
            self.transfers += 1  # the first into an empty folder, later ones replace the finished result
            argv = self.transfer_argv(overwrite=self.transfers > 1)
        self.argv[name] = argv

    def transfer_argv(self, overwrite: bool) -> list[str]:
        work = self.work
        checkpoint, mesh = work / "transfer_gan" / "checkpoint.safetensors", work / "shapes" / "box0.npz"
        fast = "--resolution 64 --latent-iters 4 --refine-iters 4 --device cpu".split()
        return mesh2tex(
            "infer",
            "transfer",
            "--checkpoint",
            checkpoint,
            "--mesh",
            mesh,
            "--image",
            work / "query.png",
            "--pose",
            "30,20",
            "--no-noc",
            "--out",
            self.out("infer transfer"),
            *fast,
            *(["--overwrite"] if overwrite else []),
        )


def output_times(folder: Path, since: int) -> tuple[int, int]:
    """(oldest, newest) modification time (ns) of the outputs under ``folder`` written since ``since``
    (0, 0 when none): not the lock, the manifest, the config every run writes as it starts, nor what
    ``--overwrite`` moved aside."""
    times = []
    for root, dirs, files in os.walk(folder):
        dirs[:] = [d for d in dirs if d != REPLACED_NAME]
        for name in files:
            if name in (LOCK_NAME, MANIFEST_NAME, "config.yaml"):
                continue
            try:
                times.append(os.stat(os.path.join(root, name)).st_mtime_ns)
            except OSError:  # removed while we looked
                pass
    times = [t for t in times if t >= since]
    return (min(times), max(times)) if times else (0, 0)


def recorded_finished(out: Path, argv: list[str], since: int) -> bool:
    """Whether the run of ``argv`` in ``out`` started at ``since`` (ns) recorded itself finished: a kill
    that lands after that, as the process exits, finds the work done, and a re-run of the same command
    keeps the results. (A record older than ``since`` is an earlier run's of the same command line.)"""
    try:
        if (out / MANIFEST_NAME).stat().st_mtime_ns < since:
            return False
        runs = json.loads((out / MANIFEST_NAME).read_text())["runs"]
    except (OSError, ValueError, KeyError):
        return False
    return runs.get(run_key(argv[3:]), {}).get("finished") is True


@dataclasses.dataclass
class Outcome:
    code: int | None  # the exit status, None when killed
    line: str  # the last line of stderr
    started: int  # time.time_ns() at its start
    first_output: float | None  # seconds from the start to its first output (a file it wrote), None: none
    last_output: float | None  # seconds from the start to its last output


def run(argv: list[str], out: Path, kill_after: float | None) -> Outcome:
    """Run ``argv`` (its outputs under ``out``) and send it SIGKILL ``kill_after`` seconds after its
    start (None: let it end)."""
    before = time.time_ns()
    with tempfile.TemporaryFile("w+") as err:
        process = subprocess.Popen(argv, env=ENV, stdout=subprocess.DEVNULL, stderr=err, text=True)
        try:
            process.wait(timeout=kill_after)
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGKILL)
            process.wait()
            code = None
        else:
            code = process.returncode
        err.seek(0)
        lines = err.read().strip().splitlines()
    first, last = output_times(out, before)
    seconds = lambda t: (t - before) / 1e9 if t else None
    return Outcome(code, lines[-1] if lines and code is not None else "", before, seconds(first), seconds(last))


def metric_faults(path: Path, iters: int) -> tuple[int, int, bool]:
    """(duplicate or out-of-order lines, lines, whether they count 1..iters) of a metrics.jsonl."""
    lines = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    iterations = [record["iteration"] for record in lines]
    faults = len(iterations) - len(set(iterations)) + sum(b <= a for a, b in zip(iterations, iterations[1:]))
    return faults, len(lines), iterations == list(range(1, iters + 1))


def loads(check) -> int:
    """1 when ``check()`` reads the output and finds it right, else 0 (and why, on stderr)."""
    try:
        return int(bool(check()))
    except Exception as error:  # any failure to read is what this counts
        print(f"  does not load: {type(error).__name__}: {str(error)[:200]}", file=sys.stderr)
        return 0


def image_loads(path: Path) -> bool:
    with Image.open(path) as image:
        image.load()
    return True


def audit(jobs: Jobs) -> tuple[dict[str, dict[str, str]], list[str]]:
    """Per command, the printed counts of what it left (outputs that load, half-written files, metric
    faults, locks), and the list of what is wrong."""
    rows: dict[str, dict[str, str]] = {}
    wrong: list[str] = []
    for name in NAMES:
        out = jobs.out(name)
        partial, locks = sum(1 for _ in out.rglob(PARTIAL_DIR)), sum(1 for _ in out.rglob(LOCK_NAME))
        row = {
            "outputs that load": "",
            "half-written files left": str(partial),
            "duplicate or out-of-order metric lines": "-",
            "locks left": str(locks),
        }
        wrong += [f"{name}: half-written files left"] * (partial > 0) + [f"{name}: locks left"] * (locks > 0)
        if name == "prepare shapes":
            index = json.loads((out / "index.json").read_text())
            shapes = sum(loads(lambda p=p: PreparedShape.load(p).num_levels == 2) for p in out.glob("*.npz"))
            good, total = shapes + index["ok"], 2 * jobs.meshes
            row["outputs that load"] = (
                f"{good} of {total} ({shapes} shapes + {index['ok']} index entries ok, {jobs.meshes} meshes)"
            )
        elif name in ("train gan", "train nca"):
            kind, iters = ("gan", jobs.gan_iters) if name == "train gan" else ("nca", jobs.nca_iters)
            faults, lines, whole = metric_faults(out / "metrics.jsonl", iters)
            row["duplicate or out-of-order metric lines"] = f"{faults} ({lines} lines for {iters} iterations)"
            wrong += [f"{name}: metrics.jsonl does not count 1..{iters} once each"] * (faults > 0 or not whole)
            files = ["checkpoint.safetensors"] + (["model.safetensors"] if kind == "nca" else [])
            good, total = (
                sum(loads(lambda f=f: load_checkpoint(out / f, kind=kind)[1]["iteration"] == iters) for f in files),
                len(files),
            )
            row["outputs that load"] = f"{good} of {total} ({' and '.join(files)} at iteration {iters})"
        else:
            good = (
                loads(lambda: trimesh.load(out / "textured.glb", force="mesh").faces.shape[0] > 0)
                + loads(lambda: "seconds" in json.loads((out / "report.json").read_text()))
                + loads(lambda: image_loads(out / "comparison.png"))
            )
            total = 3
            row["outputs that load"] = f"{good} of {total} (textured.glb in trimesh, report.json, comparison.png)"
        wrong += [f"{name}: outputs that do not load"] * (good != total)
        rows[name] = row
    return rows, wrong


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=20, help="kills to land in each command")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--work", default="kill_runs_work")
    args = parser.parse_args()
    work = Path(args.work)
    if work.exists():
        raise SystemExit(f"{work}: exists; give a new --work folder")
    start = time.perf_counter()
    make_world(work)
    jobs = Jobs(work)
    rng = random.Random(args.seed)
    killed = dict.fromkeys(NAMES, 0)  # kills that landed before the run had finished its work
    in_work = dict.fromkeys(NAMES, 0)  # of those, kills after the round had written an output
    late = dict.fromkeys(NAMES, 0)  # kills after the run had recorded itself finished, as it exited (not counted above)
    kept = dict.fromkeys(NAMES, 0)  # re-runs after those, refused because the finished results are kept
    finished = dict.fromkeys(NAMES, 0)
    failed = dict.fromkeys(NAMES, 0)
    # of its last whole run: seconds to its first and its last output
    first_output, last_output = dict.fromkeys(NAMES, 5.0), dict.fromkeys(NAMES, 7.0)
    state = dict.fromkeys(
        NAMES, "new"
    )  # of the current job: new, killed (before its end), late (killed after it), done
    rounds = 0

    def one_run(name: str, kill_after: float | None) -> None:
        if state[name] == "done":
            jobs.next(name)  # more work; after a kill, the same command line again
        outcome = run(jobs.argv[name], jobs.out(name), kill_after)
        code, line = outcome.code, outcome.line
        if code is None and recorded_finished(jobs.out(name), jobs.argv[name], outcome.started):
            late[name] += 1
            state[name] = "late"
        elif code is None:
            killed[name] += 1
            in_work[name] += outcome.first_output is not None
            state[name] = "killed"
        elif code == 2 and "already holds" in line and state[name] == "late":
            kept[name] += 1
            state[name] = "done"
        elif code == 0:
            finished[name] += 1
            if (
                state[name] in ("new", "done") and outcome.first_output and outcome.last_output
            ):  # a whole job: it times the next kills
                first_output[name], last_output[name] = (
                    outcome.first_output,
                    max(outcome.last_output, outcome.first_output),
                )
            state[name] = "done"
        else:
            failed[name] += 1
            print(f"{name} exit {code}: {line}", file=sys.stderr)
            state[name] = "done"

    while any(killed[name] < args.kills for name in NAMES) and rounds < 8 * args.kills:
        for name in NAMES:
            if killed[name] < args.kills:
                # half the kills at any moment up to its last output (in start-up, a step, the transfer's optimisation),
                # half while it writes (from its first output to its last: checkpoints, samples,
                # shapes, the transfer's files)
                anywhere = rng.random() < 0.5
                one_run(
                    name,
                    rng.uniform(0.2, 1.0) * last_output[name]
                    if anywhere
                    else first_output[name] + rng.uniform(0.0, 1.0) * (last_output[name] - first_output[name]),
                )
                rounds += 1
    for name in NAMES:  # once more to the end: a killed job continued, a finished one given more work
        if state[name] == "late":
            one_run(name, None)  # refused (the results kept) or continued
        one_run(name, None)
    outcome = run(
        jobs.transfer_argv(overwrite=False), jobs.out("infer transfer"), None
    )  # a finished transfer is kept without --overwrite
    code, line = outcome.code, outcome.line
    result_kept = code == 2 and "already holds" in line
    rows, wrong = audit(jobs)
    table = {
        name: {
            "kills landed": f"{killed[name]} ({in_work[name]} after the round had written an output)",
            "kills as it exited, its work done": f"{late[name]} (re-runs told the results are kept: {kept[name]})",
            "runs not killed that finished": f"{finished[name]} of {finished[name] + failed[name]}",
            **rows[name],
        }
        for name in NAMES
    }
    for name in NAMES:
        print(f"{name}:")
        for key, value in table[name].items():
            print(f"  {key:40s} {value}")
    print(
        "infer transfer without --overwrite after it finished: "
        f"{'refused, the result kept' if result_kept else f'exit {code}: {line}'}"
    )
    print(
        f"({time.perf_counter() - start:.0f} s; {rounds} rounds; train gan to {jobs.gan_iters} iterations, train nca "
        f"to {jobs.nca_iters}, {jobs.meshes} meshes prepared, {jobs.transfers} transfers started)"
    )
    wrong += [f"{name}: {killed[name]} kills landed" for name in NAMES if killed[name] < args.kills]
    wrong += [f"{name}: {failed[name]} runs not killed failed" for name in NAMES if failed[name]]
    wrong += [f"{name}: the last run did not finish" for name in NAMES if state[name] != "done"]
    wrong += [] if result_kept else ["infer transfer: a finished result not kept without --overwrite"]
    for problem in wrong:
        print(f"WRONG: {problem}")
    return 1 if wrong else 0


if __name__ == "__main__":
    sys.exit(main())
