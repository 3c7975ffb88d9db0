# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""A process's memory and CPU from ``/proc``, once or sampled over time by a thread.

Each helper process reports its own ``getrusage`` figures; these are the same quantities read from
outside, for a time series (a plot of RSS and CPU over a run) and for a process that is too busy to
answer a command.
"""

from __future__ import annotations

import os
import re
import threading
import time
from typing import Any, Optional, Sequence

#: Clock ticks per second, the unit of utime and stime in /proc/PID/stat.
_TICKS = os.sysconf('SC_CLK_TCK')


def rss_kb(pid: int) -> Optional[int]:
    """The resident set of ``pid`` in kB (``VmRSS``), or None when it is gone."""
    try:
        with open(f'/proc/{pid}/status') as status:
            for line in status:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1])
    except (OSError, ValueError):
        return None
    return None


def _stat(path: str) -> Optional[tuple[str, float]]:
    """The name and the user + system seconds in a ``/proc/.../stat`` file, or None when it is
    gone."""
    try:
        with open(path) as stat:
            head, tail = stat.read().rsplit(')', 1)
        fields = tail.split()
        # After the command: state is field 3 of stat(5), utime 14 and stime 15.
        return head.split('(', 1)[1], (int(fields[11]) + int(fields[12])) / _TICKS
    except (OSError, ValueError, IndexError):
        return None


def cpu_s(pid: int) -> Optional[float]:
    """User + system seconds of ``pid`` so far, all threads, or None when it is gone."""
    found = _stat(f'/proc/{pid}/stat')
    return None if found is None else found[1]


def thread_cpu_s(pid: int) -> dict[str, float]:
    """User + system seconds of ``pid``'s threads so far, summed by thread name with its digits
    as ``#`` (``dds.udp.7412`` is ``dds.udp.#``): which of Python's and Fast DDS's threads work.
    Threads that ended are not listed."""
    out: dict[str, float] = {}
    try:
        tids = os.listdir(f'/proc/{pid}/task')
    except OSError:
        return out
    for tid in tids:
        found = _stat(f'/proc/{pid}/task/{tid}/stat')
        if found is not None:
            name = re.sub(r'\d+', '#', found[0])
            out[name] = out.get(name, 0.0) + found[1]
    return out


class Sampler:
    """Samples the RSS and CPU of named processes every ``period`` seconds, on a daemon thread.

    :ivar samples: ``(seconds since start, name, rss kB, cpu s)``, one per process and sample.
    """

    def __init__(self, pids: dict[str, int], period: float = 0.5) -> None:
        """Start sampling ``pids`` (name -> pid) at once."""
        self.pids = dict(pids)
        self.period = period
        self.started = time.monotonic()
        self.samples: list[tuple[float, str, Optional[int], Optional[float]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            t = time.monotonic() - self.started
            for name, pid in self.pids.items():
                self.samples.append((t, name, rss_kb(pid), cpu_s(pid)))
            self._stop.wait(self.period)

    def stop(self) -> None:
        """Stop sampling (bounded wait for the thread)."""
        self._stop.set()
        self._thread.join(5.0)

    def peak_rss_kb(self, name: str) -> Optional[int]:
        """The largest RSS sampled for ``name``."""
        values = [rss for _, n, rss, _ in self.samples if n == name and rss is not None]
        return max(values, default=None)

    def series(self, name: str) -> list[tuple[float, Optional[int], Optional[float]]]:
        """``(t, rss kB, cpu s)`` of ``name``, in order."""
        return [(t, rss, cpu) for t, n, rss, cpu in self.samples if n == name]


def py_spy() -> Optional[str]:
    """The py-spy executable beside this interpreter or on PATH, or None (it is optional)."""
    import shutil
    import sys
    beside = os.path.join(os.path.dirname(sys.executable), 'py-spy')
    return beside if os.access(beside, os.X_OK) else shutil.which('py-spy')


def profile(pid: int, seconds: float, rate: int = 50, top: int = 25,
            watch: Sequence[str] = ()) -> Optional[dict[str, Any]]:
    """Where ``pid`` spends its time, by py-spy, with native frames (C, C++) below Python's.

    py-spy stops the process for each sample (native stacks need it), ``rate`` times a second.

    Returns ``{'samples': n, 'self': [[share, frame], ...], 'inclusive': [...]}``, the ``top``
    frames by the share of samples in which they are the innermost frame, and in which they appear
    at all; idle threads (blocked in ``read``, ``sleep``, ``wait``) count as samples too. With
    ``watch``, also ``'watched'``: for each substring, the share of samples with a frame that
    contains it. None when py-spy is not installed or failed.
    """
    import collections
    import subprocess
    import tempfile
    spy = py_spy()
    if spy is None:
        return None
    with tempfile.NamedTemporaryFile('r', suffix='.txt') as out:
        try:
            subprocess.run([spy, 'record', '-p', str(pid), '-d', str(max(1, round(seconds))),
                            '-r', str(rate), '--native', '-f', 'raw',
                            '-o', out.name], capture_output=True, timeout=seconds + 60,
                           stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return None
        own: collections.Counter[str] = collections.Counter()
        watched: collections.Counter[str] = collections.Counter()
        inclusive: collections.Counter[str] = collections.Counter()
        total = 0
        for line in out:
            stack, _, count = line.rstrip('\n').rpartition(' ')
            if not stack or not count.isdigit():
                continue
            frames = stack.split(';')
            total += int(count)
            own[frames[-1]] += int(count)
            for frame in set(frames):
                inclusive[frame] += int(count)
            for needle in watch:
                if needle in stack:
                    watched[needle] += int(count)
    if not total:
        return None
    return {'samples': total,
            'self': [[round(n / total, 4), f] for f, n in own.most_common(top)],
            'inclusive': [[round(n / total, 4), f] for f, n in inclusive.most_common(top)],
            'watched': {needle: round(watched[needle] / total, 4) for needle in watch}}
