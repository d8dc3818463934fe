# One venv, torch CPU first (any other torch spec pulls a multi-GB CUDA build), then the package.
PYTHON ?= python3
VENV := .venv
# Where pip has no local CPU wheel of torch: make setup TORCH_PIP_ARGS='--index-url https://download.pytorch.org/whl/cpu'
TORCH_PIP_ARGS ?=
STAMP := $(VENV)/.installed

.PHONY: setup demo lint test test-all data train results v1

$(STAMP): pyproject.toml
	test -d $(VENV) || $(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install -q --upgrade pip
	$(VENV)/bin/pip install -q $(TORCH_PIP_ARGS) torch==2.13.0
	$(VENV)/bin/pip install -q -e '.[sim,test]'
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/garsim demo --out demo_out

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

test: $(STAMP)
	$(VENV)/bin/python -m pytest -q

test-all: $(STAMP)
	$(VENV)/bin/python -m pytest -q -m ""

# The v5 dataset (issue 8): the test / ood folder first, then the training folder, each on both workers. The test folder
# first: every candidate is judged on it, and on a machine that starts without ~/garsim-data the training folder's first
# jobs only remake what the shipped model was trained on. Each is resumable (rerun after an interruption: finished jobs
# are kept, a mismatched setting is refused); a run whose jobs failed transiently (exit status 3) is rerun, up to three
# times. Hours of CPU (~2.5 h for the test folder, ~15 h for the training folder on the 2-core host of 2026-12-07):
#   nohup make data > ~/garsim-data/generate.log 2>&1 &
DATA_ROOT ?= $(HOME)/garsim-data
GENERATE := $(VENV)/bin/garsim data generate --seed 0 --strap-pins crest --workers 2
data: $(STAMP)
	mkdir -p $(DATA_ROOT)
	for folder in "--out $(DATA_ROOT)/v5test --train 0 --test 260 --ood 64" "--out $(DATA_ROOT)/v5 --train 1800 --test 0 --ood 0"; do \
	  ok=0; for try in 1 2 3; do $(GENERATE) $$folder && { ok=1; break; }; sleep 10; done; [ $$ok = 1 ] || exit 1; \
	done

# The v1.0 training recipe from scratch on the v5 training folder (issue 9; docs/studies/scratch_v5.md: 48 minutes on
# 1,196 samples on the 2 cores), in resumable stages (rerun to continue); it prints the model folder to ship (stage 1,
# then the fine-tune and the fabric stage, each averaged with its start) and writes it to $(RUN)/model.txt. One
# remeshed variant per sample, not the rehearsals' two: on the complete folder (~3,150 samples) two would cache
# ~37,800 graphs, ~24 GB for the two processes before the cache shared equal tensors; one caches ~25,200 (~14-15 GB
# with the sharing, ~19 GB without), ~8 minutes an epoch, about 3 hours in all (docs/studies/training_cost.md):
#   nohup make train > ~/garsim-runs/train.log 2>&1 &     then: make results RUN=~/garsim-runs/v1/stage1 MODEL=<printed>
# The fabric stage (3 epochs of the heavy smoothed pair term and the fold term, averaged back) is in: in the session-30
# rehearsal it took the paired groups' ordering from 0.775 to 0.892 for +0.21 mm on test (docs/studies/scratch_v5.md).
TRAIN_DATA ?= $(DATA_ROOT)/v5
train: $(STAMP)
	DATA=$(TRAIN_DATA) OUT=$(RUN) PROCS=2 BATCH=4 LR=5e-4 STAGE1_EPOCHS=12 FINETUNE_EPOCHS=4 FABRIC_EPOCHS=3 \
	  STAGE2_EPOCHS=0 REMESH=1 MIRROR=1 PAIR=1 SOUP=1 bash examples/train_v1.sh

# The whole v1.0 path, one stage after the other, each resumed where it stopped (rerun the same command after an
# interruption; a finished stage is skipped): the dataset, its `data info` (docs/dataset.json), the recipe, then the
# candidate scored beside the shipped model on v5test (raw network, 95% intervals) and on the external set, into
# $(RUN)/candidate; shipping it and `make results` stay a decision:
#   mkdir -p ~/garsim-runs && nohup make v1 > ~/garsim-runs/v1.log 2>&1 &
v1: $(STAMP)
	$(MAKE) data
	$(VENV)/bin/garsim data info $(TRAIN_DATA) --json > docs/dataset.json.tmp && mv docs/dataset.json.tmp docs/dataset.json
	$(MAKE) train
	mkdir -p $(RUN)/candidate
	OMP_NUM_THREADS=1 $(VENV)/bin/garsim eval --data $(DATA) --model $$(cat $(RUN)/model.txt) --compare $(MODEL) \
	  --out $(RUN)/candidate/compare.json
	if [ -f $(EXTERNAL) ]; then OMP_NUM_THREADS=1 $(VENV)/bin/python $(EXTERNAL) --model $$(cat $(RUN)/model.txt) \
	  --json $(RUN)/candidate/external.json; fi

# The results report (docs/results.md and its figures) from the dataset, the model and its training run (when
# RUN exists; otherwise docs/training_curve.png is kept):
#   make results DATA=~/garsim-data/v5test RUN=~/garsim-runs/v1 MODEL=garsim/weights
# (DATA: `garsim data generate --out ~/garsim-data/v5test --seed 0 --train 0 --test 260 --ood 64 --strap-pins crest`)
DATA ?= $(HOME)/garsim-data/v5test
RUN ?= $(HOME)/garsim-runs/v1
MODEL ?= garsim/weights
EXTERNAL := ../shared/external-eval/check.py
# one thread per process, as every committed figure was measured (the bench records it)
results: export OMP_NUM_THREADS := 1
results: $(STAMP)
	$(VENV)/bin/garsim eval --data $(DATA) --model $(MODEL) --refine --out docs/results.json
	$(VENV)/bin/garsim eval --data $(DATA) --model $(MODEL) --resolution full --out docs/results_full.json
	$(VENV)/bin/garsim eval --data $(DATA) --model $(MODEL) --by construction canonical_pose pose_mode fabric \
	  --out docs/results_by.json
	if [ -f $(EXTERNAL) ]; then \
	  $(VENV)/bin/python $(EXTERNAL) --model $(MODEL) --json docs/external_default.json && \
	  $(VENV)/bin/python examples/external_check.py --model $(MODEL) --raw --json docs/external_raw.json && \
	  $(VENV)/bin/python examples/external_check.py --prior-only --refine --json docs/external_prior_refine.json; fi
	$(VENV)/bin/python examples/robustness.py --model $(MODEL) --data tests/fixtures/dataset_v2 --data $(DATA) --split test \
	  --per-type 10 --noise-draws 3 $$([ -f $(EXTERNAL) ] && echo --external $(dir $(EXTERNAL))data) --json docs/robustness.json
	$(VENV)/bin/garsim bench --model $(MODEL) --sizes 600 2400 10000 40000 --garment skirt --repeats 9 \
	  --newton --newton-max 2400 --out docs/bench.json
	$(VENV)/bin/python examples/make_report.py --run $(patsubst %/log.csv,%,$(wildcard $(RUN)/log.csv)) --model $(MODEL) --data $(DATA) \
	  --results docs/results.json --results-full docs/results_full.json --results-by docs/results_by.json --bench docs/bench.json \
	  $$([ -f docs/external_default.json ] && echo --external-default docs/external_default.json) \
	  $$([ -f docs/external_raw.json ] && echo --external-raw docs/external_raw.json) \
	  $$([ -f docs/external_prior_refine.json ] && echo --external docs/external_prior_refine.json) \
	  --robustness docs/robustness.json
