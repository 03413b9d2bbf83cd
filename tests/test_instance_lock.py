"""Covers bridge.session.children, bridge.session, bridge.session.fleet and bridge.cli.flying: an instance's lock.

``bsst sitl --instance N`` (and ``bsst vehicle``'s, a fleet's range) did not take instance N's lock, the
``flock`` on ``<tmp>/bsst-instance-N.lock`` that the suite's sessions (``instance_slot()``) and ``bsst sweep``
hold: a person's session beside the suite flew on a test's instance (``test_local_origin`` heard a stranger, system
4, instance 3's), and two sessions started on one instance both wrote their run directories before the second's
vehicle failed to bind. Now every session holds its instances' locks for its life and refuses, before anything is
written, one another session holds (exit 2, naming its pid); the kernel releases a lock when its process dies.
Real ``bsst`` processes on 127.0.0.1; the holders beside them are real processes too.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from pathlib import Path

import pytest

from bridge.core.locks import lock_holder_in
from bridge.nodes.report import Ready, parse_line
from bridge.record.halves import count_records
from bridge.session import hold_instances, instance_slot, sitl
from params import ConfigError
from tests.sitlkit import ROOT, Proc, run_bsst
from tests.waiting import wait_for

pytestmark = pytest.mark.process  # starts processes

UP = "bsst sitl: vehicle up, sysid "
SINE = 'name = "sine"\nduration_s = {}\n[trajectory]\nkind = "sine"\n'
# another session's holder, as a pytest worker's instance_slot() is: it prints the instance it holds, then waits
HOLDER = ("import signal\nfrom bridge.session import instance_slot\nwith instance_slot() as n:\n"
          "    print(n, flush=True)\n    signal.pause()\n")


def busy(n: int, pid: int, flag: str | None = None) -> str:
    """The one line a session refused on instance ``n`` says, ``pid`` holding it."""
    return f"bsst: {flag or f'--instance {n}'}: instance {n} is in use by another session (pid {pid}); pick another " \
           "instance\n"


def free(n: int) -> bool:
    """Whether instance ``n``'s lock can be taken now (taken and released at once)."""
    try:
        with hold_instances((n,), lambda k: f"instance {k}"):
            return True
    except ConfigError:
        return False


def _mission(tmp_path: Path, seconds: float, hold: bool = False) -> str:
    """The sine of ``seconds``; ``hold``: its end held, for a session flown at 1x whose end landing (and
    COM_DISARM_LAND after it, ~4 s of the wall clock) no test reads."""
    path = tmp_path / f"sine{seconds:g}{'-hold' if hold else ''}.toml"
    path.write_text(SINE.format(seconds) + ('[end]\naction = "hold"\n' if hold else ""))
    return str(path)


def _flying(tmp_path: Path, mission: str) -> tuple[Proc, int]:
    """``bsst sitl MISSION --speed 1`` up on the lowest instance from 2 it could take: one another session holds (a
    pytest worker's instance_slot(), which takes the highest free first) refuses it, and the next is tried."""
    for n in range(2, 10):
        p = Proc.bsst("sitl", mission, "--instance", str(n), "--speed", "1", "--out", str(tmp_path / f"a{n}"),
                      "--no-plots", cwd=ROOT)
        said = p.wait_line(lambda s: s.startswith((UP, "bsst: --instance")), timeout=120)
        if said.startswith(UP):
            return p, n
        # refused: its one line on stderr (bsst sitl's stdout is a person's, no reports), the last it says
        held = f"bsst: --instance {n}: instance {n} is in use by another session (pid "
        assert p.ended() == 2 and said.startswith(held) and p.lines[-1] == said, p.lines[-5:]
    raise AssertionError("no free instance from 2 to 9")


