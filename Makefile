# Two commands on a fresh machine:  make demo   and   make test
# ROS 2 Jazzy by default; ROS_DISTRO=kilted make <target> for Kilted (docs/setup.md, scripts/distro.sh).
SHELL := /bin/bash
.DEFAULT_GOAL := help
RUN := scripts/run.sh

help:
	@echo "make demo       run the node graph on the default input, write out/ (bag, animation, plots)"
	@echo "make test       bootstrap if needed and run the test suite (lint included)"
	@echo "make lint       only the linter (ruff, configured in ruff.toml)"
	@echo "make setup      only bootstrap (venv / ROS 2, launch tooling, colcon build); ROS_DISTRO=kilted for Kilted"
	@echo "make warm-kernels  compile the numba kernels into their disk cache (make setup does it too)"
	@echo "make build-db   build the motion database from ../shared/mocap/cmu (or built-in motions) into"
	@echo "                cache/motion_db.npz, the file the nodes load (they never build it)"
	@echo "make build-correction  learn the sensor correction from ../shared/kinect/ui-prmd (or ARGS=\"--src DIR\")"
	@echo "                into cache/sensor_correction_kinect_v2_sdk.npz (input_tracker:=kinect_v2_sdk loads it)"
	@echo "make evaluate   accuracy table of every method on the sensor-model streams"
	@echo "make bench      end-to-end latency/throughput benchmark"
	@echo "make bench-guard  CI's budget guard: short A/B against HEAD^, fails only on a large regression in 3 of 3 runs"
	@echo "make soak       10-minute soak of the running graph"
	@echo "make params     write config/*.yaml and the generated reference pages (docs/parameters.md,"
	@echo "                docs/launch_arguments.md, docs/commands.md) from the declarations"
	@echo "make docs       build the documentation site (MkDocs, strict: links, anchors, navigation) into out/site/"

setup:
	@scripts/setup.sh
	@$(RUN) python -m kinect_bringup.warm_kernels

# the numba kernels compiled into their on-disk cache (seconds when they already are), so that no
# node of the graph compiles at its first start
warm-kernels:
	@$(RUN) python -m kinect_bringup.warm_kernels

test:
	@scripts/run-tests.sh

lint:
	@$(RUN) ruff check .

demo: build-db warm-kernels
	@$(RUN) ros2 run kinect_bringup demo

build-db:
	@$(RUN) ros2 run skeleton_data build_db $(ARGS)

build-correction:
	@$(RUN) ros2 run pose_reconstruction build_correction $(ARGS)

evaluate:
	@$(RUN) ros2 run kinect_experiments evaluate $(ARGS)

bench:
	@$(RUN) ros2 run kinect_experiments bench $(ARGS)

bench-guard:
	@scripts/bench-guard.sh

soak:
	@$(RUN) ros2 run kinect_experiments soak $(ARGS)

params:
	@$(RUN) ros2 run kinect_experiments param_docs $(ARGS)

docs:
	@scripts/docs.sh --check-generated

.PHONY: warm-kernels help setup test lint demo build-db build-correction evaluate bench bench-guard soak params docs
