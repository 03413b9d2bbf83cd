"""Covers tests.gcsfork and tests.sitlkit: a ground-station script forked warm runs as the same script cold does.

(tests/sitlkit.py's ``run_script`` and ``Script``, through the test kit's fork server.)

In:  a pymavlink script and a Ctrl-C'd one, each run forked warm and cold
Out: assertions: the same stdout, stderr and exit status; its own pid; SIGINT's status -2
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from tests.sitlkit import ENV, Script, run_script

pytestmark = pytest.mark.process  # starts processes

# what a script sees of its start (argv, __main__, sys.path[0], the directory, the wire protocol its environment asks
# for through pymavlink's import), a non-daemon thread that prints after the main thread has ended, a status
SEEN = r"""
import os, sys, threading, time
from pymavlink import mavutil
print(sys.argv, __name__, repr(sys.path[0]), os.getcwd(), mavutil.mavlink.__name__, os.environ["MAVLINK_DIALECT"])
print("to stderr", file=sys.stderr)
threading.Thread(target=lambda: (time.sleep(0.2), print("the thread's last line"))).start()
sys.exit(int(sys.argv[1]))
"""


@pytest.mark.parametrize("env", [ENV, {k: v for k, v in ENV.items() if k != "MAVLINK20"}], ids=["mavlink2", "mavlink1"])
def test_a_script_forked_warm_prints_and_ends_as_it_does_cold(tmp_path, env) -> None:
    """The same stdout (its threads' lines included), stderr and exit status as ``python -c`` exec'd, with the
    MAVLink version its environment gives pymavlink (the server imported it under its own)."""
    warm = run_script("-c", SEEN, "3", cwd=tmp_path, env=env, timeout=60)
    cold = subprocess.run([sys.executable, "-c", SEEN, "3"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=60)
    assert (warm.returncode, warm.stdout, warm.stderr) == (cold.returncode, cold.stdout, cold.stderr)
    assert cold.returncode == 3 and "the thread's last line" in cold.stdout


def test_a_script_forked_warm_is_its_own_process_and_a_ctrl_c_ends_it_as_cold() -> None:
    """Its own pid and session; an uncaught KeyboardInterrupt ends it by SIGINT (-2), its traceback on stderr."""
    p = Script("-c", "import os, time; print(os.getpid(), os.getsid(0), flush=True); time.sleep(60)")
    try:
        pid, sid = map(int, p.stdout.readline().split())  # type: ignore[union-attr]
        assert pid == p.pid == sid and pid != os.getpid()
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(30)
    finally:
        p.kill()
    assert p.returncode == -signal.SIGINT and err.rstrip().endswith("KeyboardInterrupt"), err


@pytest.mark.parametrize("args, env", [
    (("-m", "platform"), ENV),  # an interpreter option, not a script's path: once FileNotFoundError .../-m
    (("-c", "import sys; print(sys.stdout.encoding, sys.dont_write_bytecode)"),
     {**ENV, "PYTHONIOENCODING": "latin-1", "PYTHONDONTWRITEBYTECODE": "1"}),  # once the server's own, frozen
], ids=["-m", "PYTHON-vars"])
def test_what_the_interpreter_reads_at_its_start_is_the_scripts_own(tmp_path, args, env) -> None:
    """An interpreter option other than ``-c`` or start-up variables (``PYTHON*``) not the server's: the script
    runs as exec'd (started cold), the same output and status."""
    warm = run_script(*args, cwd=tmp_path, env=env, timeout=60)
    cold = subprocess.run([sys.executable, *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert (warm.returncode, warm.stdout, warm.stderr) == (cold.returncode, cold.stdout, cold.stderr)
    assert cold.returncode == 0 and cold.stdout.strip(), cold
