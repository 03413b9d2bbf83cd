"""The real-time relay (bridge.relay) with real UDP sockets on 127.0.0.1."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bridge.link import LinkConfig, LinkSettings
from bridge.relay import Relay, parse_address

ROOT = Path(__file__).resolve().parent.parent
STAMP = struct.Struct("<dI")
FRAME = 93  # bytes, a HIL_ACTUATOR_CONTROLS frame


def udp(timeout: float = 2.0) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(timeout)
    return s


def stamped(i: int, size: int = FRAME) -> bytes:
    head = STAMP.pack(time.perf_counter(), i)
    return head + bytes(size - len(head))


def ping_pong(client: socket.socket, target: socket.socket, relay_addr, rounds: int) -> tuple[list, list]:
    """client -> relay -> target, target -> relay -> client, one at a time: one-way delays (s)."""
    up, down = [], []
    for i in range(rounds):
        client.sendto(stamped(i), relay_addr)
        data, back = target.recvfrom(2048)
        t_sent, n = STAMP.unpack_from(data)
        up.append(time.perf_counter() - t_sent)
        assert n == i and len(data) == FRAME
        target.sendto(stamped(i, 242), back)
        data, _ = client.recvfrom(2048)
        t_sent, n = STAMP.unpack_from(data)
        down.append(time.perf_counter() - t_sent)
        assert n == i and len(data) == 242
    return up, down


def test_twenty_ms_each_way_measured_within_two_ms() -> None:
    target, client = udp(), udp()
    cfg = LinkConfig(delay_ms=20.0)
    with Relay(("127.0.0.1", 0), target.getsockname(), LinkSettings(cfg, cfg)) as relay:
        relay.start()
        up, down = ping_pong(client, target, relay.address, 40)
    for d in (up, down):
        assert abs(np.median(d) * 1000.0 - 20.0) <= 2.0
        assert min(d) >= 0.020  # never early
    s = relay.summary()
    assert s["up"]["sent"] == s["up"]["delivered"] == 40 == s["down"]["delivered"]
    assert s["up"]["delay_ms"]["p50"] == pytest.approx(20.0)
    assert abs(s["up"]["measured_ms"]["p50"] - 20.0) <= 2.0
    target.close()
    client.close()


def test_no_impairment_forwards_at_once_and_loss_drops_what_the_model_says() -> None:
    target, client = udp(0.5), udp()
    with Relay(("127.0.0.1", 0), target.getsockname()) as relay:
        relay.start()
        up, _ = ping_pong(client, target, relay.address, 30)
    assert np.median(up) < 0.005
    lossy = LinkSettings(LinkConfig(loss_pct=50.0, seed=3))
    with Relay(("127.0.0.1", 0), target.getsockname(), lossy) as relay:
        relay.start()
        for i in range(200):
            client.sendto(stamped(i), relay.address)
        got = []
        try:
            while True:
                got.append(STAMP.unpack_from(target.recv(2048))[1])
        except TimeoutError:
            pass
    st = relay.summary()["up"]
    assert st["sent"] == 200 and len(got) == st["delivered"] and st["lost"] == 200 - len(got)
    assert 70 < len(got) < 130
    assert got == sorted(got)
    target.close()
    client.close()


def test_bsst_relay_process_stops_on_sigterm_and_writes_stats(tmp_path: Path) -> None:
    target, client = udp(), udp()
    tport = target.getsockname()[1]
    stats = tmp_path / "relay.json"
    proc = subprocess.Popen([sys.executable, "-m", "bridge", "relay", "--listen", "127.0.0.1:0",
                             "--to", f"127.0.0.1:{tport}", "--down-delay", "5", "--stats", str(stats)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        line = proc.stdout.readline()  # the ready line, printed once bound
        m = re.search(r"listening on ([\d.]+):(\d+)", line)
        assert m, line + proc.stderr.read()
        up, down = ping_pong(client, target, (m.group(1), int(m.group(2))), 20)
        assert min(down) >= 0.005 and np.median(up) < 0.005
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "added delay p50" in out
    s = json.loads(stats.read_text())
    assert s["up"]["delivered"] == s["down"]["delivered"] == 20
    assert s["down"]["delay_ms"]["p50"] == pytest.approx(5.0)
    assert s["cpu_us_per_packet"] > 0
    target.close()
    client.close()


@pytest.mark.parametrize(("args", "message"), [
    (["--listen", "127.0.0.1:x", "--to", "127.0.0.1:1"], "--listen must be HOST:PORT"),
    (["--listen", "127.0.0.1:0", "--to", "nowhere"], "--to must be HOST:PORT"),
    (["--listen", "127.0.0.1:0", "--to", "127.0.0.1:1", "--loss", "-3"], "--loss must be in [0, 100]"),
    (["--listen", "127.0.0.1:0", "--to", "127.0.0.1:1", "--mission", "nope.toml"], "nope.toml: no such file"),
])
def test_bad_relay_input_exits_2_with_one_line(args: list[str], message: str, capsys) -> None:
    from bridge.cli import main

    assert main(["relay", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_busy_port_is_a_clear_error(capsys) -> None:
    from bridge.cli import main

    busy = udp()
    port = busy.getsockname()[1]
    assert main(["relay", "--listen", f"127.0.0.1:{port}", "--to", "127.0.0.1:1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--listen 127.0.0.1:{port}: cannot bind" in err[0]
    busy.close()


def test_parse_address() -> None:
    assert parse_address("127.0.0.1:14560", "--to") == ("127.0.0.1", 14560)
    with pytest.raises(ValueError, match="--to"):
        parse_address("127.0.0.1:99999", "--to")
