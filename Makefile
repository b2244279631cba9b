# pose_lifter — every set-up step lives here; each target is idempotent.
#   make demo   lift a committed bag and print its error table (sets everything up first)
#   make test   lint, type-check and run every test, ROS graph tests included
SHELL := /bin/bash
.DEFAULT_GOAL := help
PY_BOOT ?= python3
VENV := $(CURDIR)/.venv
PY := $(VENV)/bin/python
UV := $(VENV)/bin/uv
PKG := ros2_ws/src/pose_lifter
CMU_DATA ?= $(CURDIR)/../shared/data/cmu
export PYTHONHASHSEED := 0
# one BLAS thread: deterministic timings, the solver runs on one core
export OMP_NUM_THREADS := 1
export OPENBLAS_NUM_THREADS := 1
export MKL_NUM_THREADS := 1

.PHONY: help venv test test-fast test-fp2 lint demo bench bench-node bench-lag bench-lift bench-collection bench-prior \
  lift-hash mutants fuzz soak experiments bases bags bag-bands prior prior-temporal prior-offline prior-temporal-cut \
  prior-offline-cut prior-fixture \
  actions-model accuracy rgbd-accuracy rgbd-accuracy-short rgbd-cross-action depth-calibration lock clean ros cross-action train-deps

help:
	@echo "make demo        lift a committed bag, print errors, write out/demo.mcap + out/demo.png"
	@echo "make test        ruff + mypy + all tests (offline and ROS graph; tests/core also under a 2nd BLAS/CPU set-up)"
	@echo "make ros         build ros2_ws (messages + node) with colcon"
	@echo "make bench       speed: fast path vs cvxpy reference, side by side"
	@echo "make bench-node  speed of the installed node at 30 Hz with 5 people"
	@echo "make fuzz        10,000 malformed messages of 28 kinds into the installed node (~6 min)"
	@echo "make soak        10 min at 30 Hz x 5 people, reliable input, RSS every 10 s"
	@echo "make experiments the paper's experiments on CMU data -> out/experiments"
	@echo "make bases       re-learn the packaged basis file from ../shared/data/cmu"
	@echo "make bags        regenerate the committed bags from ../shared/data/cmu"
	@echo "make prior       re-train the packaged learned prior (data/prior_mlp.npz, PyTorch, ~20 min loaded)"
	@echo "make cross-action  leave-one-class-out accuracy on unseen motion -> out/cross_action (~1 h)"
	@echo "make prior-temporal  re-train its causal temporal variant (data/prior_mlp_w4.npz, ~25 min loaded)"
	@echo "make prior-offline   re-train the offline variant, past and future (data/prior_mlp_w7c.npz, ~15 min)"
	@echo "make prior-temporal-cut, prior-offline-cut  their variants for bodies the image cuts (data/*_crop.npz)"
	@echo "make accuracy    paper / learned / hybrid on the evaluation split -> out/accuracy/accuracy.md (~25 min)"
	@echo "make rgbd-accuracy   mono / naive depth lookup / fused / fused-lag at 1.5, 3, 5 m -> out/rgbd_accuracy (~6 min)"
	@echo "make rgbd-cross-action  the same on unseen motion, per cross-action fold and their mean (~3 min; needs make cross-action)"
	@echo "make depth-calibration  the depth fusion's constants measured on the training split (printed)"
	@echo "make rgbd-accuracy-short  the same on 3 trials x 30 frames, one view -> out/rgbd_accuracy_short (~20 s)"
	@echo "make bench-lag   what the node's output_lag costs per person-frame (bags/five_people.mcap)"
	@echo "make bench-lift BEFORE=DIR BAG=FILE      pose-lifter lift of this checkout vs DIR's, side by side"
	@echo "make bench-collection BEFORE=DIR BAG=FILE  the same over a collection of copies of BAG"
	@echo "make bench-prior  the learned priors' layer pass per row at 1-72 rows, and this CPU's facts"
	@echo "make lift-hash   a hash of every committed bag's lifts: equal before and after a refactor (same machine)"
	@echo "make mutants     every planted regression of tests/mutants must fail its tests (kernel plants: minutes each)"
	@echo "make bag-bands   the committed bags' errors at the tests' replay settings (tests/tolerances.py BAG_REPLAY_MM)"
	@echo "make actions-model   re-train the action example's model (data/actions_knn.npz) and print its accuracy"
	@echo "make prior-fixture   regenerate tests/fixtures/prior_torch.npz (torch's outputs of a small prior)"

