"""Demos of cft_action.

The multi-client load demo (``make demo``) is ``load_demo.py``; its private modules are shared
with the benchmark sweep (``make bench``):

- ``_harness.py``: starts the server and the client processes, runs a load phase and accounts it;
- ``_server.py`` and ``_client.py``: the two process scripts (``_server.py`` is also the action
  server of the benchmarks and the tests);
- ``_proc.py``: the child-process wrapper and role dispatcher that demos, benchmarks and tests
  share;
- ``_netns.py``: one network namespace per client, so that bytes on the wire can be counted;
- ``_plot.py``: the plots.
"""
