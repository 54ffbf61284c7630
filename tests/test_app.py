"""``mesh2tex app``: the page in a real browser (the system's Chromium, driven by playwright), and what a
visitor can get wrong through plain HTTP requests.

One server for the module, started as a user starts it (``python -m mesh2tex app --port 0``) with a tiny
model (the session's tiny GAN, exported, with the chair's pose, NOC and mask networks beside it) and a
config whose jobs are small; its temporary folders go to a folder of the test's own (``TMPDIR``), so that
the tests can say that nothing is left on disk.
"""

from __future__ import annotations

import http.client
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml
from conftest import TINY_NCA

pytest.importorskip("fastapi", reason="the app's extra is not installed: pip install -e '.[app]'")
pytest.importorskip("uvicorn", reason="the app's extra is not installed: pip install -e '.[app]'")

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
BROWSER_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
# the tiny automaton of tests/test_train_nca.py
TINY_NCA_RUN = {**TINY_NCA, "iters": 4}
# small jobs: the page's flags, as a user would put them in --config
CONFIG = {
    "max_mesh_mb": 1,
    "max_photo_mb": 1,
    "generate_flags": "--views 1 --resolution 32 --texture-size 64",
    "transfer_flags": "--resolution 64 --texture-size 64",
    "quick_transfer_flags": "--latent-iters 2 --refine-iters 2",
    "nca_flags": "--steps 4 --views 1 --resolution 32 --texture-size 64 --frames 0",
    "quick_synthesize_flags": "--iters 2 --texture-size 32 --resolution 32 --views 1",
}


@pytest.fixture(scope="module")
def server(tiny_gan, tmp_path_factory):
    """The running app: {"url", "tmp" (its temporary folders' parent), "process"}."""
    from mesh2tex.models import MODEL_FILES, export_inference_checkpoint

    root = tmp_path_factory.mktemp("app")
    models = root / "models" / "tiny"
    models.mkdir(parents=True)
    export_inference_checkpoint(tiny_gan / "run" / "checkpoint.safetensors", "gan", models / MODEL_FILES["gan"])
    for kind in ("pose", "noc", "mask"):
        shutil.copyfile(ROOT / "mesh2tex" / "models" / "chair" / MODEL_FILES[kind], models / MODEL_FILES[kind])
    (root / "app.yaml").write_text(yaml.safe_dump(CONFIG))
    (root / "tmp").mkdir()
    env = {
        **os.environ,
        "MESH2TEX_MODELS": str(root / "models"),
        "TMPDIR": str(root / "tmp"),
        "OMP_NUM_THREADS": "1",
        "PYTHONPATH": str(ROOT),
    }
    process = subprocess.Popen(
        [sys.executable, "-m", "mesh2tex", "app", "--port", "0", "--device", "cpu", "--config", str(root / "app.yaml")],
        cwd=root,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    line = process.stdout.readline()
    assert "this machine only" in line, line + process.stderr.read()
    url = line.split()[2].rstrip("/")
    yield {"url": url, "tmp": root / "tmp", "process": process}
    process.send_signal(signal.SIGINT)
    assert process.wait(timeout=30) == 0
    assert list((root / "tmp").iterdir()) == [], "the server left files behind"


def request(url: str, method: str = "GET", body: bytes | None = None, headers: dict | None = None) -> tuple[int, dict]:
    try:
        with urllib.request.urlopen(
            urllib.request.Request(url, body, headers or {}, method=method), timeout=60
        ) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read())


def session(server) -> str:
    return request(f"{server['url']}/api/session", "POST")[1]["session"]


def files_under(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.is_file()]


def run_job(server, token: str, job: dict, timeout: float = 120) -> dict:
    status, state = request(
        f"{server['url']}/api/s/{token}/jobs", "POST", json.dumps(job).encode(), {"Content-Type": "application/json"}
    )
    assert status == 200, state
    deadline = time.time() + timeout
    while state["status"] in ("queued", "running") and time.time() < deadline:
        time.sleep(0.2)
        state = request(f"{server['url']}/api/s/{token}/jobs/{state['id']}")[1]
    return state