$(VENV)/.stamp: requirements.lock $(PKG)/setup.py $(PKG)/setup.cfg
	@test -x $(PY) || $(PY_BOOT) -m venv $(VENV)
	@test -x $(UV) || $(PY) -m pip install -q 'uv==0.13.9'
	$(UV) pip install --system-certs -q -p $(PY) -r requirements.lock
	$(UV) pip install --system-certs -q -p $(PY) --no-deps -e $(PKG)
	@touch $@

# uv installs without bytecode, and where PYTHONDONTWRITEBYTECODE is set Python never caches it:
# every `pose-lifter` run then compiles numpy, scipy, numba and rosbags from source (its imports:
# 3.7 s of CPU instead of 1.1). Compiled once here, after every install.
$(VENV)/.bytecode: $(VENV)/.stamp
	$(PY) -m compileall -q -j 0 $$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])') \
	  $(PKG)/pose_lifter > /dev/null || true
	@touch $@

# numba caches the compiled solver kernels beside the sources, so the place the package is imported
# from (this editable tree; the colcon install, see `ros`) needs them compiled once: done here,
# so that a user's first `pose-lifter lift` is as fast as the second (~1 s when already cached)
venv: $(VENV)/.stamp $(VENV)/.bytecode
	@$(PY) -m pose_lifter.cli warm-up

lock:
	$(UV) pip compile --system-certs -p .venv/bin/python requirements.in -o requirements.lock

lint: venv
	$(VENV)/bin/ruff check $(PKG)/pose_lifter tests tools
	$(VENV)/bin/mypy

# The numerically sensitive tests (tests/core) once more under a second floating-point
# configuration: OpenBLAS's SSE3 kernels (OPENBLAS_CORETYPE=Prescott runs on every x86-64 CPU)
# and numba compiling for a generic x86-64 (no FMA, no AVX). A test that holds only with this
# machine's BLAS kernel or vector width fails here, on the developer's machine, first.
FP2_ENV := OPENBLAS_CORETYPE=Prescott NUMBA_CPU_NAME=generic
test-fp2: venv
	$(FP2_ENV) $(PY) -m pytest -q -p no:cacheprovider tests/core

test: venv ros lint test-fp2
	$(PY) -m pytest -q tests

test-fast: venv
	$(PY) -m pytest -q -m "not ros" tests

demo: venv
	$(PY) -m pose_lifter.cli demo --out out

bench: venv ros
	$(PY) tools/bench.py

# the installed node fed bags/five_people.mcap at 30 Hz (issue 5's live measurement)
bench-node: venv ros
	source ros2_ws/install/setup.bash && $(PY) tools/bench_node.py

# the frame pipeline as the node runs it, without an output lag and with one (tools/bench_lag.py)
bench-lag: venv
	$(PY) tools/bench_lag.py $(BENCH_LAG_ARGS)

# end-to-end `pose-lifter lift` of this checkout against the checkout BEFORE (e.g. `git worktree add
# --detach ../before main`), alternating, on BAG; bench-collection: a collection of copies of BAG
BEFORE ?= ../before
BAG ?= bags/five_people.mcap
bench-lift: venv
	$(PY) tools/bench_lift.py $(BAG) --before $(BEFORE) $(BENCH_LIFT_ARGS)

bench-collection: venv
	$(PY) tools/bench_collection.py $(BAG) --before $(BEFORE) --work out/bench_collection $(BENCH_COLLECTION_ARGS)

# the priors' layer pass per row at a few row counts, with the CPU model, numba's target and
# OpenBLAS's kernel: what differs between machines (docs/bench.md, the CPU kinds)
bench-prior: venv
	$(PY) tools/bench.py --prior-rows

# a refactor that changes no result keeps these hashes (on one machine and install; tools/lift_hash.py)
lift-hash: venv
	$(PY) tools/lift_hash.py $(LIFT_HASH_ARGS)

# each plant of tests/mutants/plants.py applied to a copy of the package; its tests must fail.
# MUTANTS_ARGS='--only SUBSTRING' runs some of them.
mutants: venv
	$(PY) tests/mutants/run.py $(MUTANTS_ARGS)

