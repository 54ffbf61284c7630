"""The visitors of the page and their jobs.

Each visitor (a tab: the page asks for a session when it loads) gets a folder of its own under the
server's temporary folder, holding its uploads and one folder per job; a job is one real command
(``python -m mesh2tex infer generate|transfer|nca|synthesize ... --out JOB``) run as a subprocess in its
own process group, so that its files, checks and one-line errors are exactly the command line's, its
progress is the bar the command shows (``MESH2TEX_PROGRESS=1``: tqdm lines on its stderr, parsed here),
and cancelling it stops the whole group. A visitor's folder is deleted when the page closes, after
``keep_minutes`` without a request, and when the server stops.
"""

from __future__ import annotations

import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

# a tqdm line: "infer generate:  50%|#####     | 1/2 [00:08<00:08, ...]"
BAR = re.compile(r"^(?P<desc>[^|]*?):\s*(?P<percent>\d+)%\|[^|]*\|\s*(?P<n>\d+)/(?P<total>\d+)")
LOG_LINES = 40  # lines of a job's output the page can show
GRACE_S = 5.0  # seconds a cancelled command has to stop before it is killed


class Refused(Exception):
    """A request the server turns down (an upload, a job): ``status`` (HTTP) and a one-line message for the page."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status


@dataclass
class Job:
    """One command run for a visitor: its arguments, state, progress and output."""

    id: str
    kind: str
    folder: Path
    argv: list[str]
    label: str
    seeds: list[int] = field(default_factory=list)
    status: str = "queued"  # queued, running, done, failed, cancelled
    stage: str = ""
    done: int = 0
    total: int = 0
    log: list[str] = field(default_factory=list)
    error: str = ""
    queued_at: float = field(default_factory=time.time)
    started_at: float = 0.0
    ended_at: float = 0.0
    kept: str = ""
    process: subprocess.Popen | None = None
    thread: threading.Thread | None = None
    cancelled: bool = False

    @property
    def active(self) -> bool:
        return self.status in ("queued", "running")

    def note(self, line: str) -> None:
        """Record a line of the command's output: a progress bar's state, or a line of its log."""
        match = BAR.match(line.strip())
        if match:
            self.stage, self.done, self.total = match["desc"].strip(), int(match["n"]), int(match["total"])
            return
        line = line.strip().replace(f"{self.folder}{os.sep}", "").replace(f"{self.folder.parent}{os.sep}", "")
        if line and (not self.log or self.log[-1] != line):
            self.log = (self.log + [line])[-LOG_LINES:]
        if line.startswith("mesh2tex: error:"):
            self.error = line

    def seconds(self) -> float:
        if not self.started_at:
            return 0.0
        return round((self.ended_at or time.time()) - self.started_at, 2)


@dataclass
class Visitor:
    """A tab of the page: its folder, its current uploads by role, its jobs."""

    id: str
    folder: Path
    uploads: dict = field(default_factory=dict)  # role -> uploads.Upload
    jobs: dict = field(default_factory=dict)  # id -> Job
    seen: float = field(default_factory=time.time)

    def running(self) -> Job | None:
        return next((job for job in self.jobs.values() if job.active), None)


class Workshop:
    """Every visitor and job of one server: their temporary folder, the slots jobs wait for, the sweeper."""

    def __init__(self, cfg, keep: Path | None = None, overwrite: bool = False):
        self.cfg, self.keep, self.overwrite = cfg, keep, overwrite
        self.root = Path(tempfile.mkdtemp(prefix="mesh2tex-app-"))
        self.visitors: dict[str, Visitor] = {}
        self.lock = threading.Lock()
        self.slots = threading.Semaphore(cfg.jobs)
        self.stopping = threading.Event()
        self.sweeper = threading.Thread(target=self._sweep_loop, name="mesh2tex-app-sweeper", daemon=True)

    def start(self) -> None:
        self.sweeper.start()

    # ------------------------------------------------------------------------------------------ visitors
    def new_visitor(self) -> Visitor:
        token = secrets.token_urlsafe(16)
        folder = self.root / token
        (folder / "uploads").mkdir(parents=True)
        visitor = Visitor(token, folder)
        with self.lock:
            self.visitors[token] = visitor
        return visitor

    def visitor(self, token: str) -> Visitor:
        with self.lock:
            visitor = self.visitors.get(token)
        if visitor is None:
            raise Refused(404, "this page's session has ended (closed or idle too long): reload the page")
        visitor.seen = time.time()
        return visitor

    def close(self, visitor: Visitor) -> None:
        """Stop the visitor's jobs and delete its folder."""
        with self.lock:
            self.visitors.pop(visitor.id, None)
        for job in list(visitor.jobs.values()):
            self.stop(job)
        shutil.rmtree(visitor.folder, ignore_errors=True)

    def sweep(self, now: float | None = None) -> int:
        """Close the visitors idle for longer than ``keep_minutes``; returns how many."""
        now = time.time() if now is None else now
        with self.lock:
            idle = [v for v in self.visitors.values() if now - v.seen > self.cfg.keep_minutes * 60]
        for visitor in idle:
            self.close(visitor)
        return len(idle)

    def _sweep_loop(self) -> None:
        while not self.stopping.wait(30.0):
            self.sweep()

    def shutdown(self) -> None:
        """Stop every job and delete every visitor's folder and the server's own."""
        self.stopping.set()
        with self.lock:
            visitors = list(self.visitors.values())
        for visitor in visitors:
            self.close(visitor)
        shutil.rmtree(self.root, ignore_errors=True)

    # ------------------------------------------------------------------------------------------ jobs
    def submit(self, visitor: Visitor, kind: str, argv: list[str], label: str, seeds: list[int]) -> Job:
        """Start ``mesh2tex infer KIND ARGV --out <a new job folder>`` for ``visitor`` once a slot is free."""
        if visitor.running() is not None:
            raise Refused(409, "a job of this page is still running: wait for it or cancel it")
        token = secrets.token_hex(6)
        folder = visitor.folder / f"job-{token}"
        command = [
            sys.executable,
            "-m",
            "mesh2tex",
            "infer",
            kind,
            *argv,
            "--device",
            self.cfg.device,
            "--out",
            str(folder),
        ]
        job = Job(token, kind, folder, command, label, seeds)
        visitor.jobs[token] = job
        for old in [j for j in visitor.jobs.values() if j is not job]:  # one result per page: the last
            self.forget(visitor, old)
        job.thread = threading.Thread(
            target=self._run, args=(visitor, job), name=f"mesh2tex-app-job-{token}", daemon=True
        )
        job.thread.start()
        return job

    def forget(self, visitor: Visitor, job: Job) -> None:
        visitor.jobs.pop(job.id, None)
        shutil.rmtree(job.folder, ignore_errors=True)

    def _run(self, visitor: Visitor, job: Job) -> None:
        with self.slots:
            if job.cancelled or self.stopping.is_set():
                job.status = "cancelled"
                return
            env = {**os.environ, "MESH2TEX_PROGRESS": "1", "PYTHONUNBUFFERED": "1"}
            job.started_at, job.status = time.time(), "running"
            try:
                job.process = subprocess.Popen(
                    job.argv,
                    cwd=visitor.folder / "uploads",
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    start_new_session=True,
                )
            except OSError as error:
                job.status, job.error, job.ended_at = (
                    "failed",
                    f"mesh2tex: error: could not start the command ({error})",
                    time.time(),
                )
                return
            if job.cancelled:  # cancelled while it was starting
                self.cancel(job)
            readers = [
                threading.Thread(target=_read, args=(stream, job), daemon=True)
                for stream in (job.process.stdout, job.process.stderr)
            ]
            for reader in readers:
                reader.start()
            try:
                code = job.process.wait(timeout=self.cfg.job_timeout)
            except subprocess.TimeoutExpired:
                job.error = f"mesh2tex: error: the job ran longer than {self.cfg.job_timeout:g} s and was stopped"
                self.cancel(job, timeout=True)
                code = job.process.wait()
            for reader in readers:
                reader.join()
            job.ended_at = time.time()
        self._finish(visitor, job, code)

    def _finish(self, visitor: Visitor, job: Job, code: int) -> None:
        if job.cancelled and not job.error:
            job.status = "cancelled"
        elif code == 0:
            job.status = "done"
            self._keep(visitor, job)
            return
        else:
            job.status = "failed"
            job.error = job.error or f"mesh2tex: error: the command stopped (exit status {code}); its output: " + (
                job.log[-1] if job.log else "none"
            )
        job.error = job.error.replace(f"{visitor.folder}{os.sep}", "")
        shutil.rmtree(job.folder, ignore_errors=True)  # a failed or cancelled job leaves nothing behind

    def stop(self, job: Job) -> None:
        """Cancel ``job`` and wait until it is over (its folder deleted, its state final)."""
        self.cancel(job)
        if job.thread is not None:
            job.thread.join(timeout=GRACE_S + 5)

    def cancel(self, job: Job, timeout: bool = False) -> None:
        """Stop the job's command and everything it started (its process group): SIGTERM, then SIGKILL."""
        job.cancelled = not timeout
        process = job.process
        if process is None and job.status == "queued":  # still waiting for a slot: it will not start
            job.status = "cancelled"
        if process is None or process.poll() is not None:
            return
        for sig, wait in ((signal.SIGTERM, GRACE_S), (signal.SIGKILL, None)):
            try:
                os.killpg(process.pid, sig)
            except ProcessLookupError:
                return
            try:
                process.wait(timeout=wait)
                return
            except subprocess.TimeoutExpired:
                continue

    def _keep(self, visitor: Visitor, job: Job) -> None:
        """With ``--out``: copy the job's files into a folder of its own there."""
        if self.keep is None:
            return
        name = re.sub(r"[^A-Za-z0-9._-]+", "_", job.label)[:80] or job.kind
        target = self.keep / name
        with self.lock:
            if target.exists() and self.overwrite:
                from mesh2tex.io.outputs import move_aside

                move_aside(self.keep, [name])
            number = 2
            while target.exists():
                target, number = self.keep / f"{name}_{number}", number + 1
            shutil.copytree(job.folder, target, ignore=shutil.ignore_patterns(".mesh2tex-*"))
        job.kept = str(target)


def _read(stream, job: Job) -> None:
    """Feed ``job`` the lines of one of its command's streams as they come (tqdm ends its frames with \\r)."""
    pending = b""
    while True:
        chunk = stream.read1(65536) if hasattr(stream, "read1") else stream.read(65536)
        if not chunk:
            break
        pending += chunk
        *lines, pending = re.split(rb"[\r\n]", pending)
        for line in lines:
            job.note(line.decode("utf-8", "replace"))
    if pending:
        job.note(pending.decode("utf-8", "replace"))
    stream.close()