def test_bad_uploads_get_the_commands_message_and_leave_nothing(server, tmp_path):
    token = session(server)
    base = f"{server['url']}/api/s/{token}/upload"
    png = (ROOT / "app" / "static" / "examples" / "chair_photo.png").read_bytes()
    cases = [
        ("mesh", "empty.obj", b"", 422, "mesh2tex: error: empty.obj: empty file"),
        ("mesh", "photo.obj", png, 422, "mesh2tex: error: photo.obj: is a PNG image, not a mesh (.obj file)"),
        ("mesh", "notes.txt", b"v 0 0 0\n", 415, "notes.txt: unsupported format '.txt' for a mesh"),
        ("mesh", "points.obj", b"v 0 0 0\nv 1 0 0\n", 422, "points.obj: "),
        ("photo", "photo.png", b"not an image at all", 422, "photo.png: not a valid .png file"),
        ("photo", "fake.jpg", png, 422, "fake.jpg: is a PNG image, not a photo"),
    ]
    for role, name, body, code, says in cases:
        status, answer = request(f"{base}/{role}?name={name}", "POST", body)
        assert (status, answer["error"].startswith("mesh2tex: error: ")) == (code, True), (name, answer)
        assert says in answer["error"], (name, answer)
    # 2 GB declared: refused from its length, before a byte is read
    connection = http.client.HTTPConnection(server["url"].split("//")[1], timeout=30)
    connection.putrequest("POST", f"/api/s/{token}/upload/mesh?name=huge.obj")
    connection.putheader("Content-Length", str(2 * 2**30))
    connection.endheaders()
    answer = connection.getresponse()
    assert answer.status == 413 and "over the upload limit of 1.0 MB" in json.loads(answer.read())["error"]
    connection.close()
    # no length given (chunked): cut off once it passes the bound
    connection = http.client.HTTPConnection(server["url"].split("//")[1], timeout=30)
    chunks = (b"v 0 0 0\n" * 8192 for _ in range(24))  # 1.5 MB
    connection.request("POST", f"/api/s/{token}/upload/mesh?name=long.obj", body=chunks, encode_chunked=True)
    answer = connection.getresponse()
    assert answer.status == 413 and "long.obj: over the upload limit" in json.loads(answer.read())["error"]
    connection.close()
    assert request(f"{server['url']}/api/info")[0] == 200  # still serving
    assert files_under(server["tmp"]) == [], "a refused upload was kept"


def test_a_photo_without_an_object_fails_with_the_commands_line_and_leaves_no_job(server):
    token = session(server)
    assert request(f"{server['url']}/api/s/{token}/example/mesh/chair.obj", "POST")[0] == 200
    import io

    from PIL import Image

    blank = io.BytesIO()
    Image.new("RGB", (64, 64), (255, 255, 255)).save(blank, format="PNG")
    status, answer = request(f"{server['url']}/api/s/{token}/upload/photo?name=wall.png", "POST", blank.getvalue())
    assert status == 200, answer
    state = run_job(server, token, {"kind": "transfer", "source": "tiny", "seed": 0, "quick": True})
    assert (
        state["status"] == "failed"
        and state["error"] == "mesh2tex: error: wall.png: the object mask is empty (fewer than 16 object pixels)"
    ), state
    assert not [p for p in (server["tmp"]).rglob("job-*")], "a failed job left its folder"
    # another tab sees none of it
    other = session(server)
    assert request(f"{server['url']}/api/s/{other}/jobs/{state['id']}")[0] == 404
    assert request(f"{server['url']}/api/s/{token}/close", "POST")[0] == 200
    assert request(f"{server['url']}/api/s/{token}/jobs/{state['id']}")[0] == 404
    assert not [p for p in server["tmp"].rglob("*") if token in str(p)], "a closed page's files were kept"


