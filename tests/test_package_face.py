"""The package face is lazy: importing cft_action, its pure modules or the CLI's help loads no ROS.

Each check runs in a fresh interpreter (the venv's python, which sets up the ROS libraries), where
rclpy is blocked with ``sys.modules['rclpy'] = None``: any import of it raises ImportError.
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

# Prints the ROS modules that were imported (a blocked one is None), after the code under test.
_REPORT = """
ros = sorted(m for m, module in sys.modules.items() if module is not None
             and (m.split('.')[0] in ('rclpy', 'rosidl_parser', 'rpyutils')
                  or m.split('.')[0].endswith(('_msgs', '_interfaces'))))
print('ROS MODULES:', ros)
"""


def run_python(code: str, *, block_rclpy: bool = True) -> subprocess.CompletedProcess:
    prelude = "import sys\nsys.modules['rclpy'] = None\n" if block_rclpy else 'import sys\n'
    return subprocess.run([sys.executable, '-c', prelude + code + _REPORT], capture_output=True,
                          text=True, timeout=60)


def test_pure_modules_import_without_rclpy():
    result = run_python('import cft_action.topics.sql, cft_action.topics.filters\n'
                        'import cft_action.action.goal_filter, cft_action.errors')
    assert result.returncode == 0, result.stderr
    assert 'ROS MODULES: []' in result.stdout


def test_the_package_imports_no_ros_until_a_ros_name_is_used():
    result = run_python('import cft_action\n'
                        'assert issubclass(cft_action.ContentFilterError,\n'
                        '                  cft_action.CftActionError)\n'
                        'assert cft_action.sql.compile_filter("data > 1")\n'
                        'from cft_action import CftActionError, InvalidArgumentError')
    assert result.returncode == 0, result.stderr
    assert 'ROS MODULES: []' in result.stdout

    result = run_python('import cft_action\nprint(cft_action.ActionClient)', block_rclpy=False)
    assert result.returncode == 0, result.stderr
    assert "<class 'cft_action.action.client.ActionClient'>" in result.stdout
    assert "'rclpy'" in result.stdout


def test_every_public_name_resolves():
    result = run_python('import cft_action\n'
                        'missing = [n for n in cft_action.__all__ if not hasattr(cft_action, n)]\n'
                        'assert not missing, missing\n'
                        'assert not hasattr(cft_action, "no_such_name")', block_rclpy=False)
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize('argv', [
    ['--help'], ['topic', '--help'], ['topic', 'echo', '--help'], ['topic', 'hz', '--help'],
    ['topic', 'bw', '--help'], ['guard', '--help'], ['action', '--help'],
    ['action', 'list', '--help'], ['action', 'info', '--help'],
])
def test_cli_help_imports_no_rclpy(argv):
    """Runs the installed ``cft-action`` console script itself."""
    script = Path(sys.executable).parent / 'cft-action'
    result = run_python(f'import runpy\nsys.argv = {["cft-action", *argv]!r}\n'
                        f'try:\n    runpy.run_path({str(script)!r}, run_name="__main__")\n'
                        'except SystemExit as e:\n    assert e.code in (0, None), e.code\n')
    assert result.returncode == 0, result.stderr
    assert 'usage: cft-action' in result.stdout
    assert 'ROS MODULES: []' in result.stdout


# The public modules of the flat layout before cft_action/action, parameters and topics.
FLAT_MODULES = {
    'client': 'action.client', 'goal_filter': 'action.goal_filter',
    'parameter_events': 'parameters.parameter_events', 'arrival': 'topics.arrival',
    'filters': 'topics.filters', 'message_types': 'topics.message_types',
    'message_yaml': 'topics.message_yaml', 'sql': 'topics.sql',
    'subscription': 'topics.subscription', 'topic_api': 'topics.topic_api',
}


@pytest.mark.parametrize('old, new', FLAT_MODULES.items(), ids=list(FLAT_MODULES))
def test_a_module_of_the_flat_layout_imports_as_the_module_it_became(old, new):
    result = run_python(f'import importlib, cft_action.{old} as old, cft_action.{new} as new\n'
                        f'from cft_action import {old} as by_from\n'
                        'assert old is new is by_from, (old, new)\n'
                        f'assert new.__spec__.name == "cft_action.{new}", new.__spec__\n'
                        'importlib.reload(new)', block_rclpy=False)
    assert result.returncode == 0, result.stderr


def test_every_name_the_readme_imports_resolves():
    """Each ``from cft_action... import name`` and each dotted ``cft_action.x.y`` of README.md."""
    readme = (Path(__file__).resolve().parent.parent / 'README.md').read_text()
    imports = re.findall(r'^\s*from (cft_action[\w.]*) import ([\w, ]+)$', readme, re.MULTILINE)
    dotted = set(re.findall(r'\b(cft_action(?:\.\w+)+)', readme))
    assert imports and dotted
    code = ['import importlib']
    code += [f'from {module} import {names}' for module, names in imports]
    for path in sorted(dotted):
        # the longest module prefix of the path, then its attributes
        code.append(f'parts = {path.split(".")!r}\n'
                    'for i in range(len(parts), 0, -1):\n'
                    '    try:\n'
                    '        value = importlib.import_module(".".join(parts[:i]))\n'
                    '        break\n'
                    '    except ModuleNotFoundError:\n'
                    '        pass\n'
                    'for attribute in parts[i:]:\n'
                    '    value = getattr(value, attribute)')
    result = run_python('\n'.join(code), block_rclpy=False)
    assert result.returncode == 0, result.stderr
