# Two commands do all set-up on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
# The CPU wheel of torch; a GPU user installs their CUDA build of torch first (see README).
TORCH_SPEC ?= torch==2.13.0

.install-stamp: pyproject.toml
	$(PYTHON) -c "import torch" 2>/dev/null || $(PYTHON) -m pip install "$(TORCH_SPEC)"
	$(PYTHON) -m pip install -e ".[test]"
	touch .install-stamp

install: .install-stamp

test: .install-stamp
	$(PYTHON) -m pytest -q

demo: .install-stamp
	mesh2tex demo --out demo_out

.PHONY: install test demo