# issue 10's long runs against the installed node (tools/reliability_node.py; CI runs short
# versions in tests/ros/test_long_runs.py). FUZZ_ARGS / SOAK_ARGS pass options through.
fuzz: venv ros
	source ros2_ws/install/setup.bash && $(PY) tools/reliability_node.py fuzz $(FUZZ_ARGS)

soak: venv ros
	source ros2_ws/install/setup.bash && $(PY) tools/reliability_node.py soak $(SOAK_ARGS)

experiments: venv
	$(PY) -m pose_lifter.cli experiments --data $(CMU_DATA) --out out/experiments

bases: venv
	bash tools/learn_default_bases.sh $(CMU_DATA)

bags: venv
	bash tools/make_bags.sh $(CMU_DATA)

# the error bands of tests/offline/test_bags.py (tests/tolerances.py BAG_REPLAY_MM, bags/README.md)
bag-bands: venv
	$(PY) tools/bag_bands.py $(BAG_BANDS_ARGS)

# the learned 2D->3D prior, trained on the training split (tools/train_prior.py defaults: residual
# MLP, the augmentation GENERALISE, 24 x 100k samples, seed 0, one thread; PyTorch for training only),
# its cameras 1.5-10 m from the person (PRIOR_AUG; docs/accuracy.md, its decisions)
PRIOR_AUG := --aug 'distance=(1.5,10.0)'
prior: venv train-deps
	$(PY) tools/train_prior.py --data $(CMU_DATA) $(PRIOR_AUG)

# the causal temporal variant (the track's last 4 frames at 30 Hz) used on tracked frames: the same
# recipe with dropout 0.05 (at 0.25 it drew almost nothing from the past frames; docs/cross_action.md)
prior-temporal: venv train-deps
	$(PY) tools/train_prior.py --data $(CMU_DATA) --window 4 --dropout 0.05 $(PRIOR_AUG) \
	  --out $(PKG)/pose_lifter/data/prior_mlp_w4.npz

# the offline variant pose-lifter lift reads (7 frames at 30 Hz, 3 before the lifted one and 3
# after; normalised on the lifted frame): the same recipe with --future 3 (docs/accuracy.md)
prior-offline: venv train-deps
	$(PY) tools/train_prior.py --data $(CMU_DATA) --window 7 --future 3 --dropout 0.05 $(PRIOR_AUG) \
	  --out $(PKG)/pose_lifter/data/prior_mlp_w7c.npz

# the variants of the tracked frames whose 2D lacks a shoulder (a person close to the camera, cut
# by the image's top border; core/lift/hybrid.py PriorFit): a tenth of the samples cut at both
# ends by the image's borders (~6 and ~8 min idle)
prior-temporal-cut: venv train-deps
	$(PY) tools/train_prior.py --data $(CMU_DATA) --window 4 --dropout 0.05 $(PRIOR_AUG) \
	  --aug p_crop=0.1 --out $(PKG)/pose_lifter/data/prior_mlp_w4_crop.npz

prior-offline-cut: venv train-deps
	$(PY) tools/train_prior.py --data $(CMU_DATA) --window 7 --future 3 --dropout 0.05 $(PRIOR_AUG) \
	  --aug p_crop=0.1 --out $(PKG)/pose_lifter/data/prior_mlp_w7c_crop.npz

# the action example's k-NN model on lifted windows (hybrid mode, tracked), and its accuracy against 2D
actions-model: venv
	$(PY) tools/action_recognition_eval.py --data $(CMU_DATA) --lifted-train 3000 --model-input lifted \
	  --model-out $(PKG)/pose_lifter/data/actions_knn.npz --json out/actions.json

# torch's outputs of a small trained prior, which tests/mocap/test_prior_training.py checks the numpy prior against
prior-fixture: venv train-deps
	$(PY) tests/fixtures/make_prior_torch.py

# the accuracy table (out/accuracy/accuracy.md, stamped with the commit and the CPU model) and plot
# (evaluation split: subjects 02, 07, 08 and 09_12; the perspective tracks' lifts know the camera's
# intrinsics, as the node with camera_info)
accuracy: venv
	$(PY) tools/accuracy.py --data $(CMU_DATA) --frames 90 --views 4 --workers 2 --intrinsics --out out/accuracy

