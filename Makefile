# Two commands do all set-up on a fresh machine: `make demo` and `make test`.
# Everything installs into a virtual environment (.venv), so a distribution's externally managed
# Python (PEP 668) is never touched; VENV=path uses another environment.
PYTHON ?= python3
VENV ?= .venv
VPY = $(VENV)/bin/python
# The CPU wheel of torch; a GPU user installs their CUDA build of torch into the environment first (see README).
TORCH_SPEC ?= torch==2.13.0

$(VPY):
	$(PYTHON) -m venv $(VENV)

.install-stamp: pyproject.toml $(VPY)
	$(VPY) -c "import torch" 2>/dev/null || $(VPY) -m pip install "$(TORCH_SPEC)"
	$(VPY) -m pip install -e ".[test]"
	$(VPY) -c "from mesh2tex.render.kernels import warm_up; warm_up()"  # compile the rasterizer's CPU loop once
	touch .install-stamp

install: .install-stamp

test: .install-stamp
	$(VPY) -m pytest -q

demo: .install-stamp
	$(VPY) -m mesh2tex demo --out demo_out

.PHONY: install test demo
