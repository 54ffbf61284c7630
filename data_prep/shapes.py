"""``mesh2tex prepare shapes``: turn mesh files and folders into prepared quad-mesh hierarchies (.npz).

Inputs are mesh files (.obj .ply .off .stl .glb .gltf) and folders searched recursively, the
ShapeNetCore v2 layout ``<synset>/<id>/models/model_normalized.obj`` included (such a shape is named
``<synset>_<id>``). One ``<name>.npz`` per shape goes to ``--out`` with ``index.json`` listing every
input, its status (ok or failed), the reason of a failure, per level the faces, the ratio to the finer
level and the method that made it, warnings (a level made by a fallback, a hierarchy too coarse to keep
the shape's parts), ``coarseness`` (how far the input's surface lies from the finest level, see
:func:`mesh2tex.geometry.prepare.coarseness_check`) and seconds.
Finished shapes are skipped on a re-run, so an interrupted run resumes. Exit status 0 when every
input succeeded, 2 when any failed.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import re
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from mesh2tex.errors import InputError, UserError
from mesh2tex.io.atomic import locked, write_json
from mesh2tex.io.outputs import guard_outputs, walked
from mesh2tex.progress import JsonLines, progress_bar


def find_meshes(inputs: list[str]) -> list[Path]:
    """Mesh files named directly or found under folders (sorted, duplicates removed).

    In a ShapeNetCore v2 folder only ``models/model_normalized.obj`` of each shape is taken.
    Raises UserError for an input path that does not exist.
    """
    from mesh2tex.geometry.mesh_io import is_mesh_file

    found: list[Path] = []
    for item in inputs:
        path = Path(item)
        if not path.exists():
            raise UserError(f"{path}: no such file or folder")
        if path.is_file():
            found.append(path)
            continue
        for root, dirs, files in os.walk(path):
            dirs[:] = walked(dirs)  # not what --overwrite moved aside
            root_path = Path(root)
            if root_path.name == "models" and "model_normalized.obj" in files:
                found.append(root_path / "model_normalized.obj")  # ShapeNet: ignore the other files beside it
                continue
            found.extend(root_path / name for name in sorted(files) if is_mesh_file(name))
    unique, seen = [], set()
    for path in found:
        key = os.path.realpath(path)  # never raises, not even for a symbolic-link loop
        if key not in seen:
            seen.add(key)
            unique.append(path)
    return unique


def shape_name(path: Path) -> str:
    """Output name of a mesh: its stem, or ``<synset>_<id>`` for ShapeNet's model_normalized.obj."""
    if path.name == "model_normalized.obj" and path.parent.name == "models" and len(path.parents) >= 3:
        stem = f"{path.parents[2].name}_{path.parents[1].name}"
    else:
        stem = path.stem
    return re.sub(r"[^A-Za-z0-9_.-]", "_", stem) or "shape"


def assign_names(paths: list[Path], earlier: dict[str, str] | None = None) -> dict[Path, str]:
    """Unique output names: a repeated name gets its parent folder's name, then a counter.

    ``earlier`` maps the sources an earlier run into the same folder prepared to their names: such a
    source keeps its name, and no other input takes one of them."""
    earlier = earlier or {}
    names: dict[Path, str] = {}
    used: set[str] = set(earlier.values())
    for path in paths:
        if str(path) in earlier:
            names[path] = earlier[str(path)]
            continue
        name = shape_name(path)
        if name in used:
            name = f"{re.sub(r'[^A-Za-z0-9_.-]', '_', path.parent.name)}_{name}"
        base, counter = name, 1
        while name in used:
            counter += 1
            name = f"{base}_{counter}"
        used.add(name)
        names[path] = name
    return names


