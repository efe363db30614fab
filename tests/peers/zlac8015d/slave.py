#!/usr/bin/env python3
"""Simulated ZLTECH ZLAC8015D dual BLDC driver: a Modbus RTU slave for conformance tests.

Written from ZLTECH's "ZLAC8015D Servo Driver RS485 Communication Instruction"
Version 1.06 (2023-06-27), called "the manual" below (§ = its chapter, p. = its page).
Modbus framing, CRC, PDU codec and exception replies are pymodbus 3.16.1's own.

Usage:  python3 slave.py --port /dev/pts/N [--unit 1] [--lag-ms 0]
Control channel: JSON lines on stdin, one JSON reply line per command on stdout
(see README.md). The slave never uses wall-clock time for behaviour: only the
virtual clock set with {"cmd":"time","ms":N}.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import math
import sys
import threading
from collections import deque

from pymodbus.constants import ExcCodes
from pymodbus.framer import FramerRTU
from pymodbus.server import ModbusSerialServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import DataType, SimData, SimDevice

# ---------------------------------------------------------------------------
# Register map: (address, name, access, type, default, min, max, source).
# access "RO" registers refuse writes with exception 2 (pymodbus read-only flag).
# min/max are the manual's "Range" (raw register value); None = full 16-bit range.
# Any address not listed here answers exception 2 (illegal data address).
# ---------------------------------------------------------------------------
D = "§4 address dictionary"
REGISTERS = [
    (0x2000, "communication offline time [ms]", "RW", "U16", 1000, 0, 32767, D + " p.13"),
    (0x2001, "RS485 node id", "RW", "U16", 1, 1, 127, D + " p.13"),
    (0x2002, "RS485 baud rate code", "RW", "U16", 2, 1, 6, D + " p.13"),
    (0x2003, "input signal status", "RO", "U16", 0, None, None, D + " p.13"),
    (0x2004, "output signal status", "RO", "U16", 0, None, None, D + " p.13"),
    (0x2005, "clear feedback position", "RW", "U16", 0, 0, 3, D + " p.13"),
    (0x2006, "reset absolute zero point", "RW", "U16", 0, 0, 3, D + " p.13-14"),
    (0x2007, "shaft state after power on", "RW", "U16", 0, 0, 1, D + " p.14"),
    (0x2008, "maximum motor speed [r/min]", "RW", "U16", 1000, 1, 1000, D + " p.14 (changed in V1.05)"),
    (0x2009, "restore factory settings", "RW", "U16", 0, 0, 1, D + " p.14"),
    (0x200A, "CAN node id", "RW", "U16", 1, 1, 127, D + " p.14"),
    (0x200B, "CAN baud rate code", "RW", "U16", 1, 0, 4, D + " p.14"),
    (0x200C, "parking mode", "RW", "U16", 0, 0, 1, D + " p.14 (added in V1.06)"),
    (0x200D, "control mode (3 = velocity)", "RW", "U16", 0, 0, 4, D + " p.14; §3.1 p.6"),
    (0x200E, "control word", "RW", "U16", 0, None, None, D + " p.14; §3.1-3.5 p.6-12"),
    (0x200F, "synchronous/asynchronous control", "RW", "U16", 0, 0, 1, D + " p.14; §3.2 p.7"),
    (0x2010, "store RW registers to EEPROM", "RW", "U16", 0, 0, 1, D + " p.14"),
    (0x2011, "quick stop control", "RW", "U16", 5, 5, 7, D + " p.14-15"),
    (0x2012, "close operation control", "RW", "U16", 1, 0, 1, D + " p.15"),
    (0x2013, "disable control", "RW", "U16", 1, 0, 1, D + " p.15"),
    (0x2014, "halt control", "RW", "U16", 1, 1, 3, D + " p.15"),
    # 0x2015 is not in the manual.
    (0x2016, "input effective level", "RW", "U16", 0, 0, 3, D + " p.15; §3.4 p.11"),
    (0x2017, "input X0 function", "RW", "U16", 9, 0, 9, D + " p.15; §3.4 p.11"),
    (0x2018, "input X1 function", "RW", "U16", 0, 0, 9, D + " p.15; §3.4 p.11"),
    (0x2019, "output effective level", "RW", "U16", 0, 0, 15, D + " p.15; §3.6 p.12"),
    (0x201A, "output B0 (brake) state", "RW", "U16", 0, 0, 1, D + " p.15-16; §3.6 p.12"),
    (0x201B, "output B1 (brake) state", "RW", "U16", 0, 0, 1, D + " p.16; §3.6 p.13"),
    (0x201C, "output Y0 function", "RW", "U16", 0, 0, 3, D + " p.16"),
    (0x201D, "output Y1 function", "RW", "U16", 0, 0, 3, D + " p.16"),
    (0x201E, "driver temperature protection [0.1 C]", "RW", "U16", 800, 0, 1200, D + " p.16"),
    (0x201F, "alarm PWM processing", "RW", "U16", 0, 0, 1, D + " p.16"),
    (0x2020, "overload processing", "RW", "U16", 0, 0, 1, D + " p.16"),
    (0x2021, "I/O emergency stop processing", "RW", "U16", 0, 0, 1, D + " p.16"),
    (0x2022, "given speed resolution (1: 1 r/min, 10: 0.1 r/min)", "RW", "U16", 1, 1, 10, D + " p.16 (added in V1.06)"),
]
# Left motor parameters 0x2030-0x204A and right motor parameters 0x2060-0x207A (§4 p.16-18):
# same layout, offset 0x30; 0x2041/0x2042 and 0x2071/0x2072 are not in the manual.
_MOTOR = [
    (0x00, "encoder lines", "U16", 1024, 0, 4096),
    (0x01, "hall offset angle [deg]", "I16", 0, -360, 360),
    (0x02, "overload factor [%]", "U16", 200, 0, 300),
    (0x03, "rated current [0.1 A]", "U16", 150, 0, 150),
    (0x04, "maximum current [0.1 A]", "U16", 300, 0, 300),
    (0x05, "overload protection time [10 ms]", "U16", 300, 0, 6553),
    (0x06, "position following error threshold [10 counts]", "U16", 409, 1, 6553),
    (0x07, "velocity smoothing factor", "U16", 1000, 0, 30000),
    (0x08, "current loop Kp", "U16", 600, 0, 30000),
    (0x09, "current loop Ki", "U16", 300, 0, 30000),
    (0x0A, "feedforward output smoothing", "U16", 100, 0, 30000),
    (0x0B, "torque output smoothing", "U16", 100, 0, 30000),
    (0x0C, "velocity loop Kp", "U16", 500, 0, 30000),
    (0x0D, "velocity loop Ki", "U16", 100, 0, 30000),
    (0x0E, "velocity loop Kf", "U16", 500, 0, 30000),
    (0x0F, "position loop Kp", "U16", 100, 0, 30000),
    (0x10, "position loop Kf", "U16", None, 0, 30000),  # default differs: left 50, right 1000
    (0x13, "initial velocity, velocity mode [r/min]", "U16", 1, 1, 250),
    (0x14, "initial velocity, position mode [r/min]", "U16", 1, 1, 250),
    (0x15, "motor poles", "U16", 15, 4, 64),
    (0x16, "over temperature threshold [0.1 C]", "U16", 800, 0, 1200),
    (0x17, "velocity observer coefficient 1", "U16", 1000, 0, 30000),
    (0x18, "velocity observer coefficient 2", "U16", 750, 0, 30000),
    (0x19, "velocity observer coefficient 3", "U16", 350, 0, 30000),
    (0x1A, "velocity observer coefficient 4", "U16", 1000, 0, 30000),
]
for _base, _side, _kf, _pages in ((0x2030, "left", 50, "p.16-17"), (0x2060, "right", 1000, "p.17-18")):
    for _off, _name, _typ, _dflt, _lo, _hi in _MOTOR:
        REGISTERS.append((_base + _off, f"{_name} ({_side})", "RW", _typ,
                          _kf if _dflt is None else _dflt, _lo, _hi, f"{D} {_pages}"))
C = "§4 control parameters p.18-19; §3.1-3.3 p.6-10"
REGISTERS += [
    (0x2080, "acceleration time left [ms]", "RW", "U16", 500, 0, 32767, C),
    (0x2081, "acceleration time right [ms]", "RW", "U16", 500, 0, 32767, C),
    (0x2082, "deceleration time left [ms]", "RW", "U16", 500, 0, 32767, C),
    (0x2083, "deceleration time right [ms]", "RW", "U16", 500, 0, 32767, C),
    (0x2084, "quick stop deceleration time left [ms]", "RW", "U16", 10, 0, 32767, C),
    (0x2085, "quick stop deceleration time right [ms]", "RW", "U16", 10, 0, 32767, C),
    (0x2086, "torque slope left [mA/s]", "RW", "U16", 300, None, None, C),
    (0x2087, "torque slope right [mA/s]", "RW", "U16", 300, None, None, C),
    # Range -3000..3000 r/min, in units of 1/resolution r/min (0x2022): checked in Drive.check.
    (0x2088, "target velocity left", "RW", "I16", 0, None, None, C + "; 0x2022 p.16"),
    (0x2089, "target velocity right", "RW", "I16", 0, None, None, C + "; 0x2022 p.16"),
    (0x208A, "target position left, high 16 bits", "RW", "I16", 0, None, None, C),
    (0x208B, "target position left, low 16 bits", "RW", "I16", 0, None, None, C),
    (0x208C, "target position right, high 16 bits", "RW", "I16", 0, None, None, C),
    (0x208D, "target position right, low 16 bits", "RW", "I16", 0, None, None, C),
    (0x208E, "max speed in position mode left [r/min]", "RW", "U16", 120, 1, 1000, C),
    (0x208F, "max speed in position mode right [r/min]", "RW", "U16", 120, 1, 1000, C),
    (0x2090, "target torque left [mA]", "RW", "I16", 0, -30000, 30000, C),
    (0x2091, "target torque right [mA]", "RW", "I16", 0, -30000, 30000, C),
]
R = "§4 read only parameters p.19-21"
REGISTERS += [
    (0x20A0, "software version", "RO", "U16", 0x0106, None, None, R),
    (0x20A1, "bus voltage [0.01 V]", "RO", "U16", 4800, None, None, R),
    (0x20A2, "status word", "RO", "U16", 0, None, None, R + " (computed)"),
    (0x20A3, "hall input state", "RO", "U16", 1, None, None, R),
    (0x20A4, "motor temperature [C], left high byte, right low byte", "RO", "U16", 0x1919, None, None, R),
    (0x20A5, "error code left", "RO", "U16", 0, None, None, R + "; §3.5 p.12"),
    (0x20A6, "error code right", "RO", "U16", 0, None, None, R + "; §3.5 p.12"),
    (0x20A7, "actual position left, high 16 bits", "RO", "I16", 0, None, None, R),
    (0x20A8, "actual position left, low 16 bits", "RO", "I16", 0, None, None, R),
    (0x20A9, "actual position right, high 16 bits", "RO", "I16", 0, None, None, R),
    (0x20AA, "actual position right, low 16 bits", "RO", "I16", 0, None, None, R),
    (0x20AB, "actual velocity left [0.1 r/min]", "RO", "I16", 0, None, None, R + "; §2.1 p.4 (computed)"),
    (0x20AC, "actual velocity right [0.1 r/min]", "RO", "I16", 0, None, None, R + " (computed)"),
    (0x20AD, "actual torque left [0.1 A]", "RO", "I16", 0, None, None, R),
    (0x20AE, "actual torque right [0.1 A]", "RO", "I16", 0, None, None, R),
    (0x20AF, "software connected status", "RO", "U16", 1, None, None, R),
    (0x20B0, "driver temperature [0.1 C]", "RO", "I16", 250, None, None, R),
]
REG = {r[0]: r for r in REGISTERS}

# Fault bits of 0x20A5/0x20A6 (§4 p.20; §3.5 p.12 lists all but 0x0800).
FAULT_BITS = {
    0x0001: "over voltage", 0x0002: "under voltage", 0x0004: "over current",
    0x0008: "over load", 0x0010: "current out of tolerance", 0x0020: "encoder out of tolerance",
    0x0040: "velocity out of tolerance", 0x0080: "reference voltage error",
    0x0100: "EEPROM error", 0x0200: "hall error", 0x0400: "motor over temperature",
    0x0800: "encoder error",
}
# Control word values (0x200E, §4 p.14).
CW_ESTOP, CW_CLEAR, CW_STOP, CW_ENABLE = 0x05, 0x06, 0x07, 0x08
CW_VALUES = {0x00, CW_ESTOP, CW_CLEAR, CW_STOP, CW_ENABLE, 0x10, 0x11, 0x12}
MODE_VELOCITY = 3
SIDES = (("left", 0x2088, 0x20AB, 0x20A5), ("right", 0x2089, 0x20AC, 0x20A6))


def s16(v: int) -> int:
    return v - 0x10000 if v & 0x8000 else v


class Drive:
    """The driver's behaviour, in virtual time."""

    def __init__(self, lag_ms: float):
        self.regs = {a: (r[4] & 0xFFFF) for a, r in REG.items()}
        self.lag_ms = lag_ms
        self.now = 0  # virtual ms
        self.last_frame = 0
        self.enabled = False
        self.estop = False
        self.offline_stop = False
        self.actual = {"left": 0.0, "right": 0.0}  # r/min
        self.forced: list[tuple[int, int, int]] = []  # (function, register, code)
        self.log: list[dict] = []
        self.update(0)

    # -- derived quantities ------------------------------------------------
    def resolution(self) -> int:
        return max(1, self.regs[0x2022])  # a harness "set" of 0 must not divide by zero

    def target_rpm(self, reg: int) -> float:
        return s16(self.regs[reg]) / self.resolution()

    def faults(self) -> int:
        return self.regs[0x20A5] | self.regs[0x20A6]

    def update(self, dt_ms: float) -> None:
        """Move the actual speeds towards the demand; recompute feedback registers."""
        vmax = self.regs[0x2008]
        running = self.enabled and self.regs[0x200D] == MODE_VELOCITY
        status = 0
        for i, (side, target, feedback, fault) in enumerate(SIDES):
            demand = max(-vmax, min(vmax, self.target_rpm(target))) if running else 0.0
            if self.lag_ms <= 0:
                self.actual[side] = demand
            else:
                self.actual[side] = demand + (self.actual[side] - demand) * math.exp(-dt_ms / self.lag_ms)
            self.regs[feedback] = max(-32768, min(32767, round(self.actual[side] * 10))) & 0xFFFF
            # 0x20A2 (§4 p.19): bits 7,6 (right 15,14): 00 release, 01 lock, 10 e-stop, 11 alarm;
            # bit 0 (right bit 8): running.
            state = 0xC0 if self.regs[fault] else 0x80 if self.estop else 0x40 if self.enabled else 0
            state |= 1 if self.regs[feedback] else 0
            status |= state << (8 * i)
        self.regs[0x20A2] = status

    def advance(self, ms: int) -> None:
        dt = ms - self.now
        self.now = ms
        self.check_offline()
        self.update(dt)

    def check_offline(self) -> None:
        """0x2000: stop when no frame arrived for more than the offline time (0 = off)."""
        limit = self.regs[0x2000]
        if limit and self.enabled and self.now - self.last_frame > limit:
            self.enabled = False
            self.offline_stop = True

    def frame_arrived(self) -> None:
        self.check_offline()
        self.last_frame = self.now

    # -- writes ------------------------------------------------------------
    def check(self, address: int, value: int) -> ExcCodes | None:
        """Value check of a Modbus write (address and access were checked by pymodbus)."""
        _, _, _, typ, _, lo, hi, _ = REG[address]
        v = s16(value) if typ == "I16" else value
        if address == 0x200E and value not in CW_VALUES:
            return ExcCodes.ILLEGAL_VALUE
        if address in (0x2088, 0x2089) and abs(v) > 3000 * self.resolution():
            return ExcCodes.ILLEGAL_VALUE  # -3000..3000 r/min (§3.1 p.6)
        if lo is not None and not lo <= v <= hi:
            return ExcCodes.ILLEGAL_VALUE
        return None

    def write(self, address: int, value: int) -> None:
        """Apply one register value with its side effects (Modbus write or harness set)."""
        value &= 0xFFFF
        self.regs[address] = value
        if address == 0x200E:
            self.control_word(value)
        elif address in (0x20A5, 0x20A6) and value:
            self.enabled = False  # a fault stops the driver; it stays latched until 0x06
        self.update(0)

    def control_word(self, cw: int) -> None:
        if cw == CW_ESTOP:
            self.enabled, self.estop = False, True
        elif cw == CW_STOP:
            self.enabled = False
        elif cw == CW_CLEAR:
            if self.faults():
                self.regs[0x20A5] = self.regs[0x20A6] = 0
                self.enabled = False
            self.estop = False
        elif cw == CW_ENABLE:
            # Enabled only with no latched fault and a defined control mode (§3.1: mode, then enable).
            if not self.faults() and self.regs[0x200D] != 0:
                self.enabled, self.estop, self.offline_stop = True, False, False

    def forced_exception(self, function: int, address: int, count: int) -> ExcCodes | None:
        for fc, reg, code in self.forced:
            if fc == function and address <= reg < address + count:
                return ExcCodes(code)
        return None

    def state(self) -> dict:
        sides = {}
        for side, target, _, fault in SIDES:
            word = self.regs[fault]
            sides[side] = {
                "target_rpm": self.target_rpm(target),
                "actual_rpm": self.actual[side],
                "fault_word": word,
                "faults": [n for b, n in FAULT_BITS.items() if word & b],
            }
        return {
            "ok": True, "t_ms": self.now, "enabled": self.enabled, "mode": self.regs[0x200D],
            "estop": self.estop, "offline_stop": self.offline_stop,
            "resolution": self.resolution(), "max_rpm": self.regs[0x2008],
            "offline_ms": self.regs[0x2000], "status_word": self.regs[0x20A2],
            "faults": sorted(set(sides["left"]["faults"] + sides["right"]["faults"])),
            **sides,
        }


