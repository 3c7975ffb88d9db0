# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The machine and the versions a result was measured with, for every benchmark's results file."""

from __future__ import annotations

import os
import platform
from typing import Any, Optional

from harness.crash import fastdds_library


def environment_facts() -> dict[str, Any]:
    """Machine and versions, for a result file."""
    from importlib import metadata
    versions: dict[str, Optional[str]] = {}
    for dist in ('ros-jazzy-rclpy', 'ros-kilted-rclpy', 'rclpy', 'ros-rcl', 'ros-rcl-action',
                 'ros-rmw-fastrtps-cpp', 'ros-fastrtps', 'ros-fastdds', 'cft-action', 'matplotlib'):
        try:
            versions[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            versions[dist] = None
    cpu = ''
    try:
        with open('/proc/cpuinfo') as info:
            cpu = next((line.split(':', 1)[1].strip() for line in info
                        if line.startswith('model name')), '')
    except OSError:
        pass
    return {'host': platform.node(), 'platform': platform.platform(),
            'python': platform.python_version(), 'cpus': os.cpu_count(), 'cpu_model': cpu,
            'load_average_at_start': os.getloadavg(), 'versions': versions,
            'fastdds_library': fastdds_library(),
            'rmw': os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp (default)'),
            # The guard's switches, which the servers inherit (e.g. CFT_GUARD_KEEP_READERS=0).
            'guard_environment': {
                k: v for k, v in sorted(os.environ.items())
                if k.startswith('CFT_GUARD_') or k == 'CFT_ACTION_READER_FILTERS'}}
