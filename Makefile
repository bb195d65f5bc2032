# The two commands of the README. Both set up everything themselves (scripts/bootstrap).
.PHONY: run test test-core test-ros test-jazzy lint bootstrap

# The ROS suites run on ROS 2 Jazzy (the Raspberry Pi's distribution) as well as on Kilted.
ROS_SUITES := tests/ros tests/system

# The main job: a full G2P learning run on the simulated rig (fast time), recorded to bags/<run-id>/
# with its report. Extra bring-up options: make run ARGS="--set learner.learner.seed=3"
run:
	scripts/with-env scripts/ros2-run g2p_bringup bringup $(ARGS)

# Lint, then every test on ROS 2 Kilted (core, simulator, hardware on fake buses, bags, nodes, the whole
# graph in real processes, and on two hosts with the rig on Jazzy), and the ROS suites on ROS 2 Jazzy.
# The three suites run side by side: the core's are CPU-bound, the ROS suites mostly wait on processes
# (each test session has a ROS domain, and two-host namespaces, of its own). Each prints when it ends.
test: bootstrap lint
	$(MAKE) --no-print-directory -j3 --output-sync=target test-core test-ros test-jazzy

# ROS 2 Kilted: everything but the ROS suites.
test-core:
	scripts/with-env python -m pytest --durations=15 $(addprefix --ignore=,$(ROS_SUITES) tests/twohost) tests

# ROS 2 Kilted: the nodes, the graph in processes, two hosts.
test-ros:
	scripts/with-env python -m pytest --durations=15 $(ROS_SUITES) tests/twohost

# ROS 2 Jazzy (the Raspberry Pi's): the nodes and the graph in processes.
test-jazzy:
	G2P_ROS_DISTRO=jazzy scripts/with-env python -m pytest --durations=15 $(ROS_SUITES)

# ruff (check and format) on everything, mypy --strict on the core library.
lint:
	scripts/with-env sh -c 'ruff check . && ruff format --check . && mypy'

# Both distributions at once (pip and colcon leave a core idle much of the time); the two-host tests run
# the rig side on Jazzy.
bootstrap:
	scripts/bootstrap & kilted=$$!; G2P_ROS_DISTRO=jazzy scripts/bootstrap; jazzy=$$?; \
	  wait $$kilted && exit $$jazzy
