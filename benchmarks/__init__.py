"""Benchmarks of cft_action: ``sweep.py`` (``make bench``) and the upstream-equivalent client."""
