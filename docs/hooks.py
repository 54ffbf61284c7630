"""mkdocs hooks: the pages keep the relative links a forge shows (README.md at the root, model cards beside
their weights), and the site gets them too.

* README.md becomes the site's home page (``index.md``): its ``docs/...`` links lose the ``docs/``.
* Each model card ``mesh2tex/models/NAME/card.md`` (and the images beside it) becomes ``models/NAME.md``.
* A link from a page to another file of the repository (a script, a test, a card) is rewritten to the
  site page that holds it, or to the file's path as code when the site has no page for it; a link to a
  file that does not exist is reported, which fails the strict build.
"""

from __future__ import annotations

import logging
import posixpath
import re
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "mesh2tex" / "models"
LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")
log = logging.getLogger("mkdocs.hooks.mesh2tex")


def _cards():
    return sorted(p for p in MODELS.glob("*/card.md"))


def on_files(files, config):
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    files.append(File.generated(config, "index.md", content=_readme_as_home(readme)))
    for card in _cards():
        name = card.parent.name
        files.append(File.generated(config, f"models/{name}.md", content=card.read_text(encoding="utf-8")))
        for image in sorted(card.parent.glob("*.png")):
            files.append(File.generated(config, f"models/{name}/{image.name}", abs_src_path=str(image)))
    return files


def _readme_as_home(text: str) -> str:
    def fix(match):
        bang, label, target = match.groups()
        if target.startswith("docs/"):
            target = target[len("docs/") :]
        elif not re.match(r"[a-z]+:", target) and not target.startswith("#"):
            target = "../" + target  # a file of the repository: resolved by on_page_markdown
        return f"{bang}[{label}]({target})"

    return LINK.sub(fix, text).replace('src="docs/', 'src="')


def on_page_markdown(markdown, page, config, files):
    src = page.file.src_uri
    if src == "index.md":
        page_dir = "docs"
    elif src.startswith("models/"):
        page_dir = f"mesh2tex/models/{Path(src).stem}"
    else:
        page_dir = posixpath.dirname(f"docs/{src}")
    site_dir = posixpath.dirname(src)

    def fix(match):
        bang, label, target = match.groups()
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            return match.group(0)
        path, _, anchor = target.partition("#")
        if src.startswith("models/"):
            in_repo = posixpath.normpath(posixpath.join(page_dir, path))
            if in_repo.startswith(f"mesh2tex/models/{Path(src).stem}/"):  # an image beside the card
                site_target = f"models/{Path(src).stem}/{posixpath.basename(path)}"
                return f"{bang}[{label}]({posixpath.relpath(site_target, site_dir)}{'#' + anchor if anchor else ''})"
        else:
            in_repo = posixpath.normpath(posixpath.join(page_dir, path))
        if in_repo.startswith("docs/"):
            site_target = in_repo[len("docs/") :]
        elif in_repo == "README.md":
            site_target = "index.md"
        elif re.fullmatch(r"mesh2tex/models/[^/]+/card\.md", in_repo):
            site_target = f"models/{in_repo.split('/')[2]}.md"
        elif re.fullmatch(r"mesh2tex/models/[^/]+/[^/]+\.png", in_repo):
            site_target = "models/" + "/".join(in_repo.split("/")[2:])
        else:
            if not (ROOT / in_repo).exists():
                log.warning(f"Doc file '{src}' links to '{target}', which is not in the repository ({in_repo})")
            return f"`{label}`" if not label.startswith("`") else label
        rel = posixpath.relpath(site_target, site_dir) if site_dir else site_target
        return f"{bang}[{label}]({rel}{'#' + anchor if anchor else ''})"

    return LINK.sub(fix, markdown)
