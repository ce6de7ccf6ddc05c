"""Simulated eddy-current sensor: a pymodbus server (TCP or RTU) over the register map.

The live registers (gap, status, temperature) are refreshed from the plant
(``rig.gap_m()`` under ``rig.lock``) on every read; writes are validated and malformed
requests get Modbus exception responses. Targets pymodbus 3.16's SimDevice API
(docs/decisions/0004). The server runs in its own thread with its own event loop.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
from typing import Any

from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from . import _eddy_registers as regmap
from ._eddy_registers import Reg
from ._interfaces import SensorStatus, TargetMaterial

log = logging.getLogger(__name__)

READ_CODES = (3, 4)
MAX_CLIENTS = 16          # TCP clients at once (one more is accepted and closed), as the SCPI twin
CLIENT_IDLE_S = 300.0     # a client silent this long is dropped (the bench asks before every sweep)
WRITE_CODES = (6, 16)
TEMPERATURE_WARNING_C = 70.0


class EddySensorModel:
    """The sensor's physics and register semantics, independent of the transport."""

    def __init__(self, rig: Any, *, unit_id: int = 1, range_start_mm: float = 0.1,
                 range_span_mm: float = 2.0, serial: int = 4711,
                 model: str = "ECS-2000-TWIN", manufacturer: str = "guideway-bench") -> None:
        self._rig = rig
        self.unit_id = unit_id
        self.range_start_mm = range_start_mm
        self.range_span_mm = range_span_mm
        self.temperature_C = 23.5
        self.probe_fault = False
        self.requests = 0
        ident = (regmap.string_to_regs(manufacturer) + regmap.string_to_regs(model)
                 + regmap.u32_to_regs(serial) + [0x0102])
        self.device = SimDevice(
            id=unit_id,
            simdata=[
                SimData(Reg.GAP_MM, count=5, values=0, datatype=DataType.REGISTERS,
                        readonly=True),
                SimData(Reg.RANGE_START_MM, values=regmap.float_to_regs(range_start_mm)
                        + regmap.float_to_regs(range_span_mm), datatype=DataType.REGISTERS,
                        readonly=True),
                SimData(Reg.ZERO_OFFSET_MM, values=regmap.float_to_regs(0.0)
                        + [int(TargetMaterial.STEEL), 0, 0], datatype=DataType.REGISTERS),
                SimData(Reg.MANUFACTURER, values=ident, datatype=DataType.REGISTERS,
                        readonly=True),
            ],
            action=self._action,
        )

    def raw_gap_mm(self) -> float:
        with self._rig.lock:
            return self._rig.gap_m() * 1e3

    async def _action(self, function_code: int, start_address: int, address: int, count: int,
                      registers: list[int], set_values: list[int] | list[bool] | None
                      ) -> ExcCodes | None:
        self.requests += 1

        def at(reg: int) -> int:
            return reg - start_address

        if set_values is None:
            if function_code in READ_CODES:
                self._refresh(registers, at)
            return None
        if function_code not in WRITE_CODES:
            return ExcCodes.ILLEGAL_FUNCTION
        return self._validate_write(address, set_values, registers, at)

    def _refresh(self, registers: list[int], at) -> None:
        raw = self.raw_gap_mm()
        offset = regmap.regs_to_float(registers[at(Reg.ZERO_OFFSET_MM):at(Reg.ZERO_OFFSET_MM) + 2])
        end = self.range_start_mm + self.range_span_mm
        status = SensorStatus.OK
        if raw > end:
            status |= SensorStatus.TARGET_TOO_FAR
        if raw < self.range_start_mm:
            status |= SensorStatus.TARGET_TOO_CLOSE
        if self.probe_fault:
            status |= SensorStatus.PROBE_FAULT
        if self.temperature_C > TEMPERATURE_WARNING_C:
            status |= SensorStatus.TEMPERATURE_WARNING
        if offset != 0.0:
            status |= SensorStatus.ZERO_ACTIVE
        clamped = min(max(raw, self.range_start_mm), end)  # the electronics saturate
        registers[at(Reg.GAP_MM):at(Reg.GAP_MM) + 2] = regmap.float_to_regs(clamped - offset)
        registers[at(Reg.GAP_RAW_0P1UM)] = int(min(max(round(clamped * 1e4), 0), 0xFFFF))
        registers[at(Reg.STATUS)] = int(status)
        registers[at(Reg.TEMPERATURE_0P1C)] = regmap.int16_to_reg(round(self.temperature_C * 10))

    def _validate_write(self, address: int, values: list[int], registers: list[int], at
                        ) -> ExcCodes | None:
        """Check a write; ``values`` is edited in place (pymodbus stores it afterwards)."""
        written = dict(zip(range(address, address + len(values)), values))
        off = Reg.ZERO_OFFSET_MM
        if (off in written) != (off + 1 in written):
            return ExcCodes.ILLEGAL_ADDRESS  # half of a float32
        if off in written:
            offset = regmap.regs_to_float([written[off], written[off + 1]])
            if not math.isfinite(offset) or abs(offset) > self.range_start_mm + self.range_span_mm:
                return ExcCodes.ILLEGAL_VALUE
        if Reg.TARGET_MATERIAL in written and \
                written[Reg.TARGET_MATERIAL] not in TargetMaterial._value2member_map_:
            return ExcCodes.ILLEGAL_VALUE
        if Reg.FILTER in written and written[Reg.FILTER] not in regmap.FILTER_CODES:
            return ExcCodes.ILLEGAL_VALUE
        if Reg.COMMAND in written:
            command = written[Reg.COMMAND]
            if command == regmap.SensorCommand.ZERO_HERE:
                new_offset = regmap.float_to_regs(self.raw_gap_mm())
            elif command == regmap.SensorCommand.CLEAR_ZERO:
                new_offset = regmap.float_to_regs(0.0)
            else:
                return ExcCodes.ILLEGAL_VALUE
            registers[at(off):at(off) + 2] = new_offset
            for i, reg in enumerate(range(address, address + len(values))):
                if reg in (off, off + 1):
                    values[i] = new_offset[reg - off]
            values[Reg.COMMAND - address] = 0  # the command register reads back 0
        return None