def prepare_one(
    path: str,
    output: str,
    faces: int,
    levels: int,
    seed: int,
    max_seconds: float | None = None,
    max_memory_gb: float | None = None,
    up: str = "auto",
) -> dict:
    """Load, prepare and save one shape (within the budgets given); returns its index record (never raises for a bad
    input)."""
    from mesh2tex.geometry.mesh_io import load_user_mesh
    from mesh2tex.geometry.prepare import prepare_user_mesh

    start = time.perf_counter()
    record = {"source": path, "file": Path(output).name}
    try:
        mesh = load_user_mesh(path, up)
        record["up"] = mesh.up
        shape = prepare_user_mesh(
            mesh, face_count=faces, levels=levels, seed=seed, max_seconds=max_seconds, max_memory_gb=max_memory_gb
        )
        shape.save(output)
        levels = shape.metadata["levels"]
        record.update(
            status="ok",
            reason="",
            face_counts=shape.face_counts,
            methods=[level["method"] for level in levels],
            levels=[{"faces": level["faces"], "ratio": level["ratio"], "method": level["method"]} for level in levels],
            warnings=list(shape.metadata["warnings"]),
            coarseness=shape.metadata["coarseness"],
        )
    except InputError as error:
        message = str(error)
        record.update(
            status="failed", reason=message if message.startswith(path) else f"{path}: {message}", face_counts=[]
        )
    except Exception as error:  # a bug or an unforeseen input: reported, the batch goes on
        record.update(status="failed", reason=f"{path}: unexpected {error.__class__.__name__}: {error}", face_counts=[])
    record["seconds"] = round(time.perf_counter() - start, 3)
    return record


INDEX_LOCK = ".index.json.lock"  # held while index.json is read, merged and rewritten


def read_index(index_path: Path, settings: dict) -> tuple[dict[str, dict], dict | None]:
    """({source: entry} of ``index_path`` when it was written with ``settings``, else {}; the other
    settings when they differ and it lists shapes). A missing or damaged index is empty."""
    try:
        old = json.loads(index_path.read_text())
        entries = {entry["source"]: entry for entry in old.get("shapes", [])}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}, None
    if old.get("settings") != settings:
        return {}, (old.get("settings") if entries else None)
    return entries, None


def is_shape_index(path: Path) -> bool:
    """Whether ``path`` is an index written by ``prepare shapes`` (its runs into one folder share it)."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and isinstance(data.get("settings"), dict) and isinstance(data.get("shapes"), list)


def _settings(args) -> dict:
    settings = {"faces": int(args.faces), "levels": int(args.levels), "seed": int(args.seed)}
    if args.up != "auto":  # the default keeps the settings of indexes written before --up
        settings["up"] = args.up
    return settings


def _check_options(args) -> None:
    """UserError for options that cannot work, before any work."""
    from mesh2tex.geometry.prepare import level_face_counts

    level_face_counts(args.faces, args.levels)
    if args.workers < 1:
        raise UserError(f"--workers must be at least 1 (got {args.workers})")
    for flag, value in (("--max-seconds", args.max_seconds), ("--max-memory-gb", args.max_memory_gb)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise UserError(f"{flag} {value}: must be a positive number")


def _index_document(settings: dict, shapes: list[dict]) -> dict:
    """index.json: the settings, every shape's record and the counts a reader checks first."""
    return {
        "settings": settings,
        "shapes": shapes,
        "ok": sum(r["status"] == "ok" for r in shapes),
        "failed": sum(r["status"] == "failed" for r in shapes),
        "with_warnings": sum(bool(r.get("warnings")) for r in shapes),
        "too_coarse": sum(bool((r.get("coarseness") or {}).get("too_coarse")) for r in shapes),
    }


def _prepare_all(jobs: list[tuple], workers: int, finish, bar, work=None) -> None:
    """``work`` (:func:`prepare_one` unless given) on every job, in this process or ``workers`` spawned ones;
    ``finish(record, bar)`` as each ends. A worker killed from outside raises UserError."""
    work = work or prepare_one
    if workers == 1 or len(jobs) <= 1:
        for job in jobs:
            finish(work(*job), bar)
        return
    # spawn, not fork: a forked child of a process that already ran pymeshlab's OpenMP code hangs in libgomp
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {pool.submit(work, *job): job[0] for job in jobs}
        done: set[str] = set()
        try:
            for future in as_completed(futures):
                finish(future.result(), bar)
                done.add(futures[future])
        except BrokenProcessPool:
            # a worker killed from outside (the system out of memory, a signal): the finished shapes
            # are already in index.json; name the ones in flight so the user knows where to look
            unfinished = [source for source in futures.values() if source not in done]
            shown = ", ".join(unfinished[:3]) + (f" and {len(unfinished) - 3} more" if len(unfinished) > 3 else "")
            raise UserError(
                f"a worker process was killed while preparing {shown} (often the system running out of "
                f"memory); {len(done)} finished {'shape is' if len(done) == 1 else 'shapes are'} kept: run the "
                f"same command again to go on, with fewer --workers or a --max-memory-gb"
            ) from None


