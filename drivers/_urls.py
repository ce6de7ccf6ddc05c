"""Which instrument URLs the drivers open: a short allow-list per instrument.

A rig file or a stored ``run.json`` names the instruments by URL, and pyserial's
``serial_for_url`` (behind the generator, the Modbus RTU sensor and python-can's serial
adapters) opens far more than instruments: ``spy://PORT?file=PATH`` truncates PATH,
``hwgrep://`` opens whatever port matches, ``alt://`` picks a backend class.  So every URL
is checked here, before anything is opened, against the schemes this bench uses; anything
else raises :class:`ConfigurationError` (a ValueError) naming the URL and the allowed forms
(the configuration adds the key: ``[rig.instruments] generator``).  See
docs/decisions/0028-hardening.md.
"""

from __future__ import annotations

import urllib.parse

from sim.errors import ConfigurationError

from ._visa_transport import is_visa_resource

# Generator: a serial device path (no scheme), a raw SCPI socket, pyserial's loopback (the
# driver tests use it), or a VISA resource string opened through pyvisa-py
# (drivers/_visa_transport.py; an ASRL resource's port must be a device path too).
GENERATOR_SCHEMES = ("socket", "loop")
GENERATOR_FORMS = ("/dev/<serial port> (or COM<n>)", "socket://host:port", "loop://",
                   "a VISA resource (TCPIP0::host::5025::SOCKET, TCPIP0::host::inst0::INSTR, "
                   "USB0::...::INSTR, ASRL/dev/<port>::INSTR, GPIB0::<n>::INSTR)")

SENSOR_SCHEMES = ("modbus-tcp", "modbus-rtu")
SENSOR_FORMS = ("modbus-tcp://host:port?unit=N", "modbus-rtu:///dev/<port>?baud=B&unit=N")

# DAQ: python-can interfaces by name.  Those in CAN_SERIAL_INTERFACES hand their channel to
# serial_for_url, so their channel must be a plain device path.
CAN_INTERFACES = ("socketcan", "socketcand", "pcan", "kvaser", "vector", "ixxat", "nican", "nixnet",
                  "neovi", "etas", "gs_usb", "systec", "usb2can", "canalystii", "cantact",
                  "slcan", "serial", "robotell", "seeedstudio")
CAN_SERIAL_INTERFACES = ("slcan", "serial", "robotell", "seeedstudio")
DAQ_FORMS = ("virtual:<channel>", "tcp://host:port", "<interface>:<channel> with interface one of "
             + ", ".join(CAN_INTERFACES))


def _refuse(url: str, what: str, forms) -> ConfigurationError:
    return ConfigurationError(f"{url!r} is not an allowed {what} URL; allowed: {', '.join(forms)}")


def _is_device_path(path: str) -> bool:
    """A serial port named by its path, which serial_for_url opens as a plain port."""
    return bool(path) and "://" not in path and "?" not in path and not path.startswith("-")


def check_generator_url(url: str) -> str:
    if not isinstance(url, str):
        raise _refuse(repr(url), "function generator", GENERATOR_FORMS)
    if is_visa_resource(url):
        board = url.strip()[4:-len("::INSTR")] if url.strip().upper().startswith("ASRL") else None
        if board is not None and not _is_device_path(board):
            raise ConfigurationError(f"{url!r}: an ASRL resource names a serial port (ASRL/dev/<port>::INSTR)")
        return url
    if "://" not in url:
        if _is_device_path(url):
            return url
        raise _refuse(url, "function generator", GENERATOR_FORMS)
    scheme = url.split("://", 1)[0].lower()
    if scheme not in GENERATOR_SCHEMES:
        raise _refuse(url, "function generator", GENERATOR_FORMS)
    if scheme == "socket":
        parts = urllib.parse.urlsplit(url)
        if parts.hostname is None or parts.port is None:
            raise ConfigurationError(f"{url!r}: expected socket://host:port")
    return url


def check_sensor_url(url: str) -> str:
    parts = urllib.parse.urlsplit(url) if isinstance(url, str) else None
    if parts is None or parts.scheme not in SENSOR_SCHEMES:
        raise _refuse(url, "displacement sensor", SENSOR_FORMS)
    if parts.scheme == "modbus-tcp" and (parts.hostname is None or parts.port is None or parts.path not in ("", "/")):
        raise ConfigurationError(f"{url!r}: expected modbus-tcp://host:port")
    if parts.scheme == "modbus-rtu" and (parts.netloc or not _is_device_path(parts.path)):
        raise ConfigurationError(f"{url!r}: expected modbus-rtu:///dev/<port> (a serial device path)")
    _check_sensor_query(url, parts)
    return url


# the query of a sensor URL: key -> (low, high) of its integer value, per scheme.  A Modbus
# serial device answers at 1-247 (0 is broadcast: nothing answers); over TCP a gateway or
# device may use any unit id 0-255.
SENSOR_QUERY = {"modbus-tcp": {"unit": (0, 255)},
                "modbus-rtu": {"unit": (1, 247), "baud": (50, 4_000_000)}}


def _check_sensor_query(url: str, parts: urllib.parse.SplitResult) -> None:
    """Each query parameter known, given once, an integer in range: checked with the rig
    file, not found at run time."""
    allowed = SENSOR_QUERY[parts.scheme]
    try:
        pairs = urllib.parse.parse_qsl(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
    except ValueError:
        raise ConfigurationError(f"{url!r}: the query {parts.query!r} is not key=value pairs joined by &") from None
    seen = set()
    for key, value in pairs:
        if key not in allowed:
            raise ConfigurationError(f"{url!r}: unknown parameter {key!r} for {parts.scheme}; "
                                     f"allowed: {', '.join(allowed)}")
        if key in seen:
            raise ConfigurationError(f"{url!r}: parameter {key!r} given twice")
        seen.add(key)
        lo, hi = allowed[key]
        if not (value.isascii() and value.isdigit() and lo <= int(value) <= hi):
            raise ConfigurationError(f"{url!r}: {key} must be an integer {lo}-{hi}, got {value!r}")


def check_daq_url(url: str) -> str:
    if not isinstance(url, str):
        raise _refuse(repr(url), "DAQ", DAQ_FORMS)
    if url.startswith("virtual:") and len(url) > len("virtual:"):
        return url
    if url.startswith("tcp://"):
        parts = urllib.parse.urlsplit(url)
        if parts.hostname is None or parts.port is None or parts.path or parts.query:
            raise ConfigurationError(f"{url!r}: expected tcp://host:port")
        return url
    interface, sep, channel = url.partition(":")
    if not sep or not channel or interface not in CAN_INTERFACES:
        raise _refuse(url, "DAQ", DAQ_FORMS)
    if interface in CAN_SERIAL_INTERFACES and not _is_device_path(channel.split("@", 1)[0]):
        raise ConfigurationError(f"{url!r}: the {interface} interface takes a serial device path "
                         f"(/dev/<port>), not {channel!r}")
    return url
