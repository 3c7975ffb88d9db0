"""The package face is lazy: importing cft_action, its pure modules or the CLI's help loads no ROS.

Each check runs in a fresh interpreter (the venv's python, which sets up the ROS libraries), where
rclpy is blocked with ``sys.modules['rclpy'] = None``: any import of it raises ImportError.
"""

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
    result = run_python('import cft_action.sql, cft_action.filters, cft_action.goal_filter\n'
                        'import cft_action.errors')
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
    assert "<class 'cft_action.client.ActionClient'>" in result.stdout
    assert "'rclpy'" in result.stdout


def test_every_public_name_resolves():
    result = run_python('import cft_action\n'
                        'missing = [n for n in cft_action.__all__ if not hasattr(cft_action, n)]\n'
                        'assert not missing, missing\n'
                        'assert not hasattr(cft_action, "no_such_name")', block_rclpy=False)
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize('argv', [
    ['--help'], ['topic', '--help'], ['topic', 'echo', '--help'], ['topic', 'hz', '--help'],
    ['topic', 'bw', '--help'], ['guard', '--help'],
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