def test_a_cancelled_job_stops_and_leaves_nothing(server):
    token = session(server)
    request(f"{server['url']}/api/s/{token}/example/mesh/chair.obj", "POST")
    request(f"{server['url']}/api/s/{token}/example/photo/chair_photo.png", "POST")
    status, state = request(
        f"{server['url']}/api/s/{token}/jobs",
        "POST",
        json.dumps({"kind": "transfer", "source": "tiny", "seed": 0, "quick": False}).encode(),
        {"Content-Type": "application/json"},
    )
    deadline = time.time() + 60
    while not state["stage"].startswith("transfer") and time.time() < deadline:  # its own progress bar is showing
        time.sleep(0.2)
        state = request(f"{server['url']}/api/s/{token}/jobs/{state['id']}")[1]
    assert state["status"] == "running" and state["total"] > 0, state
    state = request(f"{server['url']}/api/s/{token}/jobs/{state['id']}/cancel", "POST")[1]
    assert state["status"] == "cancelled" and state["results"] == {}
    assert not [p for p in server["tmp"].rglob("job-*")]


def served_glb(server, token: str, state: dict, tmp_path) -> trimesh.Trimesh:
    """The job's (first) textured GLB, downloaded as the page does; a textured mesh."""
    assert state["status"] == "done", state
    name = state["results"]["meshes"][0]["glb"]
    url = f"{server['url']}/api/s/{token}/jobs/{state['id']}/files/{name}?download=1"
    with urllib.request.urlopen(url, timeout=60) as answer:
        (tmp_path / name).write_bytes(answer.read())
    mesh = trimesh.load(tmp_path / name, force="mesh", process=False)
    assert np.asarray(mesh.visual.material.baseColorTexture.convert("RGB")).std() > 0
    return mesh


