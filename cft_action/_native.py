# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Where the package's C shared libraries are: built by setup.py, never imported as modules."""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
from pathlib import Path
from typing import Optional

#: The server guard, ``_guard.c`` and ``_guard_filter.c``: ``LD_PRELOAD``-ed into servers.
GUARD_LIBRARY = '_cftguard'
#: The reader lock, ``_reader_lock.c``, and the status trim, ``_status_trim.c``: loaded with ctypes
#: into processes that change filters or take an action client's status.
READER_LOCK_LIBRARY = '_cftreader'
#: The guard's Fast DDS 3 layer (native/guard/fastdds3/), built only against Fast DDS 3.3+ headers
#: and dlopened by the guard, never by Python.
GUARD_FASTDDS3_LIBRARY = '_cftguard_fastdds3'
#: The client's Fast DDS 3 layer (native/reader/fastdds3/), built only against Fast DDS 3.3+ headers
#: and loaded with ctypes by cft_action._rcl where that Fast DDS is loaded.
READER_FASTDDS3_LIBRARY = '_cftreader_fastdds3'
LIBRARIES = (GUARD_LIBRARY, READER_LOCK_LIBRARY, GUARD_FASTDDS3_LIBRARY, READER_FASTDDS3_LIBRARY)


def extension_path(module: str) -> Optional[str]:
    """The absolute path of the shared library ``cft_action.<module>``, or None if not built."""
    here = Path(__file__).resolve().parent
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        candidate = here / f'{module}{suffix}'
        if candidate.is_file():
            return str(candidate)
    # An install layout that keeps extension modules elsewhere: ask the import system where the
    # module is, without importing it (it is a shared library, not a Python module).
    spec = importlib.util.find_spec(f'{__package__ or "cft_action"}.{module}')
    if spec is not None and spec.origin and os.path.isfile(spec.origin):
        return os.path.abspath(spec.origin)
    return None