# metric accuracy with a depth camera (out/rgbd_accuracy/rgbd_accuracy.md, stamped): the evaluation split
# filmed at 1.5, 3 and 5 m through the realistic detector and depth sensor, the monocular lift, the
# naive depth lookup, the fused lift and the fused lift three frames late (tools/rgbd_accuracy.py;
# a cross-action fold's class with its fold's priors: --fold CLASS --folds out/cross_action/folds)
rgbd-accuracy: venv
	$(PY) tools/rgbd_accuracy.py --data $(CMU_DATA) --frames 90 --views 2 --elevated --workers 2 \
	  --out out/rgbd_accuracy

# the depth fusion's constants (pose_lifter.mocap.depth_calibration) measured on the training split's
# trials the packaged prior was not fitted on; printed, to be copied into core/depth
depth-calibration: venv
	$(PY) tools/rgbd_accuracy.py --calibrate --data $(CMU_DATA) --frames 60 --views 2 --elevated

# the same on unseen motion: each motion class lifted by the priors trained without it (make
# cross-action trains them), 8 trials a class, one view; the mean over the classes
RGBD_CLASSES := walk run jump punch dance basketball playground other
rgbd-cross-action: venv
	for c in $(RGBD_CLASSES); do $(PY) tools/rgbd_accuracy.py --data $(CMU_DATA) --fold $$c --frames 60 --views 1 \
	  --max-trials 8 --workers 2 --methods mono naive fused fused-lag --out out/rgbd_cross_action/$$c || exit 1; done
	$(PY) tools/rgbd_accuracy.py --merge $(addprefix out/rgbd_cross_action/,$(RGBD_CLASSES)) \
	  --out out/rgbd_cross_action

rgbd-accuracy-short: venv
	$(PY) tools/rgbd_accuracy.py --data $(CMU_DATA) --frames 30 --views 1 --max-trials 3 --workers 2 \
	  --out out/rgbd_accuracy_short

# ROS 2 build: colcon builds ros2_ws (pose_lifter_msgs + pose_lifter) against the ros-jazzy
# wheels in the venv. CMAKE_PROJECT_INCLUDE works around the wheels' baked-in /opt/python
# include dirs (tools/colcon_fix_python_include.cmake; a no-op on a normal Jazzy install).
# ros2_ws/vendor holds hri_msgs and tf2_msgs (what the node publishes; no wheel exists for them) and
# tests/ros/msgs yolo_msgs (the adapter's graph tests): both have a COLCON_IGNORE, so they are named here.
# Afterwards: `source ros2_ws/install/setup.bash`, then run ros2_ws/install/pose_lifter/lib/pose_lifter/lifter.
ros: venv
	cd ros2_ws && PATH="$(VENV)/bin:$$PATH" VIRTUAL_ENV="$(VENV)" \
	  AMENT_PREFIX_PATH="$(VENV)" CMAKE_PREFIX_PATH="$(VENV)" \
	  $(VENV)/bin/colcon --log-level warning build --event-handlers console_direct- summary- \
	  --base-paths src vendor/hri_msgs vendor/tf2_msgs ../tests/ros/msgs/yolo_msgs \
	  --cmake-args -DCMAKE_PROJECT_INCLUDE=$(CURDIR)/tools/colcon_fix_python_include.cmake \
	  -DPython3_EXECUTABLE=$(PY) -DBUILD_TESTING=OFF
	@# compile the solver kernels into the installed package's cache now, so the first start of
	@# the node is ready in about a second instead of compiling for ~25 s (a no-op when cached)
	source ros2_ws/install/setup.bash && ros2_ws/install/pose_lifter/lib/pose_lifter/lifter --warm-up

clean:
	rm -rf ros2_ws/build ros2_ws/install ros2_ws/log out

# the training-only library of the learned prior (the optional extra `train`: PyTorch). pip, not uv:
# pip also looks in PIP_FIND_LINKS, where these machines keep the CPU build of torch 2.13.0 (uv would
# fetch the CUDA build from the index, about 4 GB)
train-deps: venv
	$(PY) -c "import torch" 2>/dev/null || $(PY) -m pip install -q 'torch==2.13.0'

# accuracy on motion never trained on: per motion class of the manifest, a prior trained without it
# and its temporal and offline priors, the lifts knowing the camera's intrinsics (tools/cross_action.py;
# docs/cross_action.md)
cross-action: venv train-deps
	$(PY) tools/cross_action.py --data $(CMU_DATA) --epochs 6 --samples 40000 --frames 60 --segments 6 \
	  --views 2 --temporal --cut --offline --intrinsics --out out/cross_action
