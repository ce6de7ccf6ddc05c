"""Driver of the eddy-current displacement sensor over Modbus TCP or RTU (pymodbus).

URLs: ``modbus-tcp://127.0.0.1:5020?unit=1`` and
``modbus-rtu:///dev/ttyUSB0?baud=115200&unit=1`` (8N1). The register map is documented
in ``drivers/_eddy_registers.py`` and docs/decisions/0004. Live values (gap, status,
temperature) are read with function code 04, configuration with 03; writes use 06/16 and
are confirmed by reading back.
"""

from __future__ import annotations

import logging
import math
import urllib.parse
from typing import Any

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from sim.errors import ConfigurationError

from . import _eddy_registers as regmap
from ._eddy_registers import Reg
from ._errors import ConnectionLost, InstrumentTimeout, ModbusError, ProtocolError
from ._interfaces import GapReading, Identity, SensorStatus, TargetMaterial
from ._urls import check_sensor_url

log = logging.getLogger(__name__)


def _parse_url(url: str) -> tuple[str, dict[str, Any], int]:
    check_sensor_url(url)
    parts = urllib.parse.urlsplit(url)
    query = dict(urllib.parse.parse_qsl(parts.query))
    unit = int(query.get("unit", 1))
    if parts.scheme == "modbus-tcp":
        if parts.hostname is None or parts.port is None:
            raise ConfigurationError(f"{url!r}: expected modbus-tcp://host:port")
        return "tcp", {"host": parts.hostname, "port": parts.port}, unit
    if parts.scheme == "modbus-rtu":
        if not parts.path:
            raise ConfigurationError(f"{url!r}: expected modbus-rtu:///dev/<port>")
        return "rtu", {"port": parts.path, "baudrate": int(query.get("baud", 115200))}, unit
    raise ConfigurationError(f"{url!r}: scheme must be modbus-tcp or modbus-rtu")


