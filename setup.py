# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Builds the package's two C shared libraries at install time.

Their sources are in ``cft_action/native/``, by the process they run in:

- ``native/guard/`` builds ``_cftguard``, the server guard, ``LD_PRELOAD``-ed into servers:
  ``_guard.c`` (the locks and the interposed Fast DDS members), ``_guard_families.c`` (which Fast
  DDS is loaded and where its real members are), ``_guard_filter.c`` (the DDS-SQL accelerator),
  ``_guard_writer_qos.c`` (the writers' filtered-reader limit and mark), ``_guard_heartbeats.c``,
  ``_guard_replies.c``, ``_guard_status.c``, ``_guard_goals.c``, ``_guard_feedback.c``,
  ``_guard_programs.c``, ``_guard_endpoints.c`` and ``_guard_log.c``;
- ``native/guard/fastdds3/`` builds ``_cftguard_fastdds3``, the guard's Fast DDS 3.3+ layer (C++,
  public API: the writers' sample prefilter and USER_DATA), and ``native/reader/fastdds3/``
  ``_cftreader_fastdds3``, the client's (its readers' USER_DATA marks), only where Fast DDS 3.3+
  headers and their library are found; each is linked against that Fast DDS, and loaded only into
  a process that has it loaded;
- ``native/reader/`` builds ``_cftreader``, loaded with ctypes by ``cft_action._rcl`` into every
  process that changes a filter or takes an action client's status: the reader lock, the reader's
  filter class, the writer marks, the PLT patcher, the status trim and the response filter;
- ``native/`` itself holds what both are built from: the filter classes (``_filter_class.c``,
  ``_uuid_program.c``, ``_node_program.c``), the CDR reader and the layout probes.

Both read Fast DDS objects at offsets that come from the Fast DDS headers found at build time:
``cft_action/native/_fastdds_layout.cpp`` is compiled to assembly against them, and its offsets
become
``_fastdds_layout.h`` in the build directory (docs/INTERNALS.md, section 17). Where no headers are
found, that header says the layout is unknown, and the guard then reads no Fast DDS layout and
says so once at run time. ``CFT_FASTDDS_INCLUDE`` names the headers' directory explicitly.

