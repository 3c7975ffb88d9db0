# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""A server that may crash: its environment, its command line, its exit and its core.

Shared by the hazard matrix (:mod:`harness.hazard`), ``benchmarks/soak.py``,
``benchmarks/guard_overhead.py`` and the guard's tests.
"""

from __future__ import annotations

import json
import os
import platform
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any, Optional

from harness.proc import python_module


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, not yet reaped by its parent, counts as dead)."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            state = f.read().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ('Z', 'X')


def server_command(action: str, period: float, pad: int, depth: Optional[int] = None, *,
                   record_readers: bool = False) -> list[str]:
    """The action server (:mod:`harness.server`) with counters every 2 s, for a crash watcher.

    Without ``depth``, its queues have rclpy's defaults, as an ordinary server's.
    ``record_readers``: its ``--record-readers``.
    """
    depth_args = [] if depth is None else ['--depth', str(depth)]
    extra = ['--record-readers'] if record_readers else []
    return python_module('harness.server', action, period, '--pad', pad, *depth_args,
                         '--stats-every', 2, *extra)


def plain_env(domain: int, **extra: str) -> dict[str, str]:
    """os.environ without the guard, with ``domain``, localhost-only discovery and Fast DDS."""
    from cft_action import guard
    env = dict(os.environ)
    try:
        ours = os.path.realpath(guard.library_path())
    except guard.GuardUnavailable:
        ours = None
    kept = [e for e in re.split(r'[\s:]+', env.get('LD_PRELOAD', ''))
            if e and os.path.realpath(e) != ours]
    if kept:
        env['LD_PRELOAD'] = ':'.join(kept)
    else:
        env.pop('LD_PRELOAD', None)
    for name in ('CFT_GUARD_DEBUG', 'CFT_ACTION_FEEDBACK_FILTER'):
        env.pop(name, None)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               RMW_IMPLEMENTATION='rmw_fastrtps_cpp', PYTHONUNBUFFERED='1')
    env.update(extra)
    return env


def server_env(domain: int, guarded: bool) -> dict[str, str]:
    from cft_action import guard
    env = plain_env(domain)
    return guard.environment(env) if guarded else env


def signal_name(rc: Optional[int]) -> str:
    if rc is None:
        return 'running'
    if rc < 0:
        try:
            return signal.Signals(-rc).name
        except ValueError:
            return f'signal {-rc}'
    return f'exit {rc}'


def core_backtrace(directory: str, pid: int, keep: bool = False,
                   frames: int = 25) -> tuple[Optional[str], list[str]]:
    """Return (core path or None, the crashing thread's backtrace frames) for a dead server.

    The kernel's ``core_pattern`` decides the name; a relative pattern (``core``, ``core.%p``)
    puts it into the server's cwd, which is ``directory``. Deletes the core unless ``keep``.
    """
    candidates = [p for p in Path(directory).iterdir() if p.name.startswith('core')]
    if not candidates:
        return None, []
    core = max(candidates, key=lambda p: p.stat().st_mtime)
    gdb = shutil.which('gdb')
    frames_out: list[str] = []
    if gdb:
        try:
            result = subprocess.run(
                [gdb, '-batch', '-nx', '-iex', 'set auto-load off',
                 '-ex', 'set debuginfod enabled off', '-ex', f'bt {frames}',
                 os.path.realpath(sys.executable), str(core)],
                capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL)
            seen = set()
            for line in result.stdout.splitlines():
                number = re.match(r'#(\d+)\s', line)
                if number and number.group(1) not in seen:  # gdb prints frame #0 twice
                    seen.add(number.group(1))
                    frames_out.append(re.sub(r'\s+', ' ', line.strip()))
        except subprocess.TimeoutExpired:
            frames_out = ['(gdb timed out)']
    else:
        frames_out = ['(gdb not installed: backtrace not read)']
    if not keep:
        try:
            core.unlink()
        except OSError:
            pass
    return (str(core) if keep else f'{core} (deleted)'), frames_out


def live_backtrace(pid: int, frames: int = 25, timeout: float = 60.0) -> Optional[str]:
    """The threads of a running process, from ``gdb -p PID -batch -ex 'thread apply all bt'``.

    For a process that hangs or does not end: what each thread waits on. None when gdb is not
    installed; ``'(gdb timed out)'`` when gdb did not finish within ``timeout`` seconds.
    """
    gdb = shutil.which('gdb')
    if gdb is None:
        return None
    try:
        result = subprocess.run(
            [gdb, '-q', '-batch', '-p', str(pid), '-ex', f'thread apply all bt {frames}'],
            capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return '(gdb timed out)'
    return '\n'.join(line for line in result.stdout.splitlines()
                     if line.startswith(('Thread ', '#')))


def short_frame(frame: str) -> str:
    """``#3 0x.. in ns::Class::member(args) () from lib.so`` -> ``Class::member``."""
    m = re.match(r'#\d+\s+(?:0x[0-9a-f]+ in )?(.*)$', frame)
    name = m.group(1) if m else frame
    previous = None
    while previous != name:  # template arguments, innermost first
        previous, name = name, re.sub(r'<[^<>]*>', '', name)
    name = name.split('(', 1)[0].strip().split(' ')[-1]
    return '::'.join(name.split('::')[-2:]) or frame


def stats_of(line: Optional[str]) -> Optional[dict[str, Any]]:
    if not line:
        return None
    try:
        return json.loads(line.split(' ', 1)[1])
    except (IndexError, ValueError):
        return None


def crash_site(outcome: dict[str, Any]) -> str:
    """The first Fast DDS frames of a backtrace, shortened, or the reason there is none."""
    frames = outcome.get('backtrace') or []
    if not frames:
        return outcome.get('backtrace_note', '')
    interesting = [short_frame(f) for f in frames if 'eprosima' in f]
    return ' < '.join((interesting or [short_frame(f) for f in frames])[:4])


def machine_line() -> str:
    from importlib import metadata
    cpu = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as f:
            cpu = next(line.split(':', 1)[1].strip() for line in f if line.startswith('model name'))
    except (OSError, StopIteration):
        pass
    versions = []
    for dist in ('ros-jazzy-rclpy', 'ros-fastrtps', 'ros-rmw-fastrtps-cpp'):
        try:
            versions.append(f'{dist} {metadata.version(dist)}')
        except metadata.PackageNotFoundError:
            pass
    return (f'{platform.node()}: {os.cpu_count()} CPUs ({cpu}), Linux {platform.release()}, '
            f'Python {platform.python_version()}, {", ".join(versions)}, '
            f'Fast DDS {fastdds_library()}; load average {os.getloadavg()[0]:.2f} at start')


def fastdds_library() -> str:
    """The real path of the Fast DDS library (libfastrtps 2.x or libfastdds 3.x) that this process
    and its children load: the one mapped here, else the first on ``LD_LIBRARY_PATH``, else this
    environment's (the wheels put it in ``<prefix>/lib``).

    A run on another stack (``compat/stack_env.sh``) swaps the library, not the wheels' versions
    that :func:`machine_line` lists, so the line names the file itself.
    """
    names = ('libfastrtps.so.2', 'libfastdds.so.3')
    with open('/proc/self/maps') as maps:
        for line in maps:
            if any(name in line for name in names):
                return line.split()[-1]
    directories = [d for d in os.environ.get('LD_LIBRARY_PATH', '').split(os.pathsep) if d]
    for directory in [*directories, str(Path(sys.prefix) / 'lib')]:
        found = sorted(p for name in names for p in Path(directory).glob(name + '.*')
                       if p.name.count('.') == 3)  # libfastdds.so.3.6, not .so.3.6.2
        if found:
            return str(found[0].resolve())
    return 'not found on LD_LIBRARY_PATH or in ' + str(Path(sys.prefix) / 'lib')