class ModbusEddySensor:
    """Eddy-current sensor on Modbus. Satisfies :class:`DisplacementSensor`."""

    def __init__(self, url: str, *, timeout_s: float = 1.0, retries: int = 1) -> None:
        self.url = url
        kind, params, self.unit_id = _parse_url(url)
        self._client: ModbusTcpClient | ModbusSerialClient
        if kind == "tcp":
            self._client = ModbusTcpClient(params["host"], port=params["port"],
                                           timeout=timeout_s, retries=retries)
        else:
            self._client = ModbusSerialClient(params["port"], framer=FramerType.RTU,
                                              baudrate=params["baudrate"], bytesize=8,
                                              parity="N", stopbits=1, timeout=timeout_s,
                                              retries=retries)
        try:
            connected = self._client.connect()
        except (ModbusException, OSError) as exc:
            raise ConnectionLost(f"cannot connect to eddy-current sensor at {url}: {exc}") from exc
        if not connected:
            raise ConnectionLost(f"cannot connect to eddy-current sensor at {url}")
        log.info("eddy-current sensor connected at %s", url)

    # ----------------------------------------------------------------- transport
    def _call(self, what: str, func, *args, **kwargs):
        try:
            response = func(*args, device_id=self.unit_id, **kwargs)
        except ModbusIOException as exc:
            raise InstrumentTimeout(f"{what} on {self.url}: no valid response: {exc}") from exc
        except (ConnectionException, OSError) as exc:      # OSError: a reset the client did not translate
            raise ConnectionLost(f"{what} on {self.url}: connection lost: {exc}") from exc
        except ModbusException as exc:
            raise ModbusError(f"{what} on {self.url}", str(exc)) from exc
        if response.isError():
            code = getattr(response, "exception_code", None)
            raise ModbusError(what, "exception response", int(code) if code is not None else None)
        return response

    def read_registers(self, address: int, count: int, *,
                       input_registers: bool = False) -> list[int]:
        fc = "04" if input_registers else "03"
        func = self._client.read_input_registers if input_registers \
            else self._client.read_holding_registers
        rr = self._call(f"FC{fc} read {count} @ {address}", func, address, count=count)
        if len(rr.registers) != count:
            raise ProtocolError(f"FC{fc} read {count} @ {address}: "
                                f"got {len(rr.registers)} registers")
        return list(rr.registers)

    def write_registers(self, address: int, values: list[int]) -> None:
        if len(values) == 1:
            self._call(f"FC06 write {values[0]} @ {address}", self._client.write_register,
                       address, values[0])
        else:
            self._call(f"FC16 write {values} @ {address}", self._client.write_registers,
                       address, values)

    def _write_confirmed(self, address: int, values: list[int]) -> None:
        self.write_registers(address, values)
        back = self.read_registers(address, len(values))
        if back != values:
            raise ProtocolError(f"write @ {address}: wrote {values}, read back {back}")

    # ----------------------------------------------------------------- readings
    def identify(self) -> Identity:
        regs = self.read_registers(Reg.MANUFACTURER, Reg.FIRMWARE - Reg.MANUFACTURER + 1)
        manufacturer = regmap.regs_to_string(regs[0:8])
        model = regmap.regs_to_string(regs[8:16])
        serial = regmap.regs_to_u32(regs[16:18])
        fw = regs[18]
        return Identity(manufacturer, model, str(serial), f"{fw >> 8}.{fw & 0xFF}")

    def read_gap(self) -> GapReading:
        """Gap (after zero offset), status and temperature from one FC04 request."""
        regs = self.read_registers(Reg.GAP_MM, 5, input_registers=True)
        return GapReading(gap_mm=regmap.regs_to_float(regs[0:2]),
                          status=SensorStatus(regs[Reg.STATUS - Reg.GAP_MM]),
                          temperature_C=regmap.reg_to_int16(regs[Reg.TEMPERATURE_0P1C
                                                                 - Reg.GAP_MM]) / 10.0)

    def read_gap_raw_mm(self) -> float:
        """Probe-face gap from the uint16 register (0.1 um steps), zero offset not applied."""
        return self.read_registers(Reg.GAP_RAW_0P1UM, 1, input_registers=True)[0] * 1e-4

    def status(self) -> SensorStatus:
        return SensorStatus(self.read_registers(Reg.STATUS, 1, input_registers=True)[0])

    def range_mm(self) -> float:
        """Span of the measuring range."""
        return regmap.regs_to_float(self.read_registers(Reg.RANGE_SPAN_MM, 2))

    def range_start_mm(self) -> float:
        return regmap.regs_to_float(self.read_registers(Reg.RANGE_START_MM, 2))

    # ----------------------------------------------------------------- configuration
    def zero_offset_mm(self) -> float:
        return regmap.regs_to_float(self.read_registers(Reg.ZERO_OFFSET_MM, 2))

    def set_zero_offset_mm(self, offset_mm: float) -> None:
        if not math.isfinite(offset_mm):
            raise ValueError(f"zero offset {offset_mm!r} mm must be finite")
        self._write_confirmed(Reg.ZERO_OFFSET_MM, regmap.float_to_regs(offset_mm))

    def zero(self) -> float:
        """Make the present gap the zero; returns the new offset (mm)."""
        self.write_registers(Reg.COMMAND, [regmap.SensorCommand.ZERO_HERE])
        return self.zero_offset_mm()

    def clear_zero(self) -> None:
        self.write_registers(Reg.COMMAND, [regmap.SensorCommand.CLEAR_ZERO])
        if self.zero_offset_mm() != 0.0:
            raise ProtocolError("zero offset not cleared")

    def set_target_material(self, material: TargetMaterial) -> None:
        self._write_confirmed(Reg.TARGET_MATERIAL, [int(TargetMaterial(material))])

    def target_material(self) -> TargetMaterial:
        return TargetMaterial(self.read_registers(Reg.TARGET_MATERIAL, 1)[0])

    def set_filter(self, cutoff_code: int) -> None:
        if cutoff_code not in regmap.FILTER_CODES:
            raise ValueError(f"filter code {cutoff_code!r} not in {sorted(regmap.FILTER_CODES)}")
        self._write_confirmed(Reg.FILTER, [cutoff_code])

    def filter_cutoff_Hz(self) -> float | None:
        return regmap.FILTER_CODES[self.read_registers(Reg.FILTER, 1)[0]]

    def close(self) -> None:
        self._client.close()

    def __enter__(self) -> ModbusEddySensor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
