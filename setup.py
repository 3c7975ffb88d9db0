# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Builds the server guard, ``cft_action/_guard.c``, into the package at install time.

All metadata is in ``pyproject.toml``; this file only adds the C shared library. It is built as a
setuptools ``Extension`` so that ``pip install .`` puts it into the installed package and
``pip install -e .`` builds it in place, next to ``cft_action/guard.py`` (which finds it with
:func:`cft_action.guard.library_path`). It is never imported: it has no Python module init and does
not link against libpython, so it can be ``LD_PRELOAD``-ed into any process.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            'cft_action._cftguard',
            sources=['cft_action/_guard.c', 'cft_action/_guard_filter.c'],
            libraries=['dl', 'pthread'],
            # Export only the three interposed Fast DDS members and the cft_guard_* C API.
            # -fexceptions: a C++ exception thrown by Fast DDS through a wrapper must still run
            # the wrapper's unlock (a cleanup attribute), or the writer's stripe stays locked.
            extra_compile_args=['-O2', '-fvisibility=hidden', '-fexceptions', '-Wall'],
        ),
    ],
)
