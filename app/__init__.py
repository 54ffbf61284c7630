"""``mesh2tex app``: a local web page that textures a visitor's mesh and shows it in 3D.

The server (:mod:`mesh2tex.app.server`) runs the real commands (``infer generate|transfer|nca|synthesize``)
as subprocesses, one job folder per visitor (:mod:`mesh2tex.app.jobs`), after the uploads are checked as
the commands check them (:mod:`mesh2tex.app.uploads`); the page (``static/``) shows their progress and
the textured GLB in Google's ``<model-viewer>``, vendored so that the page works offline.
"""
