"""Bad files, bad values and bad folders through the command line, counted: tracebacks, silent
results, files lost, hangs and messages over 1 kB must all be 0.

    python benchmarks/bad_inputs.py [--work DIR] [--timeout 60] [--only WORD] [--list]

The cases are not those of the test suite (``tests/test_bad_inputs.py``, ``tests/test_cli_property.py``):
other file damage, other values, other folder mishaps. A tiny GAN, an NCA model, a view network and a
two-shape world are made once under ``--work``. Each case runs ``mesh2tex.cli.main`` in a forked
process (the imports are paid once) in a folder of its own, whose ``out/`` holds a file of the user's
(and, for some cases, a file at a name the command writes). Counted per case:

* traceback: "Traceback" on stderr, or an exit status other than 0, 2, 4 and 130;
* silent result: exit 0 where the input should be refused; for an awkward input that is fine (a
  UTF-16 OBJ), no success or no line saying what was read;
* files lost: a file of the user's in ``out/`` changed or gone;
* hang: no exit within ``--timeout`` seconds (the process is killed);
* message over 1 kB: a line of stderr longer than 1024 bytes.

Exit status 0 when every count is 0.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ["MESH2TEX_PROGRESS"] = "0"

from bad_input_cases import BOX_OBJ, Case, cases, write  # noqa: E402  (this folder)
from tiny_configs import TINY_GAN, TINY_NCA  # noqa: E402  (this folder)

TINY_NCA_RUN = {**TINY_NCA, "iters": 2}
USER_FILE = "my_notes.txt"


# ---------------------------------------------------------------------------------------- fixtures
def make_fixtures(work: Path) -> dict[str, Path]:
    """The tiny models and data every case reads (made once; a few seconds of training)."""
    import trimesh
    import yaml
    from PIL import Image

    from mesh2tex.cli import main
    from mesh2tex.geometry.prepare import prepare_shape
    from mesh2tex.synthetic.exemplars import exemplar_image

    fx = {
        name: work / name
        for name in ("shapes", "photos", "gan", "nca", "pose", "world", "exemplar.png", "query.png", "box.obj")
    }
    if (work / "ready").exists():
        return fx
    fx["shapes"].mkdir(parents=True, exist_ok=True)
    for i, extents in enumerate([(1.0, 0.6, 0.4), (0.5, 1.0, 0.5)]):
        box = trimesh.creation.box(extents)
        prepare_shape(box.vertices, box.faces, face_count=96, levels=3, seed=0).save(fx["shapes"] / f"box{i}.npz")
    fx["photos"].mkdir(exist_ok=True)
    for i in range(4):
        rgba = np.zeros((16, 16, 4), np.uint8)
        rgba[4:12, 4:12] = (200, 40 * i, 30, 255)
        Image.fromarray(rgba).save(fx["photos"] / f"{i}.png")
    (work / "gan.yaml").write_text(yaml.safe_dump(TINY_GAN))
    (work / "nca.yaml").write_text(yaml.safe_dump(TINY_NCA_RUN))
    Image.fromarray(exemplar_image("stripes", 48)).save(fx["exemplar.png"])
    query = Image.new("RGBA", (48, 48), (0, 0, 0, 0))
    query.paste((220, 180, 30, 255), (14, 10, 34, 40))
    query.save(fx["query.png"])
    fx["box.obj"].write_text(BOX_OBJ)
    steps = [
        [
            "train",
            "gan",
            "--shapes",
            str(fx["shapes"]),
            "--images",
            str(fx["photos"]),
            "--out",
            str(fx["gan"]),
            "--config",
            str(work / "gan.yaml"),
            "--iters",
            "2",
            "--batch",
            "2",
            "--views",
            "2",
            "--resolution",
            "16",
            "--device",
            "cpu",
        ],
        [
            "train",
            "nca",
            "--exemplar",
            str(fx["exemplar.png"]),
            "--out",
            str(fx["nca"]),
            "--config",
            str(work / "nca.yaml"),
            "--device",
            "cpu",
        ],
        [
            "train",
            "pose",
            "--shapes",
            str(fx["shapes"]),
            "--out",
            str(fx["pose"]),
            "--iters",
            "1",
            "--samples",
            "8",
            "--resolution",
            "32",
            "--batch",
            "4",
            "--device",
            "cpu",
        ],
        [
            "prepare",
            "synthetic",
            "--out",
            str(fx["world"]),
            "--shapes",
            "2",
            "--query-shapes",
            "1",
            "--views",
            "2",
            "--resolution",
            "32",
            "--texture-size",
            "64",
            "--query-views",
            "1",
        ],
    ]
    for argv in steps:
        made = Path(argv[argv.index("--out") + 1])
        if (made / "checkpoint.safetensors").is_file() or (made / "index.json").is_file():
            continue  # made by an earlier, interrupted start
        if main(argv) != 0:
            raise SystemExit(f"fixture failed: {' '.join(argv)}")
    (work / "ready").write_text("")
    return fx


# ------------------------------------------------------------------------------------------- cases
def snapshot(folder: Path) -> dict[str, bytes]:
    return (
        {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file() and not p.is_symlink()}
        if folder.is_dir()
        else {}
    )


def run_case(case: Case, fx: dict, folder: Path, timeout: float) -> dict:
    from mesh2tex.cli import main

    folder.mkdir(parents=True)
    if case.setup is not None:
        case.setup(folder)
    out = folder / "out"
    if not out.exists():
        out.mkdir()
    write(out / USER_FILE, "the user's notes\n")
    before = snapshot(out)
    argv = case.argv(fx, folder)
    err_path = folder / "stderr.txt"
    start = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # the child: one command, its output in files
        code = 1
        try:
            os.chdir(folder)
            with open(err_path, "w") as err, open(folder / "stdout.txt", "w") as std:
                os.dup2(err.fileno(), 2)
                os.dup2(std.fileno(), 1)
                code = main(argv)
        except SystemExit as stop:
            code = stop.code if isinstance(stop.code, int) else 2
        except BaseException:
            import traceback

            traceback.print_exc()
            code = 1
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    hang = False
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.perf_counter() - start > timeout:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            hang, status = True, 9
            break
        time.sleep(0.02)
    code = os.waitstatus_to_exitcode(status) if not hang else None
    err = err_path.read_text(errors="replace") if err_path.exists() else ""
    said = err + ((folder / "stdout.txt").read_text(errors="replace") if (folder / "stdout.txt").exists() else "")
    lines = err.splitlines()
    after = snapshot(out) if out.is_dir() and not out.is_symlink() else {}
    lost = [name for name, data in before.items() if after.get(name) != data]
    traceback_seen = "Traceback" in err or (code is not None and code not in (0, 2, 4, 130))
    if case.accept is None:
        silent = code == 0
    else:
        silent = code != 0 or case.accept not in said  # an awkward input that is fine must be done, and said
    errors = [line for line in lines if line.startswith("mesh2tex: error:")]
    return {
        "case": case.name,
        "kind": case.kind,
        "exit": code,
        "seconds": round(time.perf_counter() - start, 2),
        "traceback": int(traceback_seen),
        "silent": int(bool(silent) and not hang),
        "lost": len(lost),
        "hang": int(hang),
        "long": int(any(len(line.encode()) > 1024 for line in lines)),
        "message": (errors[-1] if errors else (lines[-1] if lines else ""))[:300],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", default="/tmp/mesh2tex_bad_inputs")
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument("--only", default="", help="run the cases whose name holds this text")
    parser.add_argument("--list", action="store_true", help="print each case's result line")
    args = parser.parse_args()
    import torch

    torch.set_num_threads(1)
    work = Path(args.work)
    fx = make_fixtures(work / "fixtures")
    runs = work / f"runs-{time.strftime('%Y%m%d-%H%M%S')}"
    all_cases = [case for case in cases() if args.only in case.name]
    results = []
    start = time.perf_counter()
    for k, case in enumerate(all_cases):
        result = run_case(case, fx, runs / f"{k:03d}", args.timeout)
        results.append(result)
        bad = [key for key in ("traceback", "silent", "lost", "hang", "long") if result[key]]
        if args.list or bad:
            print(
                f"{'BAD ' + ','.join(bad) if bad else 'ok':>16}  {result['exit']!s:>4}  {case.kind:6}  {case.name}: "
                f"{result['message']}",
                flush=True,
            )
    (runs / "results.json").write_text(json.dumps(results, indent=1))
    kinds = sorted({r["kind"] for r in results})
    per_kind = ", ".join(f"{sum(r['kind'] == k for r in results)} {k}" for k in kinds)
    print(
        f"\n{len(results)} cases ({per_kind}) in {time.perf_counter() - start:.0f} s; details in "
        f"{runs / 'results.json'}\n"
    )
    print("| count | value |\n| --- | --- |")
    totals = {
        "tracebacks": "traceback",
        "silent results": "silent",
        "files lost": "lost",
        "hangs": "hang",
        "messages over 1 kB": "long",
    }
    for label, key in totals.items():
        print(f"| {label} | {sum(r[key] for r in results)} |")
    refused = sum(r["exit"] == 2 for r in results)
    print(f"| refused with exit 2 | {refused} of {len(results)} |")
    return 0 if all(sum(r[key] for r in results) == 0 for key in totals.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