# ---------------------------------------------------------------------------
# pymodbus glue
# ---------------------------------------------------------------------------
class Framer(FramerRTU):
    """pymodbus's RTU framer, consuming one frame at a time.

    pymodbus 3.16.1's FramerRTU.decode returns the whole buffer as used, so a second
    request that arrives in the same read is dropped. This is the same hunt (function
    code lookup, frame size and CRC check, all pymodbus's) returning the end of the
    frame instead; a frame with a bad CRC is dropped without reply.
    """

    def decode(self, data: bytes) -> tuple[int, int, int, bytes]:
        for start in range(len(data)):
            if len(data) - start < self.MIN_SIZE:
                return 0, 0, 0, self.EMPTY
            if not (pdu_class := self.decoder.lookupPduClass(data[start:])):
                continue
            if not (size := pdu_class.calculateRtuFrameSize(data[start:])):
                return 0, 0, 0, self.EMPTY
            end = start + size
            if len(data) < end:
                return 0, 0, 0, self.EMPTY
            if not self.check_CRC(data[start : end - 2], int.from_bytes(data[end - 2 : end], "big")):
                return end, 0, 0, self.EMPTY
            return end, data[start], 0, data[start + 1 : end - 2]
        return 0, 0, 0, self.EMPTY


class Handler(ServerRequestHandler):
    """pymodbus's request handler, serving every complete frame in the buffer, in order."""

    def __init__(self, *args):
        super().__init__(*args)
        self.pending: deque = deque()
        self.worker: asyncio.Future | None = None

    def callback_data(self, data: bytes, addr: tuple | None = None) -> int:
        used = 0
        while used < len(data):
            n = super().callback_data(data[used:], addr)
            if not n:
                break
            used += n
            if self.last_pdu is not None:
                self.pending.append((self.last_pdu, self.last_addr))
        return used

    def handle_later(self) -> None:
        if self.worker is None or self.worker.done():
            self.worker = asyncio.ensure_future(self.drain())

    async def drain(self) -> None:
        while self.pending:
            self.last_pdu, self.last_addr = self.pending.popleft()
            await self.handle_request()


