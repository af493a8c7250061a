# Two commands on a fresh machine: `make run` (service) and `make test` (test suite).
# The first one installs everything (a few minutes on a fresh machine; every step says what it does).
PYTHON ?= python3.11
VENV   ?= .venv
BIN     = $(VENV)/bin
STAMP   = $(VENV)/.installed
# PyTorch's CPU wheels: torch 2.13.0+cpu from there wins over PyPI's CUDA build of 2.13.0 (a higher
# version for pip). Where the index is unreachable (an offline mirror, a local wheel folder), setup says so
# and takes the torch pip is configured to find; either way step 4 fails on a CUDA build.
TORCH_INDEX ?= https://download.pytorch.org/whl/cpu

.PHONY: run test setup bench lint clean

$(STAMP): pyproject.toml
	@echo "==> [1/4] creating the virtual environment $(VENV) with $(PYTHON)"
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --upgrade pip
	@echo "==> [2/4] PyTorch 2.13.0, CPU build (about 200 MB; first, so nothing later pulls a CUDA build)"
	@if $(BIN)/python -c "import urllib.request as u; u.urlopen('$(TORCH_INDEX)/', timeout=10)" 2>/dev/null; then \
	    echo "$(BIN)/pip install --extra-index-url $(TORCH_INDEX) torch==2.13.0"; \
	    $(BIN)/pip install --extra-index-url $(TORCH_INDEX) torch==2.13.0; \
	else \
	    echo "    $(TORCH_INDEX) is unreachable: installing the torch pip is configured to find (step 4 checks it)"; \
	    echo "$(BIN)/pip install torch==2.13.0"; \
	    $(BIN)/pip install torch==2.13.0; \
	fi
	@echo "==> [3/4] vtdslam and its pinned dependencies (the longest step: a few minutes on a fresh machine)"
	$(BIN)/pip install -e '.[dev]'
	@echo "==> [4/4] checking that torch is the CPU build"
	$(BIN)/python -c "import sys, torch; cuda = torch.version.cuda; print('torch', torch.__version__, f'is a CUDA {cuda} build: see TORCH_INDEX in the Makefile' if cuda else 'CPU build: ok'); sys.exit(1 if cuda else 0)"
	touch $(STAMP)
	@echo "==> setup done"

setup: $(STAMP)

run: $(STAMP)
	@# First start: a demo sequence and a queued job, so the dashboard opens on a run.
	@[ -d "$${VTD_DATA_DIR:-data}/demo" ] || { echo "==> first start: making a demo sequence and queuing a job"; $(BIN)/vtdslam demo; }
	@echo "==> dashboard at http://$${VTD_HOST:-127.0.0.1}:$${VTD_PORT:-8000}/ (api, worker and 3D viewer; this terminal stays with them: Ctrl-C stops all)"
	$(BIN)/vtdslam serve

# Static checks: import contracts, ruff, mypy (settings in pyproject.toml); `make test` runs them first.
lint: $(STAMP)
	@echo "==> import contracts"
	$(BIN)/lint-imports --no-cache
	@echo "==> lint (ruff)"
	$(BIN)/ruff check .
	@echo "==> types (mypy)"
	$(BIN)/mypy

test: lint
	@echo "==> test suite"
	$(BIN)/python -m pytest $(PYTEST_ARGS)

bench: $(STAMP)
	bash bench/run_all.sh

clean:
	rm -rf $(VENV) .pytest_cache
