# The two commands of the README. Both set up everything themselves (scripts/bootstrap).
.PHONY: test lint bootstrap

# Every test: core, simulator, bags, nodes and whole-graph tests in real processes.
test:
	scripts/with-env python -m pytest tests

# ruff and mypy on the core library.
lint:
	scripts/with-env sh -c 'ruff check src tests benchmarks g2p_ros g2p_sim g2p_learner g2p_driver && mypy'

bootstrap:
	scripts/bootstrap
