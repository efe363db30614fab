#!/usr/bin/env python3
"""Self-test of slave.py: socat pty pair, the slave on one end, a pymodbus serial client
(and raw frames) on the other. Exits nonzero on the first failed check.

Byte-exact vectors are the example frames printed in ZLTECH's ZLAC8015D RS485
Communication Instruction V1.06 (§2.1-2.3 p.4-5, §3.1-3.6 p.6-13).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time

from pymodbus.client import ModbusSerialClient
from pymodbus.framer import FramerRTU

HERE = os.path.dirname(os.path.abspath(__file__))

# (request, reply) as printed in the manual; reply None = the request is echoed.
MANUAL_FRAMES = [
    # §3.1 velocity mode initialization (p.6)
    ("01 06 20 0D 00 03 53 C8", None),
    ("01 06 20 80 01 F4 83 F5", None),
    ("01 06 20 81 01 F4 D2 35", None),
    ("01 06 20 82 01 F4 22 35", None),
    ("01 06 20 83 01 F4 73 F5", None),
    ("01 06 20 0E 00 08 E2 0F", None),
    # §3.1 left / right / synchronous velocity control (p.7)
    ("01 06 20 88 00 64 03 CB", None),
    ("01 06 20 88 FF 9C 43 B9", None),
    ("01 06 20 89 00 64 52 0B", None),
    ("01 06 20 89 FF 9C 12 79", None),
    ("01 10 20 88 00 02 04 FF 9C FF 9C D2 0B", "01 10 20 88 00 02 CA 22"),
    ("01 10 20 88 00 02 04 00 64 00 64 23 9C", "01 10 20 88 00 02 CA 22"),
    ("01 06 20 0E 00 07 A2 0B", None),
    # §2.3 write multiple registers (p.5)
    ("01 10 20 30 00 02 04 04 00 00 00 68 4A", "01 10 20 30 00 02 4A 07"),
    # §3.2 position mode (p.8-10)
    ("01 06 20 0F 00 00 B2 09", None),
    ("01 06 20 0D 00 01 D2 09", None),
    ("01 06 20 8E 00 32 63 F4", None),
    ("01 06 20 8F 00 32 32 34", None),
    ("01 10 20 8A 00 02 04 00 00 50 00 DE 71", "01 10 20 8A 00 02 6B E2"),
    ("01 06 20 0E 00 11 23 C5", None),
    ("01 10 20 8A 00 02 04 FF FF B0 00 97 95", "01 10 20 8A 00 02 6B E2"),
    ("01 10 20 8C 00 02 04 00 00 50 00 5E 5B", "01 10 20 8C 00 02 8B E3"),
    ("01 06 20 0E 00 12 63 C4", None),
    ("01 10 20 8C 00 02 04 FF FF B0 00 17 BF", "01 10 20 8C 00 02 8B E3"),
    ("01 06 20 0F 00 01 73 C9", None),
    ("01 10 20 8A 00 04 08 00 00 50 00 00 00 50 00 E3 2C", "01 10 20 8A 00 04 EB E0"),
    ("01 06 20 0E 00 10 E2 05", None),
    ("01 10 20 8A 00 04 08 FF FF B0 00 FF FF B0 00 FC A3", "01 10 20 8A 00 04 EB E0"),
    # §3.3 torque mode (p.10-11)
    ("01 06 20 0D 00 04 12 0A", None),
    ("01 06 20 86 01 F4 63 F4", None),
    ("01 06 20 87 01 F4 32 34", None),
    ("01 06 20 90 07 D0 81 8B", None),
    ("01 06 20 90 F8 30 C1 F3", None),
    ("01 06 20 91 07 D0 D0 4B", None),
    ("01 06 20 91 F8 30 90 33", None),
    ("01 10 20 90 00 02 04 07 D0 07 D0 60 23", "01 10 20 90 00 02 4A 25"),
    ("01 10 20 90 00 02 04 F8 30 F8 30 11 B9", "01 10 20 90 00 02 4A 25"),
    # §3.4 emergency stop, §3.5 clear fault, §3.6 brake (p.12-13)
    ("01 06 20 0E 00 05 23 CA", None),
    ("01 06 20 0E 00 06 63 CB", None),
    ("01 06 20 1A 00 01 62 0D", None),
]
# §2.1 (p.4): read the actual speed (0x20AB, 2 registers) -> 100 and 100 (0.1 r/min units).
READ_SPEED = ("01 03 20 AB 00 02 BE 2B", "01 03 04 00 64 00 64 BA 07")

FAILURES = 0
# Longest wait for an expected reply: reads return as soon as the reply is in, so a
# generous ceiling costs nothing and keeps the test independent of host load.
REPLY_WAIT = 3.0


def check(cond: bool, what: str) -> None:
    global FAILURES
    print(("ok   " if cond else "FAIL ") + what, flush=True)
    if not cond:
        FAILURES += 1
        raise SystemExit(1)


class Slave:
    def __init__(self, port: str, *extra: str):
        self.p = subprocess.Popen([sys.executable, os.path.join(HERE, "slave.py"), "--port", port, *extra],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        ready = json.loads(self.p.stdout.readline())
        check(ready.get("ready") is True and ready.get("port") == port, f"ready line {ready}")

    def cmd(self, **c) -> dict:
        self.p.stdin.write(json.dumps(c) + "\n")
        self.p.stdin.flush()
        return json.loads(self.p.stdout.readline())


def frame(hex_without_crc: str) -> bytes:
    body = bytes.fromhex(hex_without_crc)
    return body + FramerRTU.compute_CRC(body).to_bytes(2, "big")


def write(client: ModbusSerialClient, address: int, *values: int) -> bool:
    """Write one or more registers (06 / 16); True when the driver acknowledged."""
    if len(values) == 1:
        r = client.write_register(address, values[0] & 0xFFFF, device_id=1)
    else:
        r = client.write_registers(address, [v & 0xFFFF for v in values], device_id=1)
    return not r.isError()


def main() -> None:
    if not shutil.which("socat"):
        sys.exit("socat is missing: apt-get install socat")
    tmp = tempfile.mkdtemp(prefix="zlac-")
    a, b = os.path.join(tmp, "slave"), os.path.join(tmp, "master")
    socat = subprocess.Popen(["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"])
    slave = None
    try:
        for _ in range(100):
            if os.path.exists(a) and os.path.exists(b):
                break
            time.sleep(0.02)
        slave = Slave(a)
        client = ModbusSerialClient(b, baudrate=115200, timeout=REPLY_WAIT, retries=0)
        check(client.connect(), "client connects")
        run(slave, client, client.socket)
        slave.cmd(cmd="quit")
        slave.p.wait(timeout=5)
        slave = Slave(a, "--lag-ms", "100")
        run_lag(slave, client)
        client.close()
        print("selftest passed", flush=True)
    finally:
        if slave:
            if slave.p.poll() is None:
                try:
                    slave.cmd(cmd="quit")
                except (BrokenPipeError, ValueError):
                    pass
                slave.p.wait(timeout=5)
        socat.terminate()
        socat.wait()
        shutil.rmtree(tmp, ignore_errors=True)


def raw(ser, data: bytes, expect: int, wait: float = REPLY_WAIT) -> bytes:
    """Send raw bytes; collect `expect` reply bytes (fewer if `wait` s pass first).

    The input is never flushed: a stray reply byte would show up in the next comparison."""
    ser.write(data)
    return receive(ser, expect=expect, wait=wait)


def receive(ser, expect: int, wait: float = REPLY_WAIT) -> bytes:
    out, deadline = b"", time.monotonic() + wait
    while time.monotonic() < deadline and len(out) < expect:
        ser.timeout = max(0.0, deadline - time.monotonic())
        out += ser.read(expect - len(out))
    return out


def run(slave: Slave, client: ModbusSerialClient, ser) -> None:
    hx = bytes.fromhex
    st = slave.cmd(cmd="state")
    check(st["enabled"] is False and st["mode"] == 0 and st["resolution"] == 1
          and st["max_rpm"] == 1000 and st["offline_ms"] == 1000, "power-on defaults (§4)")

    # -- manual's example frames, byte-exact -------------------------------------------
    for req, rep in MANUAL_FRAMES:
        want = hx(rep or req)
        got = raw(ser, hx(req), expect=len(want))
        check(got == want, f"manual frame {req} -> {got.hex(' ').upper()}")
    slave.cmd(cmd="time", ms=0)
    for req in ("01 06 20 0D 00 03 53 C8", "01 06 20 0E 00 08 E2 0F"):  # velocity mode, enable
        check(raw(ser, hx(req), expect=8) == hx(req), f"manual frame {req}")
    check(write(client, 0x2088, 10, 10), "write 0x2088 = 10, 10")  # 10 r/min both motors
    got = raw(ser, hx(READ_SPEED[0]), expect=9)
    check(got == hx(READ_SPEED[1]), f"manual §2.1 read of actual speed -> {got.hex(' ').upper()}")

    # -- enable sequence ----------------------------------------------------------------
    check(write(client, 0x200E, 0x07), "write 0x200E = 0x07")  # stop
    check(write(client, 0x200D, 0), "write 0x200D = 0")
    check(write(client, 0x200E, 0x08), "write 0x200E = 0x08")
    check(slave.cmd(cmd="state")["enabled"] is False, "enable ignored without a control mode")
    check(write(client, 0x200D, 3), "write 0x200D = 3")
    check(write(client, 0x200E, 0x08), "write 0x200E = 0x08")
    st = slave.cmd(cmd="state")
    check(st["enabled"] is True and st["mode"] == 3, "enabled after mode 3 then 0x08 (§3.1)")
    sw = client.read_holding_registers(0x20A2, count=1, device_id=1).registers[0]
    check(sw == 0x4141, f"status word 0x20A2 shaft lock + running both sides: 0x{sw:04X}")

    # -- speed at resolution 1 and 10 ---------------------------------------------------
    check(write(client, 0x2088, 100, -250), "write 0x2088 = 100, -250")
    st = slave.cmd(cmd="state")
    fb = client.read_holding_registers(0x20AB, count=2, device_id=1).registers
    check(st["left"]["target_rpm"] == 100.0 and st["left"]["actual_rpm"] == 100.0
          and st["right"]["actual_rpm"] == -250.0 and fb == [1000, (-2500) & 0xFFFF],
          f"resolution 1: 100 / -250 r/min -> feedback {fb} (0.1 r/min)")
    check(write(client, 0x2022, 10), "write 0x2022 = 10")
    check(slave.cmd(cmd="get", reg="0x2022")["value"] == 10, "0x2022 set to 10")
    st = slave.cmd(cmd="state")
    check(st["left"]["actual_rpm"] == 10.0, "resolution 10: the same raw 100 is now 10.0 r/min")
    check(write(client, 0x2088, -1234), "write 0x2088 = -1234")
    fb = client.read_holding_registers(0x20AB, count=1, device_id=1).registers[0]
    st = slave.cmd(cmd="state")
    check(st["left"]["target_rpm"] == -123.4 and fb == (-1234) & 0xFFFF,
          f"resolution 10: raw -1234 -> -123.4 r/min, feedback {fb - 65536}")
    r = client.write_register(0x2088, 30001, device_id=1)
    check(r.isError() and r.exception_code == 3, "resolution 10: 3000.1 r/min refused (exception 3)")
    check(write(client, 0x2022, 1), "write 0x2022 = 1")

    # -- 0x2008 maximum motor speed -----------------------------------------------------
    r = client.write_register(0x2008, 1001, device_id=1)
    check(r.isError() and r.exception_code == 3, "0x2008 = 1001 refused with exception 3")
    r = client.write_register(0x2088, 3001, device_id=1)
    check(r.isError() and r.exception_code == 3, "target 3001 r/min refused with exception 3")
    r = client.write_register(0x2088, 2640, device_id=1)
    fb = client.read_holding_registers(0x20AB, count=1, device_id=1).registers[0]
    check(not r.isError() and fb == 10000, f"target 2640 accepted, speed limited to 1000 r/min: {fb}")
    check(write(client, 0x2008, 500), "write 0x2008 = 500")
    fb = client.read_holding_registers(0x20AB, count=1, device_id=1).registers[0]
    check(fb == 5000, f"0x2008 = 500 limits the speed to 500 r/min: {fb}")
    check(write(client, 0x2008, 1000), "write 0x2008 = 1000")

    # -- fault latch and clear ----------------------------------------------------------
    check(write(client, 0x2088, 100), "write 0x2088 = 100")
    slave.cmd(cmd="set", reg="0x20A5", value=0x0800)
    st = slave.cmd(cmd="state")
    check(st["enabled"] is False and st["faults"] == ["encoder error"] and st["left"]["actual_rpm"] == 0,
          "fault 0x0800 (encoder error) stops the motor")
    regs = client.read_holding_registers(0x20A2, count=5, device_id=1).registers
    check(regs[0] & 0xC0 == 0xC0 and regs[3] == 0x0800, f"status word alarm, 0x20A5 = 0x0800: {regs}")
    check(write(client, 0x200E, 0x08), "write 0x200E = 0x08")
    st = slave.cmd(cmd="state")
    check(st["enabled"] is False and st["faults"] == ["encoder error"], "enable refused while faulted")
    clear = hx("01 06 20 0E 00 06 63 CB")  # clear fault (§3.5)
    check(raw(ser, clear, expect=8) == clear, "clear fault frame echoed")
    st = slave.cmd(cmd="state")
    check(st["faults"] == [] and st["enabled"] is False, "clear (0x06) clears the latch, driver disabled")
    check(write(client, 0x200E, 0x08), "write 0x200E = 0x08")
    check(slave.cmd(cmd="state")["enabled"] is True, "enable after clear")

    # -- offline time (0x2000, default 1000 ms) -----------------------------------------
    slave.cmd(cmd="time", ms=10_000)
    check(write(client, 0x200E, 0x08), "write 0x200E = 0x08")  # a frame at t = 10 000
    slave.cmd(cmd="time", ms=11_000)
    check(slave.cmd(cmd="state")["enabled"] is True, "still enabled 1000 ms after the last frame")
    slave.cmd(cmd="time", ms=11_001)
    st = slave.cmd(cmd="state")
    check(st["enabled"] is False and st["offline_stop"] is True and st["left"]["actual_rpm"] == 0,
          "stopped 1001 ms after the last frame")
    check(write(client, 0x200E, 0x08), "write 0x200E = 0x08")
    check(write(client, 0x2000, 0), "write 0x2000 = 0")
    slave.cmd(cmd="time", ms=100_000)
    check(slave.cmd(cmd="state")["enabled"] is True, "offline time 0 never stops")
    check(write(client, 0x2000, 1000), "write 0x2000 = 1000")

    # -- unmapped addresses, read-only, unsupported functions ---------------------------
    for addr, count in ((0x2015, 1), (0x2014, 2), (0x1FFF, 1), (0x20B1, 1), (0x2041, 1)):
        r = client.read_holding_registers(addr, count=count, device_id=1)
        check(r.isError() and r.exception_code == 2, f"read 0x{addr:04X} x{count}: exception 2")
    r = client.write_register(0x20AB, 5, device_id=1)
    check(r.isError() and r.exception_code == 2, "write to read-only 0x20AB: exception 2")
    r = client.read_input_registers(0x20AB, count=1, device_id=1)
    check(r.isError() and r.exception_code == 1, "function 04: exception 1")
    r = client.write_register(0x200E, 0x09, device_id=1)
    check(r.isError() and r.exception_code == 3, "control word 0x09: exception 3")

    # -- forced exceptions --------------------------------------------------------------
    slave.cmd(cmd="exception", function=3, reg="0x20AB", code=4)
    r = client.read_holding_registers(0x20AA, count=3, device_id=1)
    check(r.isError() and r.exception_code == 4, "forced exception 4 on a read covering 0x20AB")
    r = client.read_holding_registers(0x20A5, count=1, device_id=1)
    check(not r.isError(), "other registers unaffected")
    slave.cmd(cmd="clear_exceptions")
    check(not client.read_holding_registers(0x20AB, count=1, device_id=1).isError(), "clear_exceptions")

    # -- framing: bad CRC, other unit, chunks, back to back -----------------------------
    # Silence is shown by order: the slave serves frames in order, so when the first bytes
    # back are the reply to a good frame sent after a bad one, the bad one got no reply.
    good = hx("01 03 20 AB 00 02 BE 2B")
    good_reply = raw(ser, good, expect=9)
    check(len(good_reply) == 9, "reference reply")
    probe = frame("01 03 20 00 00 01")  # offline time: 1000
    probe_reply = frame("01 03 02 03 E8")
    bad = good[:-1] + bytes([good[-1] ^ 0x01])
    check(raw(ser, bad + probe, expect=7) == probe_reply, "no reply to a bad CRC")
    other = frame("02 03 20 AB 00 02")
    check(raw(ser, other + probe, expect=7) == probe_reply, "no reply to another unit id")
    check(raw(ser, bad, expect=0) == b"" and raw(ser, probe, expect=7) == probe_reply,
          "bad CRC alone in a write, then a good frame in the next")
    for part in (good[:1], good[1:5], good[5:]):
        ser.write(part)
        time.sleep(0.03)
    check(receive(ser, expect=9) == good_reply, "request in three chunks answered")
    wr = hx("01 06 20 80 01 F4 83 F5")
    check(raw(ser, wr + good, expect=17) == wr + good_reply, "two requests back to back: two replies")
    check(raw(ser, other + bad + good, expect=9) == good_reply,
          "other unit + bad CRC + good in one write: one reply")
    accel = frame("01 03 20 80 00 01")
    check(raw(ser, frame("00 06 20 80 02 58") + accel, expect=7) == frame("01 03 02 02 58"),
          "broadcast (unit 0) write executed without a reply")
    check(write(client, 0x2000, 1000) and raw(ser, probe, expect=7) == probe_reply, "no stray bytes")

    # -- log ----------------------------------------------------------------------------
    log = slave.cmd(cmd="log")["requests"]
    check(len(log) > 50 and all("t_ms" in e for e in log), f"log holds {len(log)} requests")
    last = log[-1]
    check(last["function"] == 3 and last["address"] == "0x2000" and last["count"] == 1
          and last["reply"] == [1000] and last["exception"] is None and last["t_ms"] == 100_000,
          f"last log entry {last}")
    check(any(e["exception"] == 2 for e in log), "log records exceptions")
    check(any(e["unit"] == 0 and e["values"] == [600] for e in log), "log records the broadcast")
    check(slave.cmd(cmd="log")["requests"] == [], "log is emptied by reading it")


def run_lag(slave: Slave, client: ModbusSerialClient) -> None:
    """--lag-ms 100: the actual speed follows the target with a 100 ms time constant."""
    check(write(client, 0x200D, 3) and write(client, 0x200E, 0x08) and write(client, 0x2088, 100),
          "lag: velocity mode, enable, 100 r/min")
    check(slave.cmd(cmd="state")["left"]["actual_rpm"] == 0.0, "lag: speed 0 at the command")
    slave.cmd(cmd="time", ms=100)
    rpm = slave.cmd(cmd="state")["left"]["actual_rpm"]
    fb = client.read_holding_registers(0x20AB, count=1, device_id=1).registers[0]
    check(abs(rpm - 100 * (1 - math.exp(-1))) < 1e-9 and fb == 632, f"lag: {rpm:.3f} r/min after 100 ms")
    check(write(client, 0x2000, 0), "lag: offline time off for the long wait")
    slave.cmd(cmd="time", ms=2000)
    check(abs(slave.cmd(cmd="state")["left"]["actual_rpm"] - 100) < 1e-6, "lag: settled after 2 s")


if __name__ == "__main__":
    try:
        main()
    except SystemExit as e:
        if e.code:
            print("selftest FAILED", flush=True)
        raise
    except Exception as e:  # a client error (no reply, lost connection) is a failure too
        print(f"FAIL {type(e).__name__}: {e}\nselftest FAILED", flush=True)
        sys.exit(1)
