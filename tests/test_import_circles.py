# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""No import circles: calls go one way between the files of the house.

- Python: a module that imports another (at its top or inside a function; ``from pkg import mod``
  imports ``pkg.mod``) depends on it, over the library, ``harness``, the benchmarks, the demos,
  ``compat`` and the tests.
- C: a source file that includes another file's header (``x.h`` of ``x.c``), or names a function
  or variable that another defines, depends on it, over ``cft_action/native``
  (``_guard_families.h`` says which way the guard's parts go).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import Iterable

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ('cft_action', 'harness', 'benchmarks', 'demos', 'compat', 'tests')


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        while work:
            node, edges = work[-1]
            for nxt in edges:
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                    break
                if nxt in stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def python_modules() -> dict[str, Path]:
    modules = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob('*.py'):
            parts = list(path.relative_to(ROOT).with_suffix('').parts)
            modules['.'.join(parts[:-1] if parts[-1] == '__init__' else parts)] = path
    return modules


def imported(module: str, path: Path, modules: Iterable[str]) -> set[str]:
    known = set(modules)
    package = module.split('.') if path.name == '__init__.py' else module.split('.')[:-1]
    deps = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for alias in node.names:
                name = alias.name
                while name and name not in known:
                    name = name.rpartition('.')[0]
                deps.add(name)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                base = '.'.join(package[:len(package) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                deps.add(f'{base}.{alias.name}' if f'{base}.{alias.name}' in known else base)
    return {d for d in deps if d in known and d != module}


def test_no_python_module_imports_one_that_imports_it_back() -> None:
    modules = python_modules()
    graph = {name: imported(name, path, modules) for name, path in modules.items()}
    assert circles(graph) == []


# A function's definition at file scope, or a variable's (not `extern`), in the C sources.
C_DEFINITION = re.compile(r'^(?!extern\b)[A-Za-z_][^;{}()]*?\b(cft_\w+)\s*(?:\([^;{]*\)\s*\{|=|;)',
                          re.MULTILINE)


def test_no_c_file_uses_a_file_that_uses_it_back() -> None:
    """By header (``#include "x.h"`` of ``x.c``) and by name: a file that names a ``cft_`` function
    or variable defined in another uses it, whichever header declares it."""
    native = ROOT / 'cft_action' / 'native'
    sources = {path.stem: path.read_text() for path in native.rglob('*.c')}
    defined = {name: stem for stem, text in sources.items() for name in C_DEFINITION.findall(text)}
    graph = {}
    for stem, text in sources.items():
        headers = {h for h in re.findall(r'#include "(\w+)\.h"', text) if h in sources}
        names = {defined.get(name) for name in re.findall(r'\b(cft_\w+)\b', text)}
        graph[stem] = (headers | names) - {stem, None}
    assert circles(graph) == []


def test_a_circle_is_found() -> None:
    assert circles({'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}) == [['a', 'b', 'c']]
