# Two commands do all set-up on a fresh machine: `make demo` and `make test`.
# Everything installs into a virtual environment (.venv), so a distribution's externally managed
# Python (PEP 668) is never touched; VENV=path uses another environment.
PYTHON ?= python3
VENV ?= .venv
VPY = $(VENV)/bin/python
# The CPU wheel of torch; a GPU user installs their CUDA build of torch into the environment first (see README).
TORCH_SPEC ?= torch==2.13.0
# Where `make figures` keeps the world and renders it makes the README's images from.
FIGURES_WORK ?= build/figures

$(VPY):
	$(PYTHON) -m venv $(VENV)

.install-stamp: pyproject.toml $(VPY)
	$(VPY) -c "import torch" 2>/dev/null || $(VPY) -m pip install "$(TORCH_SPEC)"
	$(VPY) -m pip install -e ".[test,docs,app]"
	$(VPY) -c "from mesh2tex.render.kernels import warm_up; warm_up()"  # compile the rasterizer's CPU loop once
	touch .install-stamp

install: .install-stamp

# How many processes share the test suite (pytest-xdist): each test runs on one torch thread, so one per core.
# Each file's tests stay in one process, in order: some use what an earlier test of their file trained.
TEST_WORKERS ?= 2

# The linter (ruff.toml), the docs site in strict mode (a broken link or anchor fails), then the test suite.
test: .install-stamp lint docs
	$(VPY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile

lint: .install-stamp
	$(VPY) -m ruff check .
	$(VPY) -m ruff format --check .

docs: .install-stamp
	NO_MKDOCS_2_WARNING=1 $(VPY) -m mkdocs build --strict --site-dir build/site

# The CLI and config reference pages, from the parsers and config dataclasses (a test checks they are current).
reference: .install-stamp
	$(VPY) docs/gen_reference.py

demo: .install-stamp
	$(VPY) -m mesh2tex demo --out demo_out

# The local web page (docs/guide/app.md): http://127.0.0.1:7860/, this machine only; Ctrl-C stops it.
app: .install-stamp
	$(VPY) -m mesh2tex app

# The README's picture of four seeds of the shipped chair on a held-out chair (docs/results/index.md lists
# every image of the docs with the command that makes it).
figures: .install-stamp
	$(VPY) -m mesh2tex prepare synthetic --out $(FIGURES_WORK)/world --category chair --shapes 64 --views 8 \
	    --query-shapes 8 --query-views 2 --seed 0 --resolution 128 --variety real
	$(VPY) -m mesh2tex prepare shapes --input $(FIGURES_WORK)/world/meshes/chair_0058.obj --out $(FIGURES_WORK)/query \
	    --faces 1536 --levels 4 --seed 0
	$(VPY) -m mesh2tex infer generate --checkpoint chair --mesh $(FIGURES_WORK)/query/chair_0058.npz --seeds 0,1,2,3 \
	    --views 4 --resolution 128 --out $(FIGURES_WORK)/seeds --overwrite
	$(VPY) benchmarks/figures.py generate $(FIGURES_WORK)/seeds --pad 0 --out docs/images/shipped_chair_seeds.png

.PHONY: install test lint docs reference demo app figures
