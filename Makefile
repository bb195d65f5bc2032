# The two commands of the README. Both set up everything themselves (scripts/bootstrap).
.PHONY: run test lint bootstrap

# The main job: a full G2P learning run on the simulated rig (fast time), recorded to bags/<run-id>/
# with its report. Extra bring-up options: make run ARGS="--set learner.learner.seed=3"
run:
	scripts/with-env install/g2p_ros/lib/g2p_ros/bringup $(ARGS)

# Every test: core, simulator, bags, nodes and whole-graph tests in real processes.
test:
	scripts/with-env python -m pytest tests

# ruff and mypy on the core library.
lint:
	scripts/with-env sh -c 'ruff check src tests benchmarks g2p_ros g2p_sim g2p_learner g2p_driver && mypy'

bootstrap:
	scripts/bootstrap
