"""The page's HTTP interface (FastAPI): the page itself, sessions, uploads, jobs, their progress and files.

Every route under ``/api/s/{session}`` belongs to one visitor (a tab); the session is a random token the
page asks for when it loads, so that two tabs or two people never see each other's uploads or results.
A refusal is JSON ``{"error": "mesh2tex: error: ..."}``, the line the command line would print.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from mesh2tex.app.jobs import Job, Refused, Visitor, Workshop
from mesh2tex.app.settings import LOCAL_HOSTS, flags
from mesh2tex.app.uploads import ROLES, Upload, check, check_name, receive, safe_name

from mesh2tex import __version__

STATIC = Path(__file__).resolve().parent / "static"
EXAMPLES = STATIC / "examples"
MAX_SEED = 2**31 - 1
PREVIEW = "preview.glb"  # the visitor's mesh, untextured, for the viewer


def refusal(status: int, message: str) -> JSONResponse:
    line = message if message.startswith("mesh2tex: ") else f"mesh2tex: error: {message}"
    return JSONResponse({"error": line}, status_code=status)


def examples() -> dict[str, list[str]]:
    """The example files shipped with the page, by role."""
    return {
        "mesh": sorted(p.name for p in EXAMPLES.glob("*") if p.suffix.lower() in ROLES["mesh"][1]),
        "photo": sorted(p.name for p in EXAMPLES.glob("*") if p.suffix.lower() in ROLES["photo"][1]),
    }


def make_app(workshop: Workshop, models: list[str] | None = None) -> FastAPI:
    """The page and its API over ``workshop``; ``models``: the shipped models offered (default: all)."""
    if models is None:
        from mesh2tex.models import list_models

        models = list_models()
    cfg = workshop.cfg
    app = FastAPI(title="mesh2tex", docs_url=None, redoc_url=None, openapi_url=None)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.exception_handler(Refused)
    async def refused(request: Request, error: Exception):
        return refusal(error.status, str(error))

    @app.get("/")
    def page():
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    @app.get("/api/info")
    def info():
        return {
            "version": __version__,
            "models": models,
            "examples": examples(),
            "local": cfg.host in LOCAL_HOSTS,
            "max_seeds": cfg.max_seeds,
            "limits_mb": {role: getattr(cfg, ROLES[role][2]) for role in ROLES},
            "suffixes": {role: list(ROLES[role][1]) for role in ROLES},
        }

    @app.post("/api/session")
    def session():
        return {"session": workshop.new_visitor().id}

    @app.get("/api/s/{token}/alive")
    def alive(token: str):
        workshop.visitor(token)  # a request keeps the visitor's files
        return {"alive": True}

    @app.post("/api/s/{token}/close")
    def close(token: str):
        workshop.close(workshop.visitor(token))
        return {"closed": True}

    _file_routes(app, workshop)
    _job_routes(app, workshop, models)
    return app


def _file_routes(app: FastAPI, workshop: Workshop) -> None:
    """The routes of a visitor's uploads and examples."""
    cfg = workshop.cfg

    @app.post("/api/s/{token}/upload/{role}")
    async def upload(token: str, role: str, request: Request, name: str = ""):
        visitor = workshop.visitor(token)
        if role not in ROLES:
            return refusal(404, f"no upload of kind {role!r}")
        if visitor.running() is not None:
            return refusal(409, "a job of this page is running: wait for it or cancel it before changing its files")
        name = safe_name(name, role)
        check_name(name, role)
        target = _target(visitor, role, name)
        limit = int(getattr(cfg, ROLES[role][2]) * 2**20)
        await receive(request, target, limit)
        return await run_in_threadpool(_accept, visitor, role, target)

    @app.get("/api/s/{token}/preview")
    def preview(token: str):
        path = workshop.visitor(token).folder / PREVIEW
        if not path.is_file():
            return refusal(404, "upload a mesh first")
        return FileResponse(path, media_type="model/gltf-binary", headers={"Cache-Control": "no-store"})

    @app.post("/api/s/{token}/example/{role}/{name}")
    def example(token: str, role: str, name: str):
        visitor = workshop.visitor(token)
        if name not in examples().get(role, []):
            return refusal(404, f"{name}: no such example")
        if visitor.running() is not None:
            return refusal(409, "a job of this page is running: wait for it or cancel it before changing its files")
        target = _target(visitor, role, name)
        shutil.copyfile(EXAMPLES / name, target)
        return _accept(visitor, role, target)


