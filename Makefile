# clothfem: every target bootstraps the machine first (Debian packages + .venv), idempotently.
SHELL := /bin/bash
PY := .venv/bin/python
# One BLAS/OpenMP thread per MPI rank: 2 ranks on 2 cores.
export OPENBLAS_NUM_THREADS := 1
export OMP_NUM_THREADS := 1
# One OpenBLAS kernel set on every x86-64 machine (the CPU-chosen kernels change round-off,
# and two contact tests are sensitive to it: docs/parallel.md)
export OPENBLAS_CORETYPE := Sandybridge
MPIRUN := mpirun --allow-run-as-root --oversubscribe -n 2
OUT ?= results

.PHONY: env test test-serial test-mpi test-slow lint demo demo-rollup demo-body demo-contact demo-pants study ladder extreme bench-arm verification bench bench-blas bench-stiff clean

env: .venv/.clothfem-installed

.venv/.clothfem-installed: pyproject.toml scripts/bootstrap.sh
	bash scripts/bootstrap.sh

## make test: the default suite, serial then on 2 MPI ranks
test: env
	$(MAKE) test-serial
	$(MAKE) test-mpi

test-serial: env
	$(PY) -m pytest -q -m "not slow" tests

test-mpi: env
	$(MPIRUN) $(PY) -m mpi4py -m pytest -q -m "not slow and not serial" -p no:cacheprovider --color=no tests

test-slow: env
	$(PY) -m pytest -q -m slow tests

lint: env
	.venv/bin/ruff check clothfem tests demos benchmarks
	.venv/bin/ruff format --check clothfem tests demos benchmarks

## make demo: the main demo, the arm-sleeve scene (docs/arm_sleeve.md); writes $(OUT)/arm-sleeve
demo: env
	$(PY) demos/arm_sleeve.py --out $(OUT)/arm-sleeve

demo-rollup: env
	$(PY) demos/rollup_strip.py --out $(OUT)/rollup

demo-body: env
	$(PY) demos/body_mocap.py --out $(OUT)/body

demo-contact: env
	$(PY) demos/contact_push.py --out $(OUT)/contact_push

## make demo-pants: pants donned onto the recorded lower body (particle model) and walked,
## 1 mm and 2 mm cotton on 2 ranks, and their right-knee torques (docs/results/pants_walk.md)
demo-pants: env
	for t in 1 2; do \
		$(MPIRUN) .venv/bin/clothfem run demos/scenes/pants_walk.toml --out $(OUT)/pants-walk-$${t}mm \
			--overwrite --set material.thickness=$${t}e-3 || exit 1; \
	done
	.venv/bin/clothfem plot $(OUT)/pants-walk-1mm $(OUT)/pants-walk-2mm --label "1 mm" "2 mm" \
		--x time --y torque_flex --title "right knee, pants on walking legs" \
		--out $(OUT)/pants_knee_torque.png

## make study: the five studies of Sec. 4.1 (benchmarks/arm_studies.py; hours on the default mesh)
STUDY_ARGS ?=
study: env
	$(PY) benchmarks/arm_studies.py --out $(OUT)/arm-studies $(STUDY_ARGS)

## make ladder: error of the torque-angle curve against run time (benchmarks/arm_ladder.py)
LADDER_ARGS ?=
ladder: env
	$(PY) benchmarks/arm_ladder.py --out $(OUT)/arm-ladder $(LADDER_ARGS)

## make extreme: stiff and extreme arm-sleeve cases (benchmarks/arm_extreme.py)
EXTREME_ARGS ?=
extreme: env
	$(PY) benchmarks/arm_extreme.py --out $(OUT)/arm-extreme $(EXTREME_ARGS)

## make bench-arm: per-step time split and the 2-rank speed-up (benchmarks/arm_perf.py)
bench-arm: env
	$(PY) benchmarks/arm_perf.py --out $(OUT)/arm-perf
	$(PY) benchmarks/arm_perf.py --integrator explicit --meshes 16x20 24x30 32x40 --angle 10 \
		--kernels numpy compiled --repeat 3 --out $(OUT)/arm-perf-explicit

## make verification: the shell verification table of docs/results/verification.md (results/verification.md)
verification: env
	$(PY) benchmarks/verification_table.py --out $(OUT)

bench: bench-blas
	$(PY) benchmarks/contact_projection.py

bench-blas: env
	$(PY) benchmarks/blas.py

## make bench-stiff: the stiff/extreme sleeve cases of docs/stiff_cases.md (~50 min: 180-s cap per implicit run)
bench-stiff: env
	$(PY) benchmarks/stiff_cases.py --out $(OUT)/stiff

clean:
	rm -rf $(OUT) .pytest_cache