def test_two_sessions_on_one_instance_the_second_is_refused_the_first_flies_and_the_instance_is_free_after(
        tmp_path: Path) -> None:
    """Two ``bsst sitl --instance N`` at once: the second says, before anything is written, that the first holds N
    (its pid), exit 2; the first flies its mission to the end (exit 0); then N is free again, and a third session
    flies on it. The old code refused the second only for its vehicle's port, not naming the session holding it,
    and only once the first's vehicle had bound it (earlier, both wrote their run directories)."""
    a, n = _flying(tmp_path, _mission(tmp_path, 8.0, hold=True))
    try:
        b = run_bsst("sitl", _mission(tmp_path, 0.5), "--instance", str(n), "--out", tmp_path / "b", "--no-plots",
                     timeout=120)
        assert a.p.poll() is None, "the first session ended before the second was refused: a longer mission"
        assert (b.returncode, b.stdout, b.stderr) == (2, "", busy(n, a.p.pid)), b
        assert not (tmp_path / "b").exists()
        a.p.wait(timeout=120)
    finally:
        a.stop()
    assert a.p.returncode == 0 and any(ln.startswith("outcome") and "completed" in ln for ln in a.lines), a.lines[-30:]
    assert free(n), f"instance {n} still held after its session ended"
    c = run_bsst("sitl", _mission(tmp_path, 0.5), "--instance", str(n), "--out", tmp_path / "c", "--no-plots",
                 timeout=120)
    assert c.returncode == 0 and c.stderr.startswith(UP), c.stderr[-2000:]


def test_an_instance_held_by_another_session_refuses_sitl_a_fleet_and_a_scripts_session(tmp_path: Path) -> None:
    """Another process holds instance N as a pytest worker's ``instance_slot()`` does, its ports unbound (a test that
    listens as N's ground station, or whose session has not bound yet): ``bsst sitl --instance N``, a fleet whose
    range takes N and ``bridge.session.sitl(instance=N)`` are each refused, naming the holder, nothing written. The
    old code flew each of them on N (exit 0), its telemetry sent to the holder's ground-station port."""
    holder = Proc([sys.executable, "-c", HOLDER], cwd=ROOT)
    try:
        n = int(holder.wait_line(str.isdigit, timeout=60))
        pid = holder.p.pid
        r = run_bsst("sitl", _mission(tmp_path, 0.5), "--instance", str(n), "--out", tmp_path / "r", "--no-plots",
                     timeout=120)
        assert (r.returncode, r.stdout, r.stderr) == (2, "", busy(n, pid)), r
        if n > 0:  # a fleet of two from N - 1: its vehicle 2 is instance N (vehicle 1's N - 1 may be another's)
            f = run_bsst("sitl", _mission(tmp_path, 0.5), "--vehicles", "2", "--instance", str(n - 1), "--out",
                         tmp_path / "f", "--no-plots", timeout=120)
            assert f.returncode == 2 and "is in use by another session (pid" in f.stderr, f
            assert f.stderr == busy(n, pid, f"--instance {n - 1} (vehicle 2)") or "(vehicle 1)" in f.stderr, f.stderr
        with pytest.raises(ConfigError, match=rf"^--instance {n}: instance {n} is in use by another session \(pid "
                                              rf"{pid}\); pick another instance$"):
            sitl(_mission(tmp_path, 0.5), instance=n, out=tmp_path / "s", plots=False)
        assert not any((tmp_path / d).exists() for d in ("r", "f", "s"))
    finally:
        holder.stop()