def _job_routes(app: FastAPI, workshop: Workshop, models: list[str]) -> None:
    """The routes of a visitor's jobs: start, state, cancel, files."""
    cfg = workshop.cfg

    @app.post("/api/s/{token}/jobs")
    async def start(token: str, request: Request):
        visitor = workshop.visitor(token)
        try:
            asked = await request.json()
        except ValueError:
            asked = None
        if not isinstance(asked, dict):
            return refusal(400, "the job request is not a JSON object")
        kind, argv, label, seeds = job_arguments(visitor, asked, models, cfg)
        return job_state(workshop.submit(visitor, kind, argv, label, seeds))

    @app.get("/api/s/{token}/jobs/{job_id}")
    def state(token: str, job_id: str):
        return job_state(_job(workshop.visitor(token), job_id))

    @app.post("/api/s/{token}/jobs/{job_id}/cancel")
    async def cancel(token: str, job_id: str):
        job = _job(workshop.visitor(token), job_id)
        await run_in_threadpool(workshop.stop, job)
        return job_state(job)

    @app.get("/api/s/{token}/jobs/{job_id}/files/{name}")
    def file(token: str, job_id: str, name: str, download: int = 0):
        visitor = workshop.visitor(token)
        job = _job(visitor, job_id)
        if name not in served_files(job):
            return refusal(404, f"{name}: no such result")
        headers = {"Cache-Control": "no-store"}
        if download:
            stem = Path(visitor.uploads["mesh"].path.name).stem if "mesh" in visitor.uploads else "mesh"
            headers["Content-Disposition"] = f'attachment; filename="{stem}_{Path(name).stem}{Path(name).suffix}"'
        return FileResponse(job.folder / name, headers=headers)


def _target(visitor: Visitor, role: str, name: str) -> Path:
    """Where an upload of ``role`` is kept: its own name, unless another role's upload holds that name."""
    others = {u.path.name for r, u in visitor.uploads.items() if r != role}
    name = name if name not in others else f"{role}_{name}"
    old = visitor.uploads.pop(role, None)
    if old is not None:
        old.path.unlink(missing_ok=True)
    return visitor.folder / "uploads" / name


def _accept(visitor: Visitor, role: str, path: Path) -> dict:
    """Check an upload as its command will; keep it for the visitor, or delete it and refuse."""
    preview = visitor.folder / PREVIEW
    if role == "mesh":
        preview.unlink(missing_ok=True)
    try:
        summary = check(path, role, preview if role == "mesh" else None)
    except Refused:
        path.unlink(missing_ok=True)
        raise
    visitor.uploads[role] = Upload(role, path, summary)
    return {"role": role, "name": path.name, "summary": summary}


def _job(visitor: Visitor, job_id: str) -> Job:
    job = visitor.jobs.get(job_id)
    if job is None:
        raise Refused(404, "no such job on this page (a newer job replaced it)")
    return job


def _number(asked: dict, key: str, default: int, low: int, high: int) -> int:
    value = asked.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise Refused(400, f"{key} {value!r}: must be a whole number from {low} to {high}")
    return value


def _needs(visitor: Visitor, role: str) -> str:
    upload = visitor.uploads.get(role)
    if upload is None or not upload.path.is_file():
        raise Refused(400, f"upload {ROLES[role][0]} first")
    return upload.path.name


