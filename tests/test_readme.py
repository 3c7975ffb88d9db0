"""The README's runnable examples run, so they cannot go stale."""

import re
import subprocess
import sys
from pathlib import Path
from typing import Optional

from cft_action import guard
from tests.support import action_server

README = Path(__file__).parent.parent / 'README.md'


def readme_example(name: str, language: str = 'python') -> str:
    """The code block marked ``<!-- example: name -->`` in the README."""
    match = re.search(rf'<!-- example: {name} -->\n```{language}\n(.*?)```', README.read_text(),
                      re.DOTALL)
    assert match, f'README has no example {name}'
    return match.group(1)


def test_readme_gives_the_two_set_up_commands_first():
    """``make demo`` and ``make test`` do all the set-up on a fresh machine (the Makefile), and
    the README gives them before any other command of this repository."""
    readme = README.read_text()
    commands = [line.split('#')[0].strip()
                for line in readme_example('set_up', 'bash').splitlines()]
    assert commands == ['make demo', 'make test']
    assert readme.index('<!-- example: set_up -->') < readme.index('make lint')


def run_tutorial_client(directory: Path, *, client_env: Optional[dict] = None,
                        server_env: Optional[dict] = None) -> str:
    """Run the README's tutorial client against a guarded Fibonacci server; return its output.

    ``client_env`` is the client's environment (default: this process's), ``server_env`` the
    server's with the guard in ``LD_PRELOAD`` (default: :func:`cft_action.guard.environment`).
    The client runs in ``directory``, where its script is written.
    """
    source = readme_example('tutorial_client')
    assert 'from rclpy.action import ActionClient' not in source
    script = directory / 'tutorial_client.py'
    script.write_text(source)
    server = action_server('fibonacci', 0.01, env=server_env or guard.environment())
    try:
        run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                             timeout=60, cwd=directory, env=client_env)
    finally:
        server.stop()
    log = run.stdout + run.stderr
    assert run.returncode == 0, log
    return log


def check_tutorial_log(log: str) -> None:
    """The tutorial's goal was accepted, gave its result and some of its feedback."""
    assert 'Goal accepted :)' in log, log
    assert 'Result: array' in log, log
    # The tutorial shuts down at its result: on a loaded machine, feedback still on its way then
    # (a lost sample is resent after the server's next heartbeat) is not delivered, as with rclpy.
    feedback = log.count('Received feedback: array')
    assert 1 <= feedback <= 10, log


def test_tutorial_client_runs_unchanged_but_for_the_import(tmp_path):
    check_tutorial_log(run_tutorial_client(tmp_path))


def test_rate_example_runs(tmp_path):
    """The README's rate-limited and polled subscriptions, on a 100 Hz publisher in its process."""
    script = tmp_path / 'rate.py'
    script.write_text(readme_example('rate'))
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=60, cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.splitlines()
    assert [line for line in lines if line.startswith('poll:')] == [
        'poll: 0', 'poll: 1', 'poll: 2'], lines
    # 3 s at max_rate=2: the first message at once, then one a 0.5 s
    assert 5 <= sum(line.startswith('std_msgs.msg.Int32(') for line in lines) <= 7, lines
    assert lines[-1] == 'filtered in reader', lines