def test_a_vehicle_holds_its_instance_until_it_dies_even_by_sigkill(tmp_path: Path) -> None:
    """``bsst vehicle --instance N`` holds N while it serves: a second is refused (exit 2, naming the first's pid,
    its --out not written); SIGKILL leaves no lock behind (the kernel releases a flock with its process) and a
    third serves on N. The old code refused the second only when it could not bind 14560 + N, after its --out."""
    for n in range(2, 10):  # the lowest instance a vehicle can take (as _flying)
        v = Proc.bsst("vehicle", "--instance", str(n), cwd=ROOT)
        line = v.wait_line(lambda s: isinstance(parse_line(s), Ready) or s.startswith("bsst:"), timeout=60)
        if isinstance(parse_line(line), Ready):
            break
        assert v.ended() == 2 and "in use" in line, v.lines[-5:]  # (stop() here: -15 once in the CI)
    else:
        raise AssertionError("no free instance from 2 to 9")
    try:
        second = run_bsst("vehicle", "--instance", str(n), "--out", tmp_path / "second", timeout=60)
        assert (second.returncode, second.stderr) == (2, busy(n, v.p.pid)), second
        assert not (tmp_path / "second").exists()
        v.p.send_signal(signal.SIGKILL)
        v.p.wait(timeout=30)
    finally:
        v.stop()
    wait_for(lambda: free(n), 10, f"instance {n} free after its vehicle was killed")
    third = Proc.bsst("vehicle", "--instance", str(n), cwd=ROOT)
    try:
        third.wait_report(Ready, timeout=60)
    finally:
        assert third.stop() == 0


def test_the_lock_holder_is_found_on_its_inode_where_the_locks_device_is_not_the_files() -> None:
    """/proc/locks names a ``flock``'s file by device and inode; on btrfs a subvolume's files stat on a device of
    their own, so the holder was never found by both (None: a test's own session inside its ``instance_slot`` was
    refused as another session's). The device and inode are matched first (the waiters' ``->`` lines and POSIX
    locks passed over); where no lock is on that device, the inode alone, if one process holds a flock on it."""
    dev, ino = os.makedev(0, 0x2F), 2146956  # fstat's: btrfs's anonymous device of the subvolume
    locks = ["1: POSIX  ADVISORY  WRITE 4547 00:2f:2146956 0 EOF\n",
             "2: FLOCK  ADVISORY  WRITE 7001 00:1e:2146956 0 EOF\n",  # the lock, on the file system's device
             "2: -> FLOCK  ADVISORY  WRITE 7002 00:1e:2146956 0 EOF\n",  # a waiter
             "3: FLOCK  ADVISORY  WRITE 7003 00:1e:99 0 EOF\n"]
    assert lock_holder_in(locks, dev, ino) == 7001
    assert lock_holder_in(locks + ["4: FLOCK  ADVISORY  WRITE 7004 00:2f:2146956 0 EOF\n"], dev, ino) == 7004
    assert lock_holder_in(locks + ["4: FLOCK  ADVISORY  WRITE 7005 00:31:2146956 0 EOF\n"], dev, ino) is None
    assert lock_holder_in(locks, dev, 5) is None


def test_two_threads_of_one_process_cannot_fly_one_instance(tmp_path: Path) -> None:
    """``bridge.session.sitl(instance=N)`` from two threads of one process: the second is refused while the first
    flies (its flock is the process's, so the own-holder rule let both fly N's ports at once until the third wave's
    forty-second session), the first completes, and N is free for this process's next session after it."""
    with instance_slot() as n:
        first: dict[str, object] = {}

        def fly() -> None:
            try:
                first["run"] = sitl(_mission(tmp_path, 1.5, hold=True), instance=n, out=tmp_path / "a", plots=False,
                                    speed=1.0)  # (1.5 s of wall time: it flies on while the second, refused
                # in this process before anything starts, is turned away; the assert below says if it had ended)
            except BaseException as exc:  # re-raised below
                first["error"] = exc

        th = threading.Thread(target=fly, name="first-session")
        th.start()
        try:
            wait_for(lambda: count_records(tmp_path / "a" / "vehicle.bin") > 0 or not th.is_alive(), 60,
                     "the first session flying")
            assert th.is_alive(), first
            with pytest.raises(ConfigError, match=rf"^--instance {n}: instance {n} is in use by another session of "
                                                  rf"this process \(pid {os.getpid()}, thread 'first-session'\); "):
                sitl(_mission(tmp_path, 0.5), instance=n, out=tmp_path / "b", plots=False)
        finally:
            th.join(timeout=120)
        assert "error" not in first and first["run"].outcome == "completed", first  # type: ignore[attr-defined]
        assert not (tmp_path / "b").exists()
        with hold_instances((n,), str):  # free again for this process
            pass
