"""Programs that the harness and the tests compile themselves (the C action server, the hostile
participant of tests/test_hostile.py), each built once per source and command line into a cache
outside the repository: ``$XDG_CACHE_HOME/cft_action/<kind>/`` (default ``~/.cache``), else the
temporary directory's ``cft_action-<uid>/<kind>/``.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import tempfile
from pathlib import Path
from typing import Sequence

#: What a command line has where the output's path goes.
OUTPUT = 'OUTPUT'


class BuildUnavailable(RuntimeError):
    """The program cannot be built here; the message says why."""


def cache_dir(kind: str) -> Path:
    """``$XDG_CACHE_HOME/cft_action/<kind>`` (default ``~/.cache``)."""
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return Path(base) / 'cft_action' / kind


def build(kind: str, name: str, source: Path, command: Sequence[str], what: str) -> Path:
    """``name`` built from ``source`` by ``command`` (with :data:`OUTPUT` where the output's path
    goes), compiled on first use for this source and command (cached by their hash).

    :param what: the program, for messages (e.g. 'the C action server').
    :raises BuildUnavailable: it cannot be built here, and why.
    """
    key = hashlib.sha256(source.read_bytes() + '\0'.join(command).encode()).hexdigest()[:16]
    for base in (cache_dir(kind), Path(tempfile.gettempdir()) / f'cft_action-{os.getuid()}' / kind):
        binary = base / key / name
        if binary.is_file():
            return binary
        try:
            binary.parent.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue  # not writable: the next place
        # Built beside its final name and renamed: a concurrent session sees it whole or not at all.
        partial = binary.with_name(f'{name}.{os.getpid()}.tmp')
        argv = [str(partial) if arg == OUTPUT else arg for arg in command]
        built = subprocess.run(argv, capture_output=True, text=True, timeout=180)
        if built.returncode != 0:
            partial.unlink(missing_ok=True)
            raise BuildUnavailable(f'{what} does not build: {" ".join(argv)}\n'
                                   f'{built.stderr.strip()[-2000:]}')
        os.replace(partial, binary)
        return binary
    raise BuildUnavailable(f'no writable cache for {what} ({cache_dir(kind)})')
