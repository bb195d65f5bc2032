# The two commands of the README. Both set up everything themselves (scripts/bootstrap).
.PHONY: run test lint bootstrap

# The main job: a full G2P learning run on the simulated rig (fast time), recorded to bags/<run-id>/
# with its report. Extra bring-up options: make run ARGS="--set learner.learner.seed=3"
run:
	scripts/with-env install/g2p_ros/lib/g2p_ros/bringup $(ARGS)

# Lint, then every test: core, simulator, hardware on fake buses, bags, nodes, and the whole graph in
# real processes.
test: lint
	scripts/with-env python -m pytest tests

# ruff (check and format) on everything, mypy --strict on the core library.
lint:
	scripts/with-env sh -c 'ruff check . && ruff format --check . && mypy'

bootstrap:
	scripts/bootstrap
