"""Fuzzing the eddy-current sensor twin (Modbus TCP, pymodbus server on loopback).

Random bytes, random PDUs in well-formed MBAP frames, and random register reads and
writes go to the real server; every request gets a normal or an exception response (or,
for garbage, a closed connection) within a time bound, the register invariants hold
(a zero offset is finite and in range, material and filter codes are valid), and a
well-formed read by the driver on a new connection still works afterwards.
"""

from __future__ import annotations

import math
import socket
import struct
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers import ModbusEddySensor, TargetMaterial
from drivers._eddy_registers import FILTER_CODES, LAST_ADDRESS, Reg
from drivers._eddy_twin import EddySensorModel, EddySensorTcpTwin
from sim.rig import SimulatedRig

from ._settings import TIME_BOUND_S, fuzz


@pytest.fixture(scope="module")
def twin():
    t = EddySensorTcpTwin(EddySensorModel(SimulatedRig()))
    yield t
    t.close()


@pytest.fixture(scope="module")
def sensor(twin):
    s = ModbusEddySensor(twin.url, timeout_s=1.0)
    yield s
    s.close()


def _exchange(twin, frame: bytes, expect_reply: bool) -> bytes | None:
    with socket.create_connection((twin.host, twin.port), timeout=0.3 if not expect_reply else TIME_BOUND_S) as s:
        s.sendall(frame)
        try:
            return s.recv(1024)
        except TimeoutError:
            if expect_reply:
                raise AssertionError(f"no reply to {frame.hex()} within {TIME_BOUND_S} s") from None
            return None


def _mbap(tid: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def _still_serves(sensor: ModbusEddySensor) -> None:
    reading = sensor.read_gap()
    assert math.isfinite(reading.gap_mm)
    offset = sensor.zero_offset_mm()
    assert math.isfinite(offset) and abs(offset) <= sensor.range_start_mm() + sensor.range_mm()
    assert sensor.target_material() in set(TargetMaterial)
    filt = sensor.read_registers(Reg.FILTER, 1)[0]
    assert filt in FILTER_CODES


@given(st.one_of(st.binary(max_size=300),
                 st.builds(_mbap, st.integers(0, 0xFFFF), st.integers(0, 255), st.binary(max_size=260))))
@fuzz(40)
def test_random_bytes_and_pdus_leave_the_twin_serving(twin, sensor, frame):
    t = time.monotonic()
    _exchange(twin, frame, expect_reply=False)
    assert time.monotonic() - t < TIME_BOUND_S
    _still_serves(sensor)


requests = st.one_of(
    st.tuples(st.sampled_from([3, 4]), st.integers(0, LAST_ADDRESS + 3), st.integers(0, 130)).map(
        lambda r: struct.pack(">BHH", *r)),
    st.tuples(st.integers(0, LAST_ADDRESS + 3), st.integers(0, 0xFFFF)).map(
        lambda r: struct.pack(">BHH", 6, *r)),
    st.tuples(st.integers(0, LAST_ADDRESS + 3), st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=8)).map(
        lambda r: struct.pack(">BHHB", 16, r[0], len(r[1]), 2 * len(r[1])) + struct.pack(f">{len(r[1])}H", *r[1])),
)


@given(st.lists(requests, min_size=1, max_size=5))
@fuzz(40)
def test_random_register_reads_and_writes_get_a_response_and_keep_the_invariants(twin, sensor, pdus):
    try:
        for tid, pdu in enumerate(pdus):
            reply = _exchange(twin, _mbap(tid, 1, pdu), expect_reply=True)
            assert len(reply) >= 9, reply
            tid_r, proto, length, unit = struct.unpack(">HHHB", reply[:7])
            assert (tid_r, proto, unit) == (tid, 0, 1) and length == len(reply) - 6
            fc = reply[7]
            # a PDU pymodbus cannot decode (a count outside 1-125) is answered with function
            # code 0x80 and exception 1, not fc | 0x80 with exception 3 as the standard
            # says (pymodbus 3.x server; our driver never sends such counts): an exception
            # response either way
            assert fc == pdu[0] or fc in (pdu[0] | 0x80, 0x80), reply.hex()
            if fc & 0x80:
                assert reply[8] in (1, 2, 3, 4), f"exception code {reply[8]}"
        _still_serves(sensor)
    finally:       # back to the defaults for the next example
        sensor.clear_zero()
        sensor.set_target_material(TargetMaterial.STEEL)
        sensor.set_filter(0)