def test_an_nca_model_and_an_exemplar_image_texture_the_mesh(server, tmp_path):
    from PIL import Image

    from mesh2tex.cli import main
    from mesh2tex.synthetic.exemplars import exemplar_image

    Image.fromarray(exemplar_image("stripes", 48)).save(tmp_path / "stripes.png")
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(TINY_NCA_RUN))
    assert (
        main(
            [
                "train",
                "nca",
                "--exemplar",
                str(tmp_path / "stripes.png"),
                "--out",
                str(tmp_path / "nca"),
                "--config",
                str(tmp_path / "tiny.yaml"),
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    token = session(server)
    base = f"{server['url']}/api/s/{token}"
    assert request(f"{base}/example/mesh/chair.obj", "POST")[0] == 200
    faces = len(trimesh.load(ROOT / "app" / "static" / "examples" / "chair.obj", force="mesh", process=False).faces)
    model = (tmp_path / "nca" / "model.safetensors").read_bytes()
    assert request(f"{base}/upload/nca?name=stripes.safetensors", "POST", model)[0] == 200
    grown = run_job(server, token, {"kind": "generate", "source": "nca", "seed": 0})
    assert grown["kind"] == "nca" and len(served_glb(server, token, grown, tmp_path).faces) == faces
    assert (
        request(f"{base}/upload/exemplar?name=stripes.png", "POST", (tmp_path / "stripes.png").read_bytes())[0] == 200
    )
    made = run_job(server, token, {"kind": "generate", "source": "exemplar", "seed": 0, "quick": True})
    assert made["kind"] == "synthesize" and len(served_glb(server, token, made, tmp_path).faces) == faces
    assert [p["file"] for p in made["results"]["pictures"]] == ["texture.png"]


@pytest.fixture(scope="module")
def browser():
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed: pip install -e '.[app]'")
    if not os.access(CHROMIUM, os.X_OK):
        pytest.skip(f"no Chromium at {CHROMIUM} (Debian: apt-get install chromium)")
    with sync_api.sync_playwright() as playwright:
        launched = playwright.chromium.launch(executable_path=CHROMIUM, args=BROWSER_ARGS)
        yield launched
        launched.close()


def open_page(browser, server):
    page = browser.new_page(accept_downloads=True)
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    page.goto(server["url"] + "/")
    page.wait_for_function("window.mesh2tex && window.mesh2tex.ready", timeout=30000)
    assert errors == []
    return page


def downloaded_glb(page, tmp_path) -> trimesh.Trimesh:
    """Download the GLB the page shows; it must be a textured mesh."""
    with page.expect_download() as started:
        page.click("#download")
    path = tmp_path / started.value.suggested_filename
    started.value.save_as(path)
    assert path.suffix == ".glb" and path.read_bytes()[:4] == b"glTF"
    mesh = trimesh.load(path, force="mesh", process=False)
    texture = np.asarray(mesh.visual.material.baseColorTexture.convert("RGB"))
    assert mesh.visual.uv.shape == (len(mesh.vertices), 2) and texture.std() > 0
    return mesh


def wait_for_viewer(page, timeout_s: float = 90) -> float:
    """Wait for the viewer's load event of the job just started; the seconds since the button was pressed."""
    page.wait_for_function(
        "window.mesh2tex.loaded > 0 || !document.getElementById('error').hidden", timeout=timeout_s * 1000
    )
    assert page.is_hidden("#error"), page.inner_text("#error")
    return page.evaluate("window.mesh2tex.seconds")


def test_generate_in_the_browser_shows_and_downloads_the_users_mesh_textured(browser, server, tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=1)
    mesh.export(tmp_path / "ball.obj")
    page = open_page(browser, server)
    (tmp_path / "empty.obj").write_bytes(b"")
    for path, says in (
        (tmp_path / "empty.obj", "mesh2tex: error: empty.obj: empty file"),
        (
            {"name": "big.obj", "mimeType": "text/plain", "buffer": b"v 0 0 0\n" * 2**18},
            "mesh2tex: error: big.obj: 2.0 MB is over the upload limit of 1.0 MB",
        ),
    ):
        page.set_input_files("#mesh-file", path)  # a bad file: the command's line in the page
        page.wait_for_function("!document.getElementById('error').hidden")
        assert page.inner_text("#error") == says
    page.set_input_files("#mesh-file", str(tmp_path / "ball.obj"))
    page.wait_for_function("document.getElementById('mesh-summary').textContent.includes('vertices')")
    assert page.inner_text("#mesh-summary") == "ball.obj: 42 vertices, 80 triangles (y-up)"
    page.wait_for_function("document.getElementById('viewer').loaded")  # the mesh as uploaded, untextured
    assert "/preview" in page.evaluate("document.getElementById('viewer').src")
    page.select_option("#source", "tiny")
    page.fill("#seed", "0")
    page.dispatch_event("#seed", "change")
    page.select_option("#count", "2")
    page.click("#generate")
    wait_for_viewer(page)
    assert page.evaluate("window.mesh2tex.glb") == "seed0.glb"
    assert page.locator("#gallery button").count() == 2  # the two seeds, a thumbnail each
    glb = downloaded_glb(page, tmp_path)
    assert len(glb.faces) == len(mesh.faces)
    assert {tuple(v) for v in np.round(glb.vertices, 5)} == {tuple(v) for v in np.round(mesh.vertices, 5)}
    page.click("#gallery button:nth-child(2)")  # the second seed in the viewer
    page.wait_for_function("document.getElementById('viewer').src.includes('seed1.glb')")
    page.close()


def test_transfer_in_the_browser_shows_the_pose_and_noc_then_the_result(browser, server, tmp_path):
    page = open_page(browser, server)
    page.select_option("#mesh-example", "chair.obj")
    page.wait_for_function("document.getElementById('mesh-summary').textContent.includes('(example)')")
    page.select_option("#photo-example", "chair_photo.png")
    page.wait_for_function("document.getElementById('photo-summary').textContent.includes('(example)')")
    page.select_option("#source", "tiny")
    assert page.is_checked("#quick")
    page.click("#transfer")
    wait_for_viewer(page)
    assert "estimated pose: azimuth" in page.inner_text("#pose")
    assert page.locator("#pictures img").count() == 2  # the photo's crop, and the comparison with both NOC maps
    example = trimesh.load(ROOT / "app" / "static" / "examples" / "chair.obj", force="mesh", process=False)
    assert len(downloaded_glb(page, tmp_path).faces) == len(example.faces)
    page.close()


# ------------------------------------------------------------------------------- without a server
def test_a_commands_progress_bar_and_lines_are_read_as_the_page_shows_them(tmp_path):
    from mesh2tex.app.jobs import Job

    job = Job("id", "generate", tmp_path / "job", [], "label")
    job.note("infer generate:  50%|#####     | 1/2 [00:08<00:08,  8.84s/seed]")
    job.note(f"seed 0: 1 views, {tmp_path / 'job' / 'seed0.glb'} (input mesh, 80 triangles)")
    job.note("mesh2tex: error: ball.obj: contains no faces")
    assert (job.stage, job.done, job.total) == ("infer generate", 1, 2)
    assert job.log == [
        "seed 0: 1 views, seed0.glb (input mesh, 80 triangles)",
        "mesh2tex: error: ball.obj: contains no faces",
    ]
    assert job.error == "mesh2tex: error: ball.obj: contains no faces"


def test_an_idle_visitors_files_are_deleted(tmp_path, monkeypatch):
    from mesh2tex.app.jobs import Refused, Workshop
    from mesh2tex.app.settings import AppConfig

    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    workshop = Workshop(AppConfig(keep_minutes=1))
    kept, idle = workshop.new_visitor(), workshop.new_visitor()
    idle.seen -= 120
    assert workshop.sweep() == 1 and kept.folder.is_dir() and not idle.folder.exists()
    with pytest.raises(Refused, match="reload the page"):
        workshop.visitor(idle.id)
    workshop.shutdown()
    assert list(tmp_path.iterdir()) == []


def test_the_pages_own_flags_and_a_taken_port_are_one_line_errors(tmp_path, capsys):
    import socket

    from mesh2tex.cli import main

    (tmp_path / "app.yaml").write_text("generate_flags: --views 1 --out elsewhere\n")
    assert main(["app", "--config", str(tmp_path / "app.yaml"), "--print-config"]) == 2
    assert "generate_flags: --out is set by the page itself" in capsys.readouterr().err
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        assert main(["app", "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert err == f"mesh2tex: error: --port {port}: already in use; choose another, or --port 0 for a free one\n"


def _sleeper_job(workshop, seconds: float, label: str):
    """A visitor with a job whose command sleeps ``seconds`` (a stand-in for a long `infer` run)."""
    from mesh2tex.app.jobs import Job

    visitor = workshop.new_visitor()
    job = Job(
        label,
        "generate",
        visitor.folder / f"job-{label}",
        [sys.executable, "-c", f"import time; time.sleep({seconds})"],
        label,
    )
    visitor.jobs[job.id] = job
    return visitor, job


def test_a_job_past_its_time_limit_is_stopped_with_one_line_and_leaves_nothing(tmp_path, monkeypatch):
    from mesh2tex.app.jobs import Workshop
    from mesh2tex.app.settings import AppConfig

    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    workshop = Workshop(AppConfig(job_timeout=0.5))
    visitor, job = _sleeper_job(workshop, 60, "slow")
    job.folder.mkdir()
    started = time.monotonic()
    workshop._run(visitor, job)
    assert time.monotonic() - started < 20, "stopped long before the command would have ended"
    assert job.status == "failed" and job.process.poll() is not None
    assert job.error == "mesh2tex: error: the job ran longer than 0.5 s and was stopped"
    assert not job.folder.exists()
    workshop.shutdown()


def test_jobs_beyond_the_servers_slots_wait_their_turn(tmp_path, monkeypatch):
    """With ``jobs: 1`` two pages' jobs run one after the other, never at once; both finish."""
    import threading

    from mesh2tex.app.jobs import Workshop
    from mesh2tex.app.settings import AppConfig

    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    workshop = Workshop(AppConfig(jobs=1))
    runs = [_sleeper_job(workshop, 1.0, name) for name in ("first", "second")]
    threads = [threading.Thread(target=workshop._run, args=run) for run in runs]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    (_, a), (_, b) = runs
    assert a.status == b.status == "done"
    first, second = sorted([a, b], key=lambda job: job.started_at)
    assert second.started_at >= first.ended_at, "the second job started while the first was running"
    workshop.shutdown()
