"""Lays out, from this Python's ROS 2 Jazzy wheels, a prefix shaped like apt's ``/opt/ros/jazzy``.

Usage: ``python -m tests.helpers.ros_prefix DEST``, run by the Python of an environment that has the
ROS wheels (tests/test_apt_install.py). ``DEST`` gets, as symbolic links into that environment:

- ``lib/*.so*`` (the ROS and Fast DDS libraries) and ``include/`` (their headers, Fast DDS's in
  ``include/fastrtps``, where setup.py finds apt's), ``share/`` (the ament index);
- ``lib/pythonX.Y/site-packages/``: the top-level modules of ``ros-jazzy-rclpy[fastrtps]`` and
  ``ros-jazzy-test-msgs`` and of everything they require, but setuptools (apt's ROS takes it from
  the system's Python, as the venv of the README does; on PYTHONPATH it would shadow the venv's
  own for pip's builds) and the ``.pth`` files (a directory on PYTHONPATH is not a site directory:
  nothing processes them there);
- ``setup.bash``, which exports what sourcing apt's ``setup.bash`` exports for Python:
  ``AMENT_PREFIX_PATH``, ``PYTHONPATH`` and ``LD_LIBRARY_PATH`` (which the wheels' own bootstrap
  ``.pth`` would otherwise set, with the ``ros_*.libs`` folders of their vendored libraries).

Prints ``DEST``'s site-packages directory.
"""

import importlib.metadata
import sys
from pathlib import Path

from packaging.requirements import Requirement

ROOTS = [('ros-jazzy-rclpy', {'fastrtps'}), ('ros-jazzy-test-msgs', set())]
#: What apt's ROS takes from the system's Python, not from /opt/ros/jazzy.
NOT_IN_THE_PREFIX = {'setuptools'}


def closure() -> list[importlib.metadata.Distribution]:
    """The distributions of ``ROOTS`` and of everything they require, with their extras."""
    found: dict[str, tuple[importlib.metadata.Distribution, set[str]]] = {}
    pending = list(ROOTS)
    while pending:
        name, extras = pending.pop()
        distribution = importlib.metadata.distribution(name)
        key = distribution.metadata['Name'].lower().replace('_', '-')
        if key in found and extras <= found[key][1]:
            continue
        known = found.setdefault(key, (distribution, set()))[1]
        known |= extras
        for text in distribution.requires or []:
            requirement = Requirement(text)
            marker = requirement.marker
            if marker and not any(marker.evaluate({'extra': e}) for e in known or {''}):
                continue
            pending.append((requirement.name, set(requirement.extras)))
    return [d for key, (d, _) in found.items() if key not in NOT_IN_THE_PREFIX]


def top_levels(distribution: importlib.metadata.Distribution) -> set[str]:
    """The names a distribution installed directly into site-packages (its data files excluded)."""
    names = set()
    for file in distribution.files or []:
        first = file.parts[0]
        if first != '..' and not first.endswith('.pth') and first != '__pycache__':
            names.add(first)
    return names


def main() -> None:
    destination = Path(sys.argv[1])
    source_site = Path(importlib.metadata.distribution('ros-jazzy-rclpy').locate_file(''))
    source_prefix = Path(sys.prefix)
    site = destination / 'lib' / f'python{sys.version_info[0]}.{sys.version_info[1]}' / \
        'site-packages'
    site.mkdir(parents=True)
    for library in (source_prefix / 'lib').glob('*.so*'):
        (destination / 'lib' / library.name).symlink_to(library)
    for folder in ('include', 'share'):
        (destination / folder).symlink_to(source_prefix / folder, target_is_directory=True)
    for distribution in closure():
        for name in top_levels(distribution):
            if (source_site / name).exists() and not (site / name).exists():
                (site / name).symlink_to(source_site / name)
    libraries = [destination / 'lib', *sorted(site.glob('ros_*.libs'))]
    (destination / 'setup.bash').write_text(
        f'export AMENT_PREFIX_PATH={destination}\n'
        f'export PYTHONPATH={site}\n'
        f'export LD_LIBRARY_PATH={":".join(str(p) for p in libraries)}\n')
    print(site, flush=True)


if __name__ == '__main__':
    main()