All metadata is in ``pyproject.toml``; this file only adds the C shared libraries. Each is built as
a setuptools ``Extension`` so that ``pip install .`` puts it into the installed package and
``pip install -e .`` builds it in place, next to ``cft_action/guard.py``. Neither is imported: they
have no Python module init and do not link against libpython.
"""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Optional

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

PROBE = 'cft_action/native/_fastdds_layout.cpp'
#: rmw's layouts (cft_action/native/_rmw_layout.cpp), probed wherever rmw's headers are found.
RMW_PROBE = 'cft_action/native/_rmw_layout.cpp'
#: The folders under an include directory that rmw/types.h needs (one per package, as ROS installs).
RMW_PACKAGES = ('rmw', 'rcutils', 'rosidl_runtime_c', 'rosidl_typesupport_interface',
                'rosidl_dynamic_typesupport')
LAYOUT_HEADER = '_fastdds_layout.h'


def header_candidates() -> list[Path]:
    """The directories searched for Fast DDS headers, in order (:func:`fastdds_include_dirs`)."""
    explicit = [Path(p) for p in os.environ.get('CFT_FASTDDS_INCLUDE', '').split(os.pathsep) if p]
    # An explicit directory may also be one above the headers' own, as a prefix's include/ is (and
    # Fast DDS 3 installs under include/fastdds/ with APPEND_PROJECT_NAME_TO_INCLUDEDIR, as
    # Lyrical's packages do).
    candidates = [d for p in explicit for d in (p, p / 'fastrtps', p / 'fastdds')]
    if explicit and not any((d / 'fastrtps' / 'config.h').is_file()
                            or (d / 'fastdds' / 'config.hpp').is_file() for d in candidates):
        # Building from other headers than the ones named would be a silent substitution.
        raise SystemExit(f'setup.py: CFT_FASTDDS_INCLUDE={os.environ["CFT_FASTDDS_INCLUDE"]} has '
                         'no fastrtps/config.h or fastdds/config.hpp in any of its directories or '
                         'their fastrtps/ or fastdds/')
    prefixes = [Path(sys.prefix)]
    prefixes += [Path(p) for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    prefixes += [Path(p).parents[2] for p in sys.path if p.endswith('site-packages')]
    for prefix in prefixes:
        candidates += [prefix / 'include', prefix / 'include' / 'fastrtps',
                       prefix / 'include' / 'fastdds']
    return candidates


#: The first Fast DDS 3 release whose DataWriter has set_sample_prefilter (fastdds3/_prefilter.cpp).
PREFILTER_SINCE = (3, 3)


def fastdds_include_dirs() -> tuple[list[Path], str, list[Path], tuple[int, int]]:
    """The include directories of the Fast DDS 2.14 headers to build against, what was found, those
    of Fast DDS 3.3+ headers for the guard's Fast DDS 3 layer (native/guard/fastdds3/), and the
    found headers' major and minor version.

    The first Fast DDS headers found decide: Fast DDS 2.14's (``fastrtps/config.h``) give the first
    list, Fast DDS 3's (``fastdds/config.hpp``: Kilted's wheels, Lyrical) give none there, since
    that stack's Fast DDS is 3.x and the 2.14 headers that pip's isolated build environment brings
    (``[build-system] requires``) are not the library that will be loaded; from 3.3 on they give the
    third list. The text says which headers were found, for the layout header's source.

    Searched in this order: ``CFT_FASTDDS_INCLUDE`` (directories separated by ``os.pathsep``);
    this Python's prefix (the ROS wheels, a colcon underlay); each ``AMENT_PREFIX_PATH`` entry
    (apt's ``/opt/ros/jazzy``, whose Fast DDS headers are under ``include/fastrtps``); the prefixes
    of ``sys.path`` (pip's isolated build environment, which gets the wheels' headers from
    ``[build-system] requires``).
    """
    candidates = header_candidates()
    for include in candidates:
        if (include / 'fastdds' / 'config.hpp').is_file():
            text = (include / 'fastdds' / 'config.hpp').read_text(errors='replace')
            version = re.search(r'FASTDDS_VERSION_STR "([^"]+)"', text)
            numbers = tuple(int(m.group(1)) if m else 0 for m in (
                re.search(rf'FASTDDS_VERSION_{part} (\d+)', text) for part in ('MAJOR', 'MINOR')))
            found = (f'the headers of Fast DDS {version.group(1) if version else "3"} in '
                     f'{include}, which has no Fast DDS 2.14 layout')
            # fastcdr: beside it (wheels), or in its own folder next to fastdds/ (Lyrical's).
            near = [include.parent / 'fastcdr'] if include.name == 'fastdds' else []
            three = [include] + [d for d in near if d.is_dir()]
            return [], found, three if numbers >= PREFILTER_SINCE else [], numbers
        if (include / 'fastrtps' / 'config.h').is_file():
            # fastcdr and foonathan_memory: beside it (wheels), in their own folders (apt), or in a
            # later candidate (CFT_FASTDDS_INCLUDE=<stack headers>:<venv>/include).
            root = include.parent if include.name == 'fastrtps' else include
            near = [root / 'fastcdr', root / 'foonathan_memory', root]
            return (list(dict.fromkeys([include] + [d for d in near + candidates if d.is_dir()])),
                    f'Fast DDS headers in {include}', [], (2, 14))
    return [], 'no Fast DDS headers were found at build time', [], (0, 0)


def probe(compiler: str, source: str, includes: list[Path], *options: str) -> list[tuple[str, ...]]:
    """The ``->NAME VALUE what`` lines of ``source`` compiled to assembly against ``includes``
    (empty, and said on stderr, if it does not compile)."""
    result = subprocess.run([compiler, '-std=c++17', '-S', '-o', '-', *options,
                             *[f'-I{d}' for d in includes], source],
                            capture_output=True, text=True, check=False)
    lines = re.findall(r'^\s*->(\w+) \$?(-?\d+) ?(.*)$', result.stdout, re.MULTILINE)
    if result.returncode != 0 or not lines:
        print(f'setup.py: {source} did not compile against {includes[0]}:\n'
              f'{result.stderr[-2000:]}', file=sys.stderr)
        return []
    return lines


def rmw_include_dirs() -> list[Path]:
    """The include directories of the first rmw headers found among the Fast DDS headers'
    candidates (the ROS wheels, a colcon underlay, /opt/ros/<distro>), for RMW_PROBE."""
    for include in header_candidates():
        if (include / 'rmw' / 'rmw' / 'types.h').is_file():
            return [include / p for p in RMW_PACKAGES if (include / p).is_dir()]
    return []


def c_string(text: str) -> str:
    """``text`` as a C string literal."""
    return '"' + text.replace('\\', '\\\\').replace('"', '\\"') + '"'


def layout_header(build_temp: Path) -> None:
    """Write ``_fastdds_layout.h`` into ``build_temp``."""
    build_temp.mkdir(parents=True, exist_ok=True)
    includes, found, three, version = fastdds_include_dirs()
    compiler = os.environ.get('CXX') or shutil.which('c++') or shutil.which('g++')
    lines: list[str] = []
    source = ''
    if includes and compiler:
        lines = probe(compiler, PROBE, includes, '-fno-access-control', '-Wno-invalid-offsetof')
        source = found if lines else f'{PROBE} did not compile against {includes[0]}'
    else:
        source = 'no C++ compiler' if includes else found
    rmw = rmw_include_dirs()
    rmw_lines = probe(compiler, RMW_PROBE, rmw) if rmw and compiler else []
    values = {name: value for name, value, _ in lines}
    out = ['// Generated by setup.py from cft_action/native/_fastdds_layout.cpp: do not edit.',
           '#ifndef CFT_ACTION_FASTDDS_LAYOUT_H_', '#define CFT_ACTION_FASTDDS_LAYOUT_H_']
    if values:
        version = '.'.join(values[f'CFT_LAYOUT_VERSION_{p}'] for p in ('MAJOR', 'MINOR', 'MICRO'))
        source = (f'the headers of Fast DDS {version} (HAVE_SECURITY '
                  f'{values["CFT_LAYOUT_HAVE_SECURITY"]}) in {includes[0]}')
        out.append('#define CFT_LAYOUT_KNOWN 1')
        out += [f'#define {name} {value}' + (f'  // {what}' if what else '')
                for name, value, what in lines]
    else:
        out.append('#define CFT_LAYOUT_KNOWN 0')
    out += [f'#define {name} {value}  // {what}' for name, value, what in rmw_lines]
    out.append(f'#define CFT_LAYOUT_SOURCE {c_string(source)}')
    # The include path itself, so that tests can compile their probes against the same headers.
    out.append('#define CFT_LAYOUT_INCLUDES '
               + c_string(os.pathsep.join(str(d) for d in includes) if values else ''))
    # The guard's Fast DDS 3 layer (native/guard/fastdds3/), built on Fast DDS 3.3+ (layer_library).
    layer = layer_library(three)
    out.append(f'#define CFT_FASTDDS3_PREFILTER {1 if layer else 0}')
    out.append('#define CFT_FASTDDS3_SONAME '
               + c_string(f'libfastdds.so.{version[0]}.{version[1]}' if layer else ''))
    # Where the layer came from, or (a clause after "not built: ") why it was not built.
    needs = (f'it needs Fast DDS {".".join(map(str, PREFILTER_SINCE))}+ headers (with '
             'DataWriter::set_sample_prefilter) and their libfastdds.so')
    out.append('#define CFT_FASTDDS3_SOURCE ' + c_string(
        f'the headers and library of Fast DDS {version[0]}.{version[1]} in {three[0]}' if layer
        else f'setup.py: the headers of Fast DDS 3 in {three[0]}, but no libfastdds.so beside '
             f'them; {needs}' if three
        else f'setup.py: {found}; {needs}'))
    out.append('#endif  // CFT_ACTION_FASTDDS_LAYOUT_H_')
    (build_temp / LAYOUT_HEADER).write_text('\n'.join(out) + '\n')
    print(f'setup.py: Fast DDS layout from {source}; the guard\'s Fast DDS 3 layer '
          f'{"from " + str(layer) if layer else "off"}', file=sys.stderr)


def layer_library(three: list[Path]) -> Optional[Path]:
    """The directory of the libfastdds.so to link the guard's Fast DDS 3 layer against: the lib/
    of the prefix of the Fast DDS 3.3+ headers ``three`` (``<prefix>/include`` or
    ``<prefix>/include/fastdds``); None without such headers or library."""
    if not three:
        return None
    prefix = three[0].parent.parent if three[0].name == 'fastdds' else three[0].parent
    for lib in (prefix / 'lib', prefix / 'lib' / 'x86_64-linux-gnu', prefix / 'lib64'):
        if (lib / 'libfastdds.so').exists():
            return lib
    return None


class BuildWithLayout(build_ext):
    """build_ext that first writes _fastdds_layout.h and puts it on each extension's includes."""

    def run(self) -> None:
        build_temp = Path(self.build_temp).resolve()
        layout_header(build_temp)
        for extension in self.extensions:
            extension.include_dirs.insert(0, str(build_temp))
            extension.depends.append(str(build_temp / LAYOUT_HEADER))
        super().run()


NATIVE = Path('cft_action/native')


def sources(*folders: Path, pattern: str = '*.c') -> list[str]:
    """The sources matching ``pattern`` directly in ``folders``, sorted, relative to this file."""
    return sorted(str(c) for folder in folders for c in folder.glob(pattern))


def native_extension(name: str, own: Path, **options) -> Extension:
    """One of the package's C libraries: the sources of ``own`` and the shared ones of native/."""
    return Extension(f'cft_action.{name}', sources=sources(own, NATIVE),
                     include_dirs=[str(own), str(NATIVE)], libraries=['dl', 'pthread'],
                     depends=sorted(str(h) for h in NATIVE.rglob('*.h')), **options)


def fastdds3_layers() -> list[Extension]:
    """The Fast DDS 3 layers (C++), where Fast DDS 3.3+ headers and their library are found: the
    guard's (native/guard/fastdds3/, ``_cftguard_fastdds3``) and the client's (native/reader/
    fastdds3/, ``_cftreader_fastdds3``), each a library of its own, linked against that Fast DDS,
    which the guard (native/guard/_guard_endpoints.c) and cft_action._rcl load only into a process
    that has it loaded. None elsewhere (each then says once why its layer is off)."""
    three = fastdds_include_dirs()[2]
    lib = layer_library(three)
    if lib is None:
        return []
    return [Extension(f'cft_action.{name}', sources=sources(layer, pattern='*.cpp'),
                      include_dirs=[str(layer), str(NATIVE), *map(str, three)],
                      library_dirs=[str(lib)], libraries=['fastdds'], language='c++',
                      depends=sources(layer, NATIVE, pattern='*.h*'),
                      extra_compile_args=['-O2', '-std=c++17', '-fvisibility=hidden', '-Wall'])
            for name, layer in (('_cftguard_fastdds3', NATIVE / 'guard' / 'fastdds3'),
                                ('_cftreader_fastdds3', NATIVE / 'reader' / 'fastdds3'))]


setup(
    cmdclass={'build_ext': BuildWithLayout},
    ext_modules=[
        # Export only the interposed Fast DDS and rmw_fastrtps functions and the cft_guard_* C API.
        # -fexceptions: a C++ exception thrown by Fast DDS through a wrapper must still run the
        # wrapper's unlock (a cleanup attribute), or the writer's stripe stays locked.
        native_extension('_cftguard', NATIVE / 'guard', extra_compile_args=[
            '-O2', '-fvisibility=hidden', '-fexceptions', '-Wall']),
        native_extension('_cftreader', NATIVE / 'reader',
                         extra_compile_args=['-O2', '-fvisibility=hidden', '-Wall']),
    ] + fastdds3_layers(),
)