def _done_and_todo(paths: list[Path], previous: dict, names: dict, output: Path) -> tuple[dict[str, dict], list[Path]]:
    """({source: record} of the shapes an earlier run finished (listed ok, their .npz present), the paths
    still to prepare)."""
    records: dict[str, dict] = {}
    todo: list[Path] = []
    for path in paths:
        entry = previous.get(str(path))
        if entry is not None and entry.get("status") == "ok" and (output / f"{names[path]}.npz").exists():
            records[str(path)] = entry
        else:
            todo.append(path)
    return records, todo


def run(args) -> int:
    _check_options(args)
    output = Path(args.out)
    output.mkdir(parents=True, exist_ok=True)
    paths = find_meshes(args.input)
    if not paths:
        raise UserError(f"no mesh files (.obj .ply .off .stl .glb .gltf) under {' '.join(args.input)}")
    index_path = output / "index.json"
    guard_outputs(output, ["index.json"], args.overwrite, accept=is_shape_index)  # a user's own index.json is kept
    settings = _settings(args)
    with locked(output / INDEX_LOCK):
        previous, other_settings = read_index(index_path, settings)
    if args.overwrite:  # every shape again; the index keeps their old names, so the new files replace the old
        previous = {source: {k: v for k, v in entry.items() if k != "status"} for source, entry in previous.items()}
    names = assign_names(
        paths,
        {source: Path(entry["file"]).stem for source, entry in previous.items() if isinstance(entry.get("file"), str)},
    )
    if other_settings:
        print(
            f"mesh2tex: note: {index_path} lists shapes prepared with other settings ({other_settings}); "
            f"they are dropped from it, their .npz files stay",
            file=sys.stderr,
        )

    records, todo = _done_and_todo(paths, previous, names, output)

    # an earlier run's files: replaced when prepared again
    listed = {Path(str(entry.get("file"))).name for entry in previous.values()}
    guard_outputs(output, [f"{names[p]}.npz" for p in todo], args.overwrite, accept=lambda path: path.name in listed)
    log = JsonLines(output / "progress.jsonl")

    def write_index() -> None:
        ours = [records[str(p)] for p in paths if str(p) in records]
        # merged with what other invocations wrote meanwhile, never rewritten from our view
        with locked(output / INDEX_LOCK):
            others = [entry for source, entry in read_index(index_path, settings)[0].items() if source not in records]
            write_json(index_path, _index_document(settings, others + ours))

    def finish(record: dict, bar) -> None:
        records[record["source"]] = record
        log.write(
            {
                "event": "shape",
                **{k: record[k] for k in ("source", "status", "reason", "face_counts", "seconds")},
                "warnings": record.get("warnings", []),
            }
        )
        write_index()  # after every shape, so an interruption loses at most the shapes in flight
        if record["status"] == "failed":
            bar.write(f"mesh2tex: failed: {record['reason']}", file=sys.stderr)
        for warning in record.get("warnings", []):
            bar.write(f"mesh2tex: warning: {record['source']}: {warning}", file=sys.stderr)
        bar.update(1)

    budgets = (args.max_seconds, args.max_memory_gb)
    jobs = [
        (str(p), str(output / f"{names[p]}.npz"), args.faces, args.levels, args.seed, *budgets, args.up) for p in todo
    ]
    with progress_bar(total=len(paths), initial=len(paths) - len(todo), desc="prepare shapes", unit="shape") as bar:
        _prepare_all(jobs, args.workers, finish, bar)
    write_index()
    failed = [r for r in records.values() if r["status"] == "failed"]
    print(
        f"prepared {len(records) - len(failed)} of {len(records)} shapes into {output} "
        f"({len(paths) - len(todo)} already done){'; failed: ' + str(len(failed)) if failed else ''}"
    )
    return 2 if failed else 0
