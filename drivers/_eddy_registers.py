"""Register map of the eddy-current displacement sensor (shared by driver and twin).

Modbus data model: one register space; function codes 03 (read holding) and 04 (read
input) read the same registers, 06 (write single) and 16 (write multiple) write the
read/write ones. Addresses are PDU addresses (0-based, as on the wire); tools that count
from 1 (mbpoll's default reference) use address + 1. Address 0 is unused. 32-bit values
are big-endian: high word first, each word big-endian (Modbus "ABCD").
See docs/decisions/0004.

=====  ====  ===================  ================================  ======  ==============
addr   regs  name                 type / unit                       access  notes
=====  ====  ===================  ================================  ======  ==============
1      2     GAP_MM               float32, mm                       R       gap - zero offset
3      1     GAP_RAW_0P1UM        uint16, 0.1 um                    R       probe-face gap,
                                                                            saturates 65535
4      1     STATUS               bit field (SensorStatus)          R       see below
5      1     TEMPERATURE_0P1C     int16, 0.1 degC                   R       electronics
8      2     RANGE_START_MM       float32, mm                       R       start of range
10     2     RANGE_SPAN_MM        float32, mm                       R       span of range
12     2     ZERO_OFFSET_MM       float32, mm                       R/W     both words, FC16
14     1     TARGET_MATERIAL      uint16 (TargetMaterial 0..3)      R/W
15     1     FILTER               uint16 (0 off, 1 10 Hz, 2 100 Hz, R/W
                                  3 1 kHz, 4 10 kHz)
16     1     COMMAND              uint16: 1 zero here, 2 clear      R/W     reads 0
                                  zero
20     8     MANUFACTURER         ASCII, 16 chars, NUL padded       R
28     8     MODEL                ASCII, 16 chars, NUL padded       R
36     2     SERIAL               uint32                            R
38     1     FIRMWARE             uint16, major*256 + minor         R
=====  ====  ===================  ================================  ======  ==============

STATUS bits: 0 target too far (beyond range), 1 target too close (before range start),
2 probe fault, 3 temperature warning (> 70 degC), 4 zero offset active.

Exceptions: 01 illegal function (other function codes), 02 illegal data address (unused
address, write to a read-only register, half of a 32-bit value), 03 illegal data value
(enumeration out of range, non-finite offset, unknown command).
"""

from __future__ import annotations

import enum
import logging
import struct

log = logging.getLogger(__name__)


class Reg(enum.IntEnum):
    GAP_MM = 1
    GAP_RAW_0P1UM = 3
    STATUS = 4
    TEMPERATURE_0P1C = 5
    RANGE_START_MM = 8
    RANGE_SPAN_MM = 10
    ZERO_OFFSET_MM = 12
    TARGET_MATERIAL = 14
    FILTER = 15
    COMMAND = 16
    MANUFACTURER = 20
    MODEL = 28
    SERIAL = 36
    FIRMWARE = 38


FIRST_ADDRESS = 1
LAST_ADDRESS = 38
STRING_REGS = 8
FILTER_CODES = {0: None, 1: 10.0, 2: 100.0, 3: 1000.0, 4: 10000.0}


class SensorCommand(enum.IntEnum):
    ZERO_HERE = 1
    CLEAR_ZERO = 2


def float_to_regs(value: float) -> list[int]:
    hi, lo = struct.unpack(">HH", struct.pack(">f", value))
    return [hi, lo]


def regs_to_float(regs: list[int]) -> float:
    return struct.unpack(">f", struct.pack(">HH", regs[0] & 0xFFFF, regs[1] & 0xFFFF))[0]


def u32_to_regs(value: int) -> list[int]:
    return [(value >> 16) & 0xFFFF, value & 0xFFFF]


def regs_to_u32(regs: list[int]) -> int:
    return (regs[0] << 16) | regs[1]


def int16_to_reg(value: int) -> int:
    return value & 0xFFFF


def reg_to_int16(reg: int) -> int:
    return reg - 0x10000 if reg & 0x8000 else reg


def string_to_regs(text: str, n_regs: int = STRING_REGS) -> list[int]:
    raw = text.encode("ascii")[: 2 * n_regs].ljust(2 * n_regs, b"\0")
    return list(struct.unpack(f">{n_regs}H", raw))


def regs_to_string(regs: list[int]) -> str:
    return struct.pack(f">{len(regs)}H", *regs).rstrip(b"\0").decode("ascii", errors="replace")
