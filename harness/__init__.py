"""What the demos, the benchmarks and the tests share: processes, the action server, the load.

A benchmark is spec -> run -> report over this package: it imports ``harness`` and nothing of
another benchmark, and no test imports a benchmark; what two of them need lives here.

Not part of the distribution (``cft_action`` is the only installed package): it is imported from
the repository, whose root is on ``sys.path`` when a command runs there (``python -m
demos.load_demo``, ``python -m benchmarks.sweep``, ``pytest``), and put on the ``PYTHONPATH`` of
every child process by :class:`harness.proc.Proc`. It imports ``cft_action`` and itself only.

- ``proc``: the child-process wrapper and role dispatcher; :func:`harness.proc.python_module`
  builds the command line of a module of this repository, :func:`harness.proc.guard_command` the
  prefix that runs a server under the guard;
- ``server``: the Fibonacci action server process of every demo, benchmark and test;
- ``client``: the load client process (plain rclpy, ``cft_action`` modes, upstream-equivalent)
  and the client classes that count or record what they take; ``upstream``: the emulation of the
  upstream (Rolling) design;
- ``load``: starts the server and the load clients, runs a load phase and accounts it (``make
  demo``, ``make bench``), and with ``CapturingRun`` captures one client's packets
  (``capture``, run as a child process); ``netns``: one network namespace per client, so that
  bytes on the wire can be counted;
- ``report``: progress lines, figures and tables (text and Markdown); ``plot``: the plots;
  ``status_model``: the status topic's size model;
- ``crash``: a server that may crash: its environment, its exit and its core; ``hazard``: one cell
  of the hazard matrix (``benchmarks/hazard.py``, the guard's tests);
- ``cli``: command-line value types (comma-separated lists);
- ``domain``: a ROS domain that no other process on the host uses; ``keystore``: an SROS2 keystore
  and its enclaves (DDS Security);
- ``ros``: an rclpy session in this process; ``polling``: bounded waits in helper processes;
  ``param_nodes``: nodes whose parameters change on command.
"""
