"""What the demos, the benchmarks and the tests share: processes, the action server, the load.

Not part of the distribution (``cft_action`` is the only installed package): it is imported from
the repository, whose root is on ``sys.path`` when a command runs there (``python -m
demos.load_demo``, ``python -m benchmarks.sweep``, ``pytest``), and put on the ``PYTHONPATH`` of
every child process by :class:`harness.proc.Proc`. It imports ``cft_action`` and itself only.

- ``proc``: the child-process wrapper and role dispatcher; :func:`harness.proc.python_module`
  builds the command line of a module of this repository;
- ``server``: the Fibonacci action server process of every demo, benchmark and test;
- ``client``: the load client process (plain rclpy, ``cft_action`` modes, upstream-equivalent),
  ``upstream``: the emulation of the upstream (Rolling) design;
- ``load``: starts the server and the load clients, runs a load phase and accounts it (``make
  demo``, ``make bench``), and with ``CapturingRun`` captures one client's packets
  (``benchmarks/_capture.py``, run as a child process); ``netns``: one network namespace per
  client, so that bytes on the wire can be counted; ``plot``: the plots;
- ``crash``: a server that may crash: its environment, its exit and its core; ``hazard``: one cell
  of the hazard matrix (``benchmarks/hazard.py``, the guard's tests);
- ``cli``: command-line value types (comma-separated lists);
- ``ros``: an rclpy session in this process; ``polling``: bounded waits in helper processes;
  ``param_nodes``: nodes whose parameters change on command.
"""