def job_arguments(visitor: Visitor, asked: dict, models: list[str], cfg) -> tuple[str, list[str], str, list[str]]:
    """The command a job request names: (infer subcommand, its arguments, a label, its seeds).
    Refused for a request the page could not have made or an upload missing."""
    kind, source, quick = asked.get("kind"), asked.get("source"), bool(asked.get("quick", False))
    seed = _number(asked, "seed", 0, 0, MAX_SEED)
    mesh = _needs(visitor, "mesh")
    stem = Path(mesh).stem
    if kind == "transfer":
        if source not in models:
            raise Refused(
                400, f"a transfer needs a shipped model ({', '.join(models) or 'none installed'}), not {source!r}"
            )
        photo = _needs(visitor, "photo")
        argv = [
            "--checkpoint",
            source,
            "--mesh",
            mesh,
            "--image",
            photo,
            "--seed",
            str(seed),
            *flags(cfg.transfer_flags),
            *(flags(cfg.quick_transfer_flags) if quick else []),
        ]
        return "transfer", argv, f"{stem}_{source}_after_{Path(photo).stem}", [seed]
    if kind != "generate":
        raise Refused(400, f"kind {kind!r}: choose generate or transfer")
    if source == "nca":
        argv = ["--checkpoint", _needs(visitor, "nca"), "--mesh", mesh, "--seed", str(seed), *flags(cfg.nca_flags)]
        return "nca", argv, f"{stem}_nca_seed{seed}", [seed]
    if source == "exemplar":
        exemplar = _needs(visitor, "exemplar")
        argv = [
            "--exemplar",
            exemplar,
            "--mesh",
            mesh,
            "--seed",
            str(seed),
            *flags(cfg.synthesize_flags),
            *(flags(cfg.quick_synthesize_flags) if quick else []),
        ]
        return "synthesize", argv, f"{stem}_{Path(exemplar).stem}_seed{seed}", [seed]
    if source not in models:
        raise Refused(
            400, f"model {source!r}: choose a shipped model ({', '.join(models) or 'none installed'}), nca or exemplar"
        )
    count = _number(asked, "count", 1, 1, cfg.max_seeds)
    seeds = list(range(seed, min(seed + count, MAX_SEED + 1)))
    argv = ["--checkpoint", source, "--mesh", mesh, "--seeds", ",".join(map(str, seeds)), *flags(cfg.generate_flags)]
    return "generate", argv, f"{stem}_{source}_seed{seeds[0]}" + (f"-{seeds[-1]}" if len(seeds) > 1 else ""), seeds


# what the page shows of each kind's files besides the textured meshes: (file, caption)
PICTURES = {
    "transfer": [
        ("photo_crop.png", "the photo, cropped to the object"),
        ("comparison.png", "photo | result at the estimated pose | predicted NOC | the mesh's NOC"),
    ],
    "synthesize": [("texture.png", "the texture")],
    "nca": [("view_0.png", "a view")],
    "generate": [],
}


def results(job: Job) -> dict:
    """What a finished job made: its textured meshes (with a thumbnail each), pictures and report."""
    if job.status != "done":
        return {}
    if job.kind == "generate":
        meshes = [{"label": f"seed {s}", "glb": f"seed{s}.glb", "thumb": f"seed{s}_view0.png"} for s in job.seeds]
    else:
        meshes = [{"label": job.label, "glb": "textured.glb", "thumb": ""}]
    for entry in meshes:
        if entry["thumb"] and not (job.folder / entry["thumb"]).is_file():
            entry["thumb"] = ""
    pictures = [
        {"file": name, "caption": caption} for name, caption in PICTURES[job.kind] if (job.folder / name).is_file()
    ]
    found = {"meshes": [m for m in meshes if (job.folder / m["glb"]).is_file()], "pictures": pictures}
    if job.kind == "transfer" and (job.folder / "report.json").is_file():
        report = json.loads((job.folder / "report.json").read_text())
        found["pose"] = {k: report.get("pose", {}).get(k) for k in ("azimuth", "elevation", "source")}
        found["fit"] = {k: report.get("fit", {}).get(k) for k in ("silhouette_iou", "lowpass_psnr", "poor", "problems")}
    return found


def served_files(job: Job) -> set[str]:
    found = results(job)
    return {m[k] for m in found.get("meshes", []) for k in ("glb", "thumb") if m[k]} | {
        p["file"] for p in found.get("pictures", [])
    }


def job_state(job: Job) -> dict:
    return {
        "id": job.id,
        "kind": job.kind,
        "label": job.label,
        "status": job.status,
        "stage": job.stage,
        "done": job.done,
        "total": job.total,
        "log": job.log[-8:],
        "error": job.error,
        "seconds": job.seconds(),
        "kept": os.path.basename(job.kept),
        "results": results(job),
    }