class Server(ModbusSerialServer):
    def callback_new_connection(self):
        return Handler(self, self.trace_packet, self.trace_pdu, self.trace_connect)


class Peer:
    def __init__(self, args):
        self.unit = args.unit
        self.drive = Drive(args.lag_ms)
        self.open: deque = deque()  # log entries waiting for their reply
        blocks, start = [], None
        for a in sorted(REG):  # contiguous runs of mapped registers; gaps stay invalid
            if start is None or a != prev + 1:
                if start is not None:
                    blocks.append((start, prev))
                start = a
            prev = a
        blocks.append((start, prev))
        simdata = []
        for lo, hi in blocks:
            for a in range(lo, hi + 1):
                simdata.append(SimData(a, values=self.drive.regs[a], datatype=DataType.REGISTERS,
                                       readonly=REG[a][2] == "RO"))
        device = SimDevice(id=self.unit, simdata=simdata, action=self.action)
        self.server = Server(device, port=args.port, baudrate=args.baud, trace_pdu=self.trace,
                             broadcast_enable=True)
        self.server.framer = Framer

    async def action(self, fc, start, address, count, registers, values):
        d = self.drive
        if fc not in (3, 6, 16):
            return ExcCodes.ILLEGAL_FUNCTION  # the manual lists 0x03, 0x06, 0x10 only (§2 p.3)
        if values is not None:
            if exc := d.forced_exception(fc, address, len(values)):
                return exc
            for i, v in enumerate(values):
                if exc := d.check(address + i, v):
                    return exc
            for i, v in enumerate(values):
                d.write(address + i, v)
        elif fc == 3 and (exc := d.forced_exception(fc, address, count)):
            return exc
        for a in range(address, address + count):  # refresh what pymodbus replies with
            registers[a - start] = d.regs[a]
        return None

    def trace(self, sending: bool, pdu):
        d = self.drive
        if not sending:
            if pdu.dev_id not in (self.unit, 0):
                return None  # another unit's request: no reply, as on a shared bus
            d.frame_arrived()
            regs = list(getattr(pdu, "registers", []) or [])
            entry = {"t_ms": d.now, "unit": pdu.dev_id, "function": pdu.function_code,
                     "address": f"0x{pdu.address:04X}",
                     "count": pdu.count if pdu.function_code != 6 else 1,
                     "values": regs or None, "exception": None, "reply": None}
            d.log.append(entry)
            if pdu.dev_id:
                self.open.append(entry)
            return pdu
        if self.open:
            entry = self.open.popleft()
            if pdu.function_code & 0x80:
                entry["exception"] = pdu.exception_code
            else:
                entry["reply"] = list(getattr(pdu, "registers", []) or []) or None
        return pdu

    def command(self, c: dict) -> dict:
        d = self.drive
        cmd = c.get("cmd")
        if cmd == "time":
            ms = int(c["ms"])
            if ms < d.now:
                return {"ok": False, "error": f"time goes forward only (now {d.now})"}
            d.advance(ms)
            return {"ok": True, "t_ms": d.now}
        if cmd in ("get", "set"):
            reg = c["reg"]
            a = int(reg, 0) if isinstance(reg, str) else int(reg)
            if a not in REG:
                return {"ok": False, "error": f"0x{a:04X} is not in the register map"}
            if cmd == "set":
                d.write(a, int(c["value"]))
            out = {"ok": True, "reg": f"0x{a:04X}", "value": d.regs[a]}
            if REG[a][3] == "I16":
                out["signed"] = s16(d.regs[a])
            return out
        if cmd == "exception":
            reg = c["reg"]
            a = int(reg, 0) if isinstance(reg, str) else int(reg)
            d.forced.append((int(c["function"]), a, ExcCodes(int(c["code"])).value))
            return {"ok": True}
        if cmd == "clear_exceptions":
            d.forced.clear()
            return {"ok": True}
        if cmd == "log":
            out, d.log = d.log, []
            return {"ok": True, "requests": out}
        if cmd == "state":
            return d.state()
        return {"ok": False, "error": f"unknown command {cmd!r}"}


