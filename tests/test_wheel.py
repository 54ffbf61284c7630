"""The wheel, installed into a fresh virtual environment outside the source tree, textures a mesh with a
shipped model, and claims no top-level import name but ``mesh2tex``."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def listed_packages() -> set[str]:
    """The packages pyproject.toml's [tool.setuptools] lists."""
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    return set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])


def test_every_package_folder_is_in_the_wheel_list():
    """A new subpackage of mesh2tex (or of a stage) that pyproject.toml does not list would be missing
    from an installed wheel, though every test in the source tree passes."""
    found = {
        ".".join(("mesh2tex", *p.parent.relative_to(ROOT / "mesh2tex").parts)).rstrip(".")
        for p in (ROOT / "mesh2tex").rglob("__init__.py")
    }
    found |= {
        "mesh2tex." + ".".join(p.parent.relative_to(ROOT).parts)
        for stage in ("data_prep", "train", "infer", "evaluate", "app")
        for p in (ROOT / stage).rglob("__init__.py")
    }
    assert found == listed_packages()


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel, built from a copy of the tracked sources (a build in the checkout would leave build/ there)."""
    pytest.importorskip("setuptools")
    folder, source = tmp_path_factory.mktemp("wheel"), tmp_path_factory.mktemp("source")
    tracked = (
        subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT,
            check=True,
            capture_output=True,
        )
        .stdout.decode()
        .split("\0")
    )
    for name in filter(None, tracked):
        if (ROOT / name).is_file() and name.split("/")[0] in (
            "mesh2tex",
            "data_prep",
            "train",
            "infer",
            "evaluate",
            "app",
            "pyproject.toml",
            "README.md",
            "LICENSE",
        ):
            (source / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, source / name)
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            str(source),
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(folder),
        ],
        check=True,
        capture_output=True,
        cwd=folder,
    )
    (built,) = folder.glob("mesh2tex-*.whl")
    return built


def test_the_wheel_claims_only_mesh2tex(wheel):
    with zipfile.ZipFile(wheel) as archive:
        tops = {name.split("/")[0] for name in archive.namelist() if not name.split("/")[0].endswith(".dist-info")}
        names = set(archive.namelist())
    assert tops == {"mesh2tex"}
    assert {
        "mesh2tex/infer/generate.py",
        "mesh2tex/train/gan.py",
        "mesh2tex/data_prep/shapes.py",
        "mesh2tex/models/chair/generator.safetensors",
        "mesh2tex/models/car/noc.safetensors",
    } <= names


def test_the_installed_wheel_textures_a_mesh_with_a_shipped_model(wheel, tmp_path):
    """pip installs the wheel into a new environment whose only other packages are this one's
    dependencies (seen through a path file, so this checkout's editable install is not); from a folder
    outside the checkout, ``mesh2tex infer generate --checkpoint chair`` writes the textured mesh."""
    import trimesh
    from user_assets import stool

    env = tmp_path / "env"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env)], check=True)
    python = env / "bin" / "python"
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    (Path(site) / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "-q", str(wheel)],
        check=True,
        capture_output=True,
    )

    work = tmp_path / "elsewhere"
    work.mkdir()
    stool().export(work / "stool.ply")
    clean = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MESH2TEX_MODELS")}
    where = subprocess.run(
        [
            str(python),
            "-c",
            "import mesh2tex, importlib.util as u; print(mesh2tex.__file__); "
            "print(u.find_spec('infer'), u.find_spec('train'), u.find_spec('data_prep'))",
        ],
        cwd=work,
        env=clean,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.splitlines()
    assert where[0].startswith(site) and where[1] == "None None None"
    result = subprocess.run(
        [
            str(env / "bin" / "mesh2tex"),
            "infer",
            "generate",
            "--checkpoint",
            "chair",
            "--mesh",
            "stool.ply",
            "--out",
            "out",
            "--seeds",
            "0,1",
            "--views",
            "1",
            "--resolution",
            "32",
            "--texture-size",
            "64",
            "--device",
            "cpu",
        ],
        cwd=work,
        env=clean,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    glb = trimesh.load(work / "out" / "seed1.glb", force="mesh", process=False)
    assert len(glb.faces) == len(stool().faces)