class _ServerThread:
    """Runs one pymodbus server in a private event loop on a daemon thread."""

    def __init__(self, make_server, name: str) -> None:
        self._make_server = make_server
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.server = None
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()
        if not self._ready.wait(10.0):
            raise RuntimeError(f"{name}: Modbus server did not start")
        if self._error is not None:
            raise RuntimeError(f"{name}: Modbus server failed to start: {self._error}")

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        try:
            self.loop.run_until_complete(self._start())
        except BaseException as exc:  # noqa: BLE001 - reported to the starting thread
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        self.loop.run_forever()

    async def _start(self) -> None:
        self.server = self._make_server()
        await self.server.serve_forever(background=True)

    def close(self) -> None:
        if self.server is not None and self.loop.is_running():
            fut = asyncio.run_coroutine_threadsafe(self.server.shutdown(), self.loop)
            try:
                fut.result(timeout=5.0)
            except Exception as exc:  # noqa: BLE001
                log.warning("Modbus server shutdown: %s", exc)
        if self.loop.is_running():
            self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(timeout=5.0)


class _CappedTcpServer(ModbusTcpServer):
    """pymodbus's TCP server with the bounds of the other twins (docs/decisions/0028,
    0041): at most ``max_clients`` connections (one more is accepted and closed at once),
    each dropped after ``idle_s`` without a request."""

    def __init__(self, *args, max_clients: int, idle_s: float, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.max_clients, self.idle_s = max_clients, idle_s
        self._last_heard: dict[str, float] = {}
        self._sweeper: asyncio.Task | None = None

    def callback_new_connection(self):
        handler = super().callback_new_connection()
        loop = asyncio.get_running_loop()
        full = len(self.active_connections) >= self.max_clients
        made, received = handler.connection_made, handler.data_received

        def connection_made(transport) -> None:
            if full:
                log.warning("Modbus twin: %d clients already; refused %s", self.max_clients,
                            transport.get_extra_info("peername"))
                self.active_connections.pop(handler.unique_id, None)
                transport.close()
                return
            self._last_heard[handler.unique_id] = loop.time()
            made(transport)
            if self._sweeper is None:
                self._sweeper = loop.create_task(self._drop_silent())

        def data_received(data: bytes) -> None:
            self._last_heard[handler.unique_id] = loop.time()
            received(data)
        handler.connection_made = connection_made
        handler.data_received = data_received
        return handler

    async def _drop_silent(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(min(1.0, self.idle_s / 4))
            for uid, conn in list(self.active_connections.items()):
                if loop.time() - self._last_heard.get(uid, loop.time()) > self.idle_s:
                    log.debug("Modbus twin: dropped a client silent for %.0f s", self.idle_s)
                    conn.close()
                    self.active_connections.pop(uid, None)
            for uid in set(self._last_heard) - set(self.active_connections):
                del self._last_heard[uid]

    async def shutdown(self):
        if self._sweeper is not None:
            self._sweeper.cancel()
        await super().shutdown()


class EddySensorTcpTwin:
    """The sensor twin on Modbus TCP (127.0.0.1, ephemeral port by default)."""

    def __init__(self, model: EddySensorModel, host: str = "127.0.0.1", port: int = 0, *,
                 max_clients: int = MAX_CLIENTS, idle_s: float = CLIENT_IDLE_S) -> None:
        self.model = model
        self._thread = _ServerThread(
            lambda: _CappedTcpServer(model.device, address=(host, port), max_clients=max_clients, idle_s=idle_s),
            "eddy-twin-tcp")
        self.host, self.port = self._thread.server.transport.sockets[0].getsockname()[:2]
        log.info("eddy-current sensor twin on %s", self.url)

    @property
    def url(self) -> str:
        return f"modbus-tcp://{self.host}:{self.port}?unit={self.model.unit_id}"

    def close(self) -> None:
        self._thread.close()


class EddySensorRtuTwin:
    """The sensor twin on Modbus RTU over a serial port (a socat pty in tests)."""

    def __init__(self, model: EddySensorModel, port: str, baudrate: int = 115200) -> None:
        self.model = model
        self.port = port
        self.baudrate = baudrate
        self._thread = _ServerThread(
            lambda: ModbusSerialServer(model.device, framer=FramerType.RTU, port=port,
                                       baudrate=baudrate, bytesize=8, parity="N", stopbits=1),
            "eddy-twin-rtu")
        log.info("eddy-current sensor twin (RTU) on %s", port)

    def close(self) -> None:
        self._thread.close()
