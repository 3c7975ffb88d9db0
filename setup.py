# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Builds the package's two C shared libraries at install time.

- ``_cftguard``, the server guard (``cft_action/_guard.c``), ``LD_PRELOAD``-ed into servers;
- ``_cftreader``, the reader lock (``cft_action/_reader_lock.c``), loaded with ctypes by
  ``cft_action._rcl`` into every process that changes a filter.

All metadata is in ``pyproject.toml``; this file only adds the C shared libraries. Each is built as a
setuptools ``Extension`` so that ``pip install .`` puts it into the installed package and
``pip install -e .`` builds it in place, next to ``cft_action/guard.py``. Neither is imported: they have no Python module init and do not
link against libpython.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            'cft_action._cftguard',
            sources=['cft_action/_guard.c', 'cft_action/_guard_filter.c',
                     'cft_action/_guard_writer_qos.c', 'cft_action/_filter_class.c',
                     'cft_action/_uuid_program.c', 'cft_action/_node_program.c'],
            libraries=['dl', 'pthread'],
            # Export only the interposed Fast DDS and rmw_fastrtps functions and the cft_guard_*
            # C API.
            # -fexceptions: a C++ exception thrown by Fast DDS through a wrapper must still run
            # the wrapper's unlock (a cleanup attribute), or the writer's stripe stays locked.
            extra_compile_args=['-O2', '-fvisibility=hidden', '-fexceptions', '-Wall'],
        ),
        Extension(
            'cft_action._cftreader',
            sources=['cft_action/_reader_lock.c', 'cft_action/_reader_class.c',
                     'cft_action/_patch.c', 'cft_action/_filter_class.c',
                     'cft_action/_uuid_program.c', 'cft_action/_node_program.c'],
            libraries=['dl', 'pthread'],
            extra_compile_args=['-O2', '-fvisibility=hidden', '-Wall'],
        ),
    ],
)
