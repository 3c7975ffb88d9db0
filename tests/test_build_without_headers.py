# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Both C libraries build where no Fast DDS 2.14 headers exist (Fast DDS 3 stacks: Kilted's wheels,
Lyrical), without a warning.

setup.py writes ``_fastdds_layout.h`` with ``CFT_LAYOUT_KNOWN 0`` there, and every line that names a
layout macro must sit inside its part's ``#if``. The Jazzy suite compiles the sources against such a
header here, so that a change that breaks the headerless build fails on Jazzy too, not only in the
Kilted venv of ``.ci/run``.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

NATIVE = Path(__file__).resolve().parents[1] / 'cft_action' / 'native'
HEADERLESS = '\n'.join([
    '#ifndef CFT_ACTION_FASTDDS_LAYOUT_H_', '#define CFT_ACTION_FASTDDS_LAYOUT_H_',
    '#define CFT_LAYOUT_KNOWN 0', '#define CFT_LAYOUT_SOURCE "no Fast DDS headers"',
    '#define CFT_LAYOUT_INCLUDES ""', '#endif', ''])


@pytest.mark.parametrize('part', ['guard', 'reader'])
def test_the_library_builds_without_fast_dds_headers_and_without_warnings(part, tmp_path) -> None:
    compiler = shutil.which('cc') or shutil.which('gcc')
    if compiler is None:
        pytest.skip('needs a C compiler')
    (tmp_path / '_fastdds_layout.h').write_text(HEADERLESS)
    own = NATIVE / part
    sources = sorted([*own.glob('*.c'), *NATIVE.glob('*.c')])
    # setup.py's flags (native_extension), warnings as errors; linked with no undefined symbol.
    result = subprocess.run(
        [compiler, '-shared', '-fPIC', '-O2', '-fvisibility=hidden', '-Wall', '-Werror',
         f'-I{tmp_path}', f'-I{own}', f'-I{NATIVE}', *map(str, sources), '-ldl', '-lpthread',
         '-Wl,--no-undefined', '-o', str(tmp_path / f'{part}.so')],
        capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr[-4000:]
