"""``mesh2tex app``: serve the page that textures a visitor's mesh, on this machine only unless told.

``run`` binds the socket (127.0.0.1 by default, and says so), prints the address and serves
:func:`mesh2tex.app.web.make_app` with uvicorn until Ctrl-C; the jobs and visitors' folders
(:class:`mesh2tex.app.jobs.Workshop`) are stopped and deleted when it stops. FastAPI and uvicorn are
the optional extra ``app`` (``pip install 'mesh2tex[app]'``).
"""

from __future__ import annotations

import errno
import socket
from pathlib import Path

from mesh2tex.app.settings import LOCAL_HOSTS, AppConfig

from mesh2tex.config import load_config
from mesh2tex.errors import UserError, warning
from mesh2tex.options import config_overrides


def build_config(args) -> AppConfig:
    """The config's defaults, then ``--config``, then the flags given."""
    return load_config(AppConfig, args.config, config_overrides(args))


def bind(host: str, port: int) -> socket.socket:
    """A listening socket on ``host:port``; UserError when the port is taken or the address is not this machine's."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as error:
        sock.close()
        if error.errno == errno.EADDRINUSE:
            raise UserError(f"--port {port}: already in use; choose another, or --port 0 for a free one") from None
        raise UserError(f"--host {host}: cannot serve there ({error.strerror or error})") from None
    except (socket.gaierror, UnicodeError) as error:
        sock.close()
        raise UserError(f"--host {host}: not an address of this machine ({error})") from None
    sock.listen(64)
    return sock


def announce(host: str, port: int) -> None:
    """Say where the page is, and whether it is this machine's only."""
    shown = f"[{host}]" if ":" in host else host
    if host in LOCAL_HOSTS:
        print(f"mesh2tex app: http://{shown}:{port}/ (this machine only; Ctrl-C stops it)", flush=True)
        return
    print(f"mesh2tex app: http://{shown}:{port}/ (Ctrl-C stops it)", flush=True)
    warning(
        f"--host {host}: the page is open to every machine that can reach this one; anyone there can upload "
        "files and run jobs on it (use --host 127.0.0.1 to keep it to this machine)"
    )


def run(args) -> int:
    cfg = build_config(args)
    try:
        import uvicorn
        from mesh2tex.app.web import make_app
    except ModuleNotFoundError as error:
        raise UserError(f"mesh2tex app needs {error.name}: pip install 'mesh2tex[app]' (or make app)") from None
    from mesh2tex.app.jobs import Workshop

    sock = bind(cfg.host, cfg.port)
    workshop = None
    try:  # Ctrl-C at any point stops the server and deletes the visitors' files
        workshop = Workshop(cfg, keep=Path(args.out) if args.out else None, overwrite=args.overwrite)
        server = uvicorn.Server(uvicorn.Config(make_app(workshop), log_level="warning", access_log=False))
        workshop.start()
        announce(cfg.host, sock.getsockname()[1])
        server.run(sockets=[sock])
    except KeyboardInterrupt:  # uvicorn stops on Ctrl-C and SIGTERM, then raises the signal again: the way to stop
        pass
    finally:
        if workshop is not None:
            workshop.shutdown()
        sock.close()
    print("mesh2tex app: stopped; every visitor's files are deleted", flush=True)
    return 0