def emit(obj: dict) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


async def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--port", required=True, help="serial device, e.g. one end of a socat pty pair")
    ap.add_argument("--unit", type=int, default=1, help="Modbus unit id (default 1, as the driver)")
    ap.add_argument("--baud", type=int, default=115200, help="passed to the serial port (a pty ignores it)")
    ap.add_argument("--lag-ms", type=float, default=0.0,
                    help="first-order lag time constant of the actual speed, virtual ms (0 = instant)")
    args = ap.parse_args()
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    peer = Peer(args)
    await peer.server.serve_forever(background=True)
    loop = asyncio.get_running_loop()
    lines: asyncio.Queue = asyncio.Queue()

    def read_stdin():
        for line in sys.stdin:
            loop.call_soon_threadsafe(lines.put_nowait, line)
        loop.call_soon_threadsafe(lines.put_nowait, None)

    threading.Thread(target=read_stdin, daemon=True).start()
    emit({"ready": True, "port": args.port, "unit": args.unit})
    while (line := await lines.get()) is not None:
        if not line.strip():
            continue
        try:
            c = json.loads(line)
            if c.get("cmd") == "quit":
                break
            reply = peer.command(c)
        except Exception as e:  # a bad command never stops the slave
            reply = {"ok": False, "error": f"{type(e).__name__}: {e}"}
        emit(reply)
    await peer.server.shutdown()
    emit({"ok": True, "bye": True})


if __name__ == "__main__":
    asyncio.run(main())
