"""Demos of cft_action, run from the repository root as modules.

- ``python -m demos.load_demo`` (``make demo``): the multi-client load demo, on :mod:`harness.load`
  (shared with the benchmark sweep, ``make bench``);
- ``python -m demos.parameter_events``: a node-filtered ParameterEventHandler against rclpy's.
"""
