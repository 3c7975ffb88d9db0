"""Benchmarks of cft_action, run from the repository root as modules: ``python -m benchmarks.sweep``
(``make bench``) and the others; what they share with the demos and tests is in ``harness``."""
