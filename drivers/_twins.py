"""Start the three instrument twins around one shared plant.

:func:`start_twins` starts the SCPI function generator (TCP), the eddy-current sensor
(Modbus TCP) and the DAQ (CAN FD on an in-process virtual channel, plus a loopback TCP
bridge for other processes) as threads, and returns their addresses. Optional serial
transports (socat pty pairs) are started on request. :func:`run_standalone` is what the
bench CLI calls to serve a simulated rig until interrupted.
"""

from __future__ import annotations

import itertools
import logging
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ._can_transport import CanTcpBridge, open_can_bus
from ._daq_twin import DaqTwin
from ._eddy_twin import EddySensorModel, EddySensorRtuTwin, EddySensorTcpTwin
from ._pty import PtyPair
from ._scpi_twin_model import ScpiGeneratorModel
from ._scpi_twin_server import ScpiSerialServer, ScpiTcpServer

log = logging.getLogger(__name__)

_channel_numbers = itertools.count(1)


@dataclass
class Twins:
    """Running twins and how to reach them. ``close()`` stops everything it started."""

    generator_url: str            # serial_for_url, e.g. socket://127.0.0.1:40123
    generator_visa: str           # TCPIP0::127.0.0.1::40123::SOCKET
    sensor_url: str               # modbus-tcp://127.0.0.1:40124?unit=1
    daq_url: str                  # virtual:<channel> (this process only)
    daq_bridge_url: str           # tcp://127.0.0.1:40125 (any process)
    generator: ScpiGeneratorModel
    sensor: EddySensorModel
    daq: DaqTwin
    scpi_server: ScpiTcpServer
    generator_serial_port: str | None = None   # client end of a pty pair
    sensor_rtu_url: str | None = None          # modbus-rtu:///dev/pts/N?baud=115200&unit=1
    _closers: list[Callable[[], None]] = field(default_factory=list, repr=False)

    def urls(self) -> dict[str, str]:
        out = {"generator": self.generator_url, "generator_visa": self.generator_visa,
               "sensor": self.sensor_url, "daq": self.daq_url, "daq_bridge": self.daq_bridge_url}
        if self.generator_serial_port:
            out["generator_serial"] = self.generator_serial_port
        if self.sensor_rtu_url:
            out["sensor_rtu"] = self.sensor_rtu_url
        return out

    def close(self) -> None:
        for closer in reversed(self._closers):
            try:
                closer()
            except Exception as exc:  # noqa: BLE001 - close everything even if one fails
                log.warning("closing a twin failed: %s", exc)
        self._closers.clear()

    def __enter__(self) -> Twins:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def start_twins(rig: Any, host: str = "127.0.0.1", *, serial_ports: bool = False) -> Twins:
    """Start the three twins on ephemeral ports of ``host`` around the shared ``rig``.

    With ``serial_ports=True`` the generator and the sensor are also served on socat
    pseudo-terminal pairs (SCPI over serial, Modbus RTU at 115200 8N1).
    """
    closers: list[Callable[[], None]] = []
    try:
        generator = ScpiGeneratorModel(rig)
        scpi = ScpiTcpServer(generator, host=host)
        closers.append(scpi.close)

        sensor = EddySensorModel(rig)
        sensor_tcp = EddySensorTcpTwin(sensor, host=host)
        closers.append(sensor_tcp.close)

        channel = f"daq-twin-{os.getpid()}-{next(_channel_numbers)}"
        daq = DaqTwin(rig, open_can_bus(f"virtual:{channel}"))
        closers.append(daq.close)
        bridge = CanTcpBridge(channel, host=host)
        closers.append(bridge.close)

        twins = Twins(generator_url=scpi.url, generator_visa=scpi.visa_resource,
                      sensor_url=sensor_tcp.url, daq_url=f"virtual:{channel}",
                      daq_bridge_url=bridge.url, generator=generator, sensor=sensor, daq=daq,
                      scpi_server=scpi, _closers=closers)
        if serial_ports:
            scpi_pty = PtyPair()
            closers.append(scpi_pty.close)
            scpi_serial = ScpiSerialServer(generator, scpi_pty.twin_port)
            closers.append(scpi_serial.close)
            twins.generator_serial_port = scpi_pty.client_port

            rtu_pty = PtyPair()
            closers.append(rtu_pty.close)
            rtu = EddySensorRtuTwin(EddySensorModel(rig), rtu_pty.twin_port)
            closers.append(rtu.close)
            twins.sensor_rtu_url = f"modbus-rtu://{rtu_pty.client_port}?baud=115200&unit=1"
        return twins
    except BaseException:
        for closer in reversed(closers):
            try:
                closer()
            except Exception:  # noqa: BLE001
                pass
        raise


def run_standalone(rig: Any | None = None, host: str = "127.0.0.1", *,
                   serial_ports: bool = False, print_fn: Callable[[str], None] = print,
                   stop: threading.Event | None = None) -> None:
    """Serve a simulated rig until Ctrl-C (or ``stop`` is set), printing the twins' URLs.

    ``rig`` defaults to ``sim.rig.SimulatedRig()``. Meant for the bench CLI.
    """
    if rig is None:
        from sim.rig import SimulatedRig  # imported late: drivers must not need sim
        rig = SimulatedRig()
    stop = stop or threading.Event()
    with start_twins(rig, host, serial_ports=serial_ports) as twins:
        for name, url in twins.urls().items():
            print_fn(f"{name:17s} {url}")
        try:
            while not stop.wait(0.5):
                pass
        except KeyboardInterrupt:
            print_fn("stopping twins")
