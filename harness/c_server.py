# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The C action server (``harness/native/action_server.c``): built against the installed ROS, and
started as :mod:`harness.server` is.

Production action servers are C++: several servers composed in one process, each with its own
executor thread, and a thread per goal, so that feedback is published from many threads at once
(rclpy holds the GIL inside ``rcl_action_publish_feedback``: an rclpy server never does). The C
server is that, over ``rcl_action``, with :mod:`harness.server`'s protocol and options where they
make sense (feedback period, padding, depths, result timeout, ``--hold-goals``) plus ``servers``:
K action servers in the process, ``ACTION`` for one, ``ACTION_0`` ... ``ACTION_<K-1>`` for more.

:func:`build` compiles it once per source and toolchain into a cache outside the repository
(:mod:`harness.native_cache`), against the headers and libraries of this Python's prefix (the ROS
wheels: ``<venv>/include/<pkg>/<pkg>/*.h``, ``<venv>/lib`` and ``site-packages/ros_*.libs``) and of
each ``AMENT_PREFIX_PATH`` entry (a sourced ROS). The wheels' ``librcl`` pulls in a Python extension
of ``type_description_interfaces`` that needs libpython's symbols at load time, so the server links
libpython too when it is shared.
:class:`CServerUnavailable` says why it cannot be built (no compiler, no headers, a failed build).

:func:`start` runs it as a :class:`CServer`: a :class:`harness.proc.Proc` whose ``stats()`` names
the guard's counters as :mod:`cft_action.guard` does (the C server reads them raw).
"""

from __future__ import annotations

import glob
import json
import os
import shutil
import sys
import sysconfig
from pathlib import Path
from typing import Any, Optional, Sequence

from cft_action import guard
from harness import native_cache
from harness.proc import Proc, pinned

#: The server's source.
SOURCE = Path(__file__).resolve().parent / 'native' / 'action_server.c'

#: Headers the server includes, each to be found under some prefix's ``include/<pkg>/``.
HEADERS = ('rcl/rcl.h', 'rcl_action/rcl_action.h', 'test_msgs/action/fibonacci.h')

#: The libraries it calls into.
LIBRARIES = ('rcl_action', 'rcl', 'rcutils', 'rmw', 'rosidl_runtime_c',
             'test_msgs__rosidl_typesupport_c', 'test_msgs__rosidl_generator_c',
             'action_msgs__rosidl_generator_c')

#: The names of the guard's call counters, in the order of ``cft_guard_call_count``
#: (:func:`cft_action.guard.call_counts`).
GUARD_CALLS = ('perform_create_new_change', 'process_reader_filter_info', 'remove_reader_filter',
               'nested_unlocked')

#: STATS keys of the guard's counter arrays, and their names.
GUARD_FAMILIES = {'guard_calls': GUARD_CALLS, 'guard_filter': guard.FILTER_COUNTERS,
                  'guard_filter_class': guard.FILTER_CLASS_COUNTERS,
                  'guard_writers': guard.WRITER_QOS_COUNTERS,
                  'guard_heartbeats': guard.HEARTBEAT_COUNTERS,
                  'guard_status': guard.STATUS_COUNTERS}


class CServerUnavailable(native_cache.BuildUnavailable):
    """The C server cannot be built here; the message says why (tests skip with it)."""


def prefixes() -> list[Path]:
    """Where ROS is installed: this Python's prefix (the wheels), then ``AMENT_PREFIX_PATH``."""
    found = [Path(sys.prefix)]
    found += [Path(p) for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    unique: list[Path] = []
    for prefix in found:
        if prefix.is_dir() and prefix.resolve() not in [p.resolve() for p in unique]:
            unique.append(prefix)
    return unique


def include_dirs(roots: Sequence[Path]) -> list[str]:
    """``<prefix>/include/<pkg>`` of every package of ``roots`` (ROS 2's layout since Humble)."""
    return [str(package) for prefix in roots
            for package in sorted((prefix / 'include').glob('*'))
            if (package / package.name).is_dir()]


def library_dirs(roots: Sequence[Path]) -> list[str]:
    """``<prefix>/lib`` of ``roots``, and the wheels' ``site-packages/ros_*.libs`` folders."""
    dirs = [str(prefix / 'lib') for prefix in roots if (prefix / 'lib').is_dir()]
    purelib = sysconfig.get_paths()['purelib']
    return dirs + sorted(glob.glob(os.path.join(purelib, 'ros_*.libs')))


def libpython() -> list[str]:
    """The link arguments of this Python's shared libpython ([] for a static one)."""
    if not sysconfig.get_config_var('Py_ENABLE_SHARED'):
        return []
    libdir, name = sysconfig.get_config_var('LIBDIR'), sysconfig.get_config_var('LDLIBRARY')
    if not libdir or not name or not (Path(libdir) / name).exists():
        return []
    # Kept although the server itself calls nothing of it (gcc links --as-needed by default).
    return ['-Wl,--no-as-needed', str(Path(libdir) / name), '-Wl,--as-needed',
            f'-Wl,-rpath,{libdir}']


def compile_command(output: Path) -> list[str]:
    """The compiler's command line that builds the server into ``output``.

    :raises CServerUnavailable: no C compiler on ``PATH``, or no prefix with the headers.
    """
    compiler = os.environ.get('CC') or shutil.which('cc') or shutil.which('gcc')
    if compiler is None:
        raise CServerUnavailable('the C action server needs a C compiler (cc or gcc on PATH)')
    roots = prefixes()
    includes = include_dirs(roots)
    missing = [h for h in HEADERS if not any(Path(d, h).is_file() for d in includes)]
    if missing:
        raise CServerUnavailable(
            f'the C action server needs the ROS headers {", ".join(missing)}, in no '
            f'<prefix>/include/<pkg>/ of {", ".join(map(str, roots))} (this Python and '
            'AMENT_PREFIX_PATH)')
    libs = library_dirs(roots)
    return [compiler, '-std=gnu11', '-O2', '-Wall', '-Wextra', '-Wno-unused-parameter',
            *[f'-I{d}' for d in includes], str(SOURCE), '-o', str(output),
            *[f'-L{d}' for d in libs], *[f'-Wl,-rpath,{d}' for d in libs],
            *[f'-Wl,-rpath-link,{d}' for d in libs], '-Wl,--disable-new-dtags',
            *[f'-l{name}' for name in LIBRARIES], *libpython(), '-lpthread', '-ldl']


def build() -> Path:
    """The built server, compiled on first use for this source and toolchain (cached by their hash,
    :mod:`harness.native_cache`).

    :raises CServerUnavailable: it cannot be built here, and why.
    """
    try:
        return native_cache.build('c_server', 'action_server', SOURCE,
                                  compile_command(Path(native_cache.OUTPUT)),
                                  'the C action server')
    except native_cache.BuildUnavailable as error:
        raise CServerUnavailable(str(error)) from None


def command(action: str, period: float, *, servers: int = 1, pad: int = 0,
            depth: Optional[str] = None, feedback_depth: Optional[int] = None,
            result_timeout: Optional[float] = None, hold_goals: int = 0) -> list[str]:
    """The server's command line (building it if needed); the options as :mod:`harness.server`'s."""
    argv = [str(build()), action, str(period), '--servers', str(servers), '--pad', str(pad)]
    if depth is not None:
        argv += ['--depth', str(depth)]
    if feedback_depth is not None:
        argv += ['--feedback-depth', str(feedback_depth)]
    if result_timeout is not None:
        argv += ['--result-timeout', str(result_timeout)]
    if hold_goals:
        argv += ['--hold-goals', str(hold_goals)]
    return argv


class CServer(Proc):
    """A running C server: a :class:`Proc` with its action names and named counters."""

    actions: list[str]

    def stats(self, timeout: float = 30.0) -> dict[str, Any]:
        """The ``STATS`` reply, with the guard's counters named as :mod:`cft_action.guard` names
        them (``{}`` for each family when the guard is not preloaded)."""
        stats = self.request_json('stats', 'STATS', timeout)
        for key, names in GUARD_FAMILIES.items():
            stats[key] = dict(zip(names, stats.get(key, [])))
        return stats

    def goals(self, timeout: float = 30.0) -> dict[str, int]:
        """Feedback messages published per goal, by goal UUID in hex (``GOALS``)."""
        return self.request_json('goals', 'GOALS', timeout)


def start(action: str, period: float, *, env: Optional[dict[str, str]] = None,
          timeout: float = 30.0, cpus: Optional[str] = None, **options: Any) -> CServer:
    """Start the C server (``options``: those of :func:`command`; on ``cpus`` only, as
    :func:`harness.proc.pinned`) and wait for its ``READY``.

    :raises CServerUnavailable: it cannot be built here.
    :raises TimeoutError: it did not get ready (it is stopped then).
    """
    argv = pinned(cpus, command(action, period, **options))
    server = CServer('c_server', argv, dict(os.environ if env is None else env))
    try:
        server.actions = [str(a) for a in
                          json.loads(server.expect('ACTIONS', timeout).split(' ', 1)[1])]
        server.expect('READY', timeout)
    except TimeoutError:
        server.stop()
        raise
    return server
