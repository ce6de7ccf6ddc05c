"""Driver of the 3-channel DAQ on CAN FD: configure, arm, trigger, read one block.

Every block is checked before it is returned: header, data frame lengths, sequence
numbers, block id, sample count and CRC32 against both the header and the end-of-block
frame. On any failure the driver sends RESEND (up to ``max_resends`` times) and then
raises :class:`BlockIntegrityError`; it never returns silently wrong data.

Waiting for a block: the deadline is the block's duration plus its transfer time plus
``timeout_s``. A DAQ that needs longer (the simulated twin computes its plant, which can
be slower than real time) sends STATUS frames in state ACQUIRING meanwhile; each one
moves the deadline to ``timeout_s`` after it, up to ``max_busy_s`` past the nominal
deadline, so a silent DAQ still fails in bounded time and a busy one is not cut off.
"""

from __future__ import annotations

import logging
import math
import time

import can
import numpy as np

from . import _daq_codec as codec
from ._errors import BlockIntegrityError, ConnectionLost, FrameError, InstrumentError, InstrumentTimeout
from ._interfaces import Channel, ChannelSpec, DaqBlock

log = logging.getLogger(__name__)

CAN_FD_DATA_BITRATE = 5e6
MAX_SAMPLE_RATE_HZ = 204_800.0
# The DAQ's largest block: NSamples of DAQ_Config is 24 bits, but a block of the three
# channels must also fit in 65535 data frames of 20 values (NFrames is 16 bits): 436900.
MAX_BLOCK_SAMPLES = min(2**24 - 1, codec.MAX_FRAMES * codec.SAMPLES_PER_FRAME // codec.N_CHANNELS)


def plan_block(freq_Hz: float, n_periods: int, min_rate_Hz: float = 25_600.0) -> tuple[float, int]:
    """Sample rate and block length covering exactly ``n_periods`` periods of ``freq_Hz``.

    Picks the smallest integer number of samples per period that reaches ``min_rate_Hz``
    and sets the rate to that multiple of the frequency (to the DAQ's 1 mHz resolution).
    """
    if not (freq_Hz > 0 and math.isfinite(freq_Hz)) or n_periods < 1:
        raise ValueError(f"need freq_Hz > 0 and n_periods >= 1, got {freq_Hz!r}, {n_periods!r}")
    samples_per_period = max(2, math.ceil(min_rate_Hz / freq_Hz - 1e-9))
    rate_Hz = round(samples_per_period * freq_Hz * 1000.0) / 1000.0
    if rate_Hz > MAX_SAMPLE_RATE_HZ:
        raise ValueError(f"{freq_Hz} Hz needs {rate_Hz} S/s, above the DAQ's "
                         f"{MAX_SAMPLE_RATE_HZ:g} S/s")
    return rate_Hz, samples_per_period * n_periods


class CanFdDaq:
    """The DAQ over a python-can bus (CAN FD frames). Satisfies :class:`Daq`.

    :param bus: any python-can bus (``interface="virtual"`` in-process, the TCP bridge
        of ``open_can_bus("tcp://...")`` across processes, a real CAN FD adapter).
    :param channels: force, acceleration and displacement transducers, in that order.
    :param max_busy_s: how much longer than the nominal block deadline to wait while the
        DAQ keeps reporting ACQUIRING (s).
    """

    def __init__(self, bus: can.BusABC, channels: tuple[ChannelSpec, ...], *,
                 timeout_s: float = 2.0, max_resends: int = 2, max_busy_s: float = 60.0) -> None:
        order = tuple(spec.channel for spec in channels)
        if order != (Channel.FORCE, Channel.ACCELERATION, Channel.DISPLACEMENT):
            raise ValueError(f"channels must be FORCE, ACCELERATION, DISPLACEMENT, got {order}")
        self._bus = bus
        self.channels = tuple(channels)
        self.timeout_s = timeout_s
        self.max_resends = max_resends
        self.max_busy_s = max_busy_s
        self._rate_mHz = 0
        self._n_samples = 0

    # ----------------------------------------------------------------- bus helpers
    @property
    def where(self) -> str:
        """The DAQ as an error names it: its bus (``tcp://host:port``, ``socketcan:can0``)."""
        return f"DAQ at {getattr(self._bus, 'channel_info', None) or 'its CAN bus'}"

    def _send(self, frame_id: int, data: bytes) -> None:
        try:
            self._bus.send(can.Message(arbitration_id=frame_id, data=data, is_fd=True,
                                       bitrate_switch=True, is_extended_id=False),
                           timeout=self.timeout_s)
        except (can.CanError, OSError) as exc:      # a lost link: the bus's error or the socket's
            raise ConnectionLost(f"{self.where}: CAN send of frame {frame_id:#x} failed: {exc}") from exc

    def _recv(self, deadline: float, waiting_for: str) -> can.Message:
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise InstrumentTimeout(f"{self.where}: no {waiting_for} within the timeout")
            try:
                msg = self._bus.recv(timeout=left)
            except (can.CanError, OSError) as exc:
                raise ConnectionLost(f"{self.where}: CAN receive failed: {exc}") from exc
            if msg is not None and not msg.is_error_frame:
                return msg

    def _drain(self) -> None:
        try:
            while self._bus.recv(timeout=0.0) is not None:
                pass
        except (can.CanError, OSError) as exc:
            raise ConnectionLost(f"{self.where}: CAN receive failed: {exc}") from exc

    def _command(self, command: codec.Command, block_id: int = 0) -> None:
        self._send(codec.ID_COMMAND, codec.encode(codec.ID_COMMAND, Command=int(command),
                                                  BlockId=block_id))

    def _await_status(self, command: int, deadline: float) -> dict:
        while True:
            msg = self._recv(deadline, f"status after command {command}")
            if msg.arbitration_id != codec.ID_STATUS:
                continue
            status = self._decode_status(msg)
            if int(status["LastCommand"]) != command:
                continue
            self._raise_on_error(status, command)
            return status

    @staticmethod
    def _decode_status(msg: can.Message) -> dict:
        try:
            return codec.decode(codec.ID_STATUS, bytes(msg.data))
        except Exception as exc:  # noqa: BLE001 - cantools raises several types
            raise FrameError(f"DAQ: unreadable status frame ({len(msg.data)} bytes): {exc}") from exc

    @staticmethod
    def _raise_on_error(status: dict, command: int) -> None:
        code = int(status["ErrorCode"])
        if code != codec.ErrorCode.NONE:
            name = codec.ErrorCode(code).name if code in codec.ErrorCode._value2member_map_ \
                else str(code)
            cmd = codec.Command(command).name if command in codec.Command._value2member_map_ \
                else ("CONFIG" if command == 0 else str(command))
            raise InstrumentError(f"DAQ refused {cmd}: {name}")

    # ----------------------------------------------------------------- public
    @property
    def sample_rate_Hz(self) -> float:
        return self._rate_mHz / 1000.0

    @property
    def n_samples(self) -> int:
        return self._n_samples

    def configure(self, sample_rate_Hz: float, n_samples: int) -> None:
        """Set sample rate (1 mHz resolution) and block length; confirmed by the DAQ's echo."""
        rate_mHz = int(round(sample_rate_Hz * 1000.0))
        if not (1_000_000 <= rate_mHz <= int(MAX_SAMPLE_RATE_HZ * 1000)):
            raise ValueError(f"sample rate {sample_rate_Hz!r} S/s outside 1 kS/s .. "
                             f"{MAX_SAMPLE_RATE_HZ:g} S/s")
        if not (1 <= n_samples <= MAX_BLOCK_SAMPLES):
            raise ValueError(f"block length {n_samples!r} outside 1 .. {MAX_BLOCK_SAMPLES} samples (three channels "
                             f"in at most {codec.MAX_FRAMES} data frames of {codec.SAMPLES_PER_FRAME} values)")
        self._drain()
        self._send(codec.ID_CONFIG, codec.encode(codec.ID_CONFIG, SampleRate_mHz=rate_mHz,
                                                 NSamples=n_samples,
                                                 ChannelMask=codec.ALL_CHANNELS_MASK))
        deadline = time.monotonic() + self.timeout_s
        ack = None
        while True:
            msg = self._recv(deadline, "configuration acknowledge")
            if msg.arbitration_id == codec.ID_CONFIG_ACK:
                ack = codec.decode(codec.ID_CONFIG_ACK, bytes(msg.data))
            elif msg.arbitration_id == codec.ID_STATUS:
                status = codec.decode(codec.ID_STATUS, bytes(msg.data))
                if int(status["LastCommand"]) == 0:
                    self._raise_on_error(status, 0)
                    if ack is not None:
                        break
        if (int(ack["SampleRate_mHz"]), int(ack["NSamples"])) != (rate_mHz, n_samples):
            raise InstrumentError(f"DAQ confirmed {ack}, asked for {rate_mHz} mHz, "
                                  f"{n_samples} samples")
        self._rate_mHz, self._n_samples = rate_mHz, n_samples
        log.debug("DAQ configured: %.3f S/s, %d samples", self.sample_rate_Hz, n_samples)

    def arm(self) -> None:
        self._drain()
        self._command(codec.Command.ARM)
        self._await_status(codec.Command.ARM, time.monotonic() + self.timeout_s)

    def trigger(self) -> None:
        self._command(codec.Command.TRIGGER)

    def _block_deadline(self) -> float:
        n_frames = codec.n_data_frames(self._n_samples)
        transfer_s = n_frames * 64 * 8 * 1.3 / CAN_FD_DATA_BITRATE
        acquire_s = self._n_samples / max(self.sample_rate_Hz, 1.0)
        return time.monotonic() + self.timeout_s + transfer_s + acquire_s

    def read_block(self, timeout_s: float | None = None) -> DaqBlock:
        """Receive the triggered block; RESEND on a bad block; never return wrong data."""
        if timeout_s is not None:
            deadline = time.monotonic() + timeout_s
        else:
            deadline = self._block_deadline()
        header: codec.BlockHeader | None = None
        problems: list[str] = []
        for attempt in range(self.max_resends + 1):
            if attempt and header is not None:      # (a failed attempt always has its header)
                log.warning("DAQ block %d: %s; RESEND (%d/%d)", header.block_id,
                            problems[-1], attempt, self.max_resends)
                self._drain()
                self._command(codec.Command.RESEND, header.block_id)
                deadline = max(deadline, self._block_deadline())
            try:
                header, frames, end = self._collect(deadline)
                self._check_end(header, end)
                payload = codec.assemble_payload(header, frames)
            except FrameError as exc:
                if isinstance(exc.header, codec.BlockHeader):
                    header = exc.header
                if header is None:
                    raise
                problems.append(str(exc))
                continue
            return self._to_block(header, payload, resends=attempt)
        raise BlockIntegrityError(f"DAQ block {header.block_id if header else '?'} still inconsistent after "
                                  f"{self.max_resends} RESEND(s): " + " | ".join(problems))

    def _collect(self, deadline: float
                 ) -> tuple[codec.BlockHeader, list[bytes], dict]:
        header: codec.BlockHeader | None = None
        frames: list[bytes] = []
        busy_limit = deadline + self.max_busy_s
        while True:
            try:
                msg = self._recv(deadline, "data block" if header is None else "end of block")
            except InstrumentTimeout:
                if header is None:
                    raise
                raise FrameError(f"block {header.block_id}: end-of-block frame lost "
                                 f"({len(frames)} of {header.n_frames} data frames received)",
                                 header) from None
            fid = msg.arbitration_id
            if fid == codec.ID_BLOCK_HEADER:
                try:
                    new_header = codec.BlockHeader.from_frame(bytes(msg.data))
                except Exception as exc:  # noqa: BLE001 - cantools raises several types
                    raise FrameError(f"unreadable block header ({len(msg.data)} bytes): "
                                     f"{exc}") from exc
                if header is not None:
                    raise FrameError(f"block {header.block_id}: new header before the end "
                                     f"of block", new_header)
                header = new_header
            elif fid == codec.ID_BLOCK_DATA:
                if header is not None:
                    frames.append(bytes(msg.data))
            elif fid == codec.ID_BLOCK_END:
                if header is None:
                    continue
                try:
                    end = codec.decode(codec.ID_BLOCK_END, bytes(msg.data))
                except Exception as exc:  # noqa: BLE001
                    raise FrameError(f"block {header.block_id}: unreadable end frame: {exc}",
                                     header) from exc
                return header, frames, end
            elif fid == codec.ID_STATUS:
                status = self._decode_status(msg)
                self._raise_on_error(status, int(status["LastCommand"]))
                if header is None and int(status["State"]) == codec.State.ACQUIRING:
                    deadline = min(max(deadline, time.monotonic() + self.timeout_s), busy_limit)

    @staticmethod
    def _check_end(header: codec.BlockHeader, end: dict) -> None:
        if (int(end["BlockId"]), int(end["NFrames"]), int(end["PayloadCrc32"])) != \
                (header.block_id, header.n_frames, header.payload_crc32):
            raise FrameError(f"block {header.block_id}: end-of-block {dict(end)} does not "
                             f"match the header", header)

    def _to_block(self, header: codec.BlockHeader, payload: bytes, resends: int) -> DaqBlock:
        counts = codec.unpack_samples(payload, header.n_samples)
        volts = codec.counts_to_volts(counts, header.full_scale_mV / 1000.0)
        force_V, accel_V, disp_V = (np.ascontiguousarray(volts[:, i]) for i in range(3))
        f, a, d = (spec.sensitivity_V_per_unit for spec in self.channels)
        return DaqBlock(block_id=header.block_id, t0_s=header.t0_us / 1e6,
                        fs_Hz=header.sample_rate_mHz / 1000.0, force_N=force_V / f,
                        accel_m_s2=accel_V / a, disp_m=disp_V / d, force_V=force_V,
                        accel_V=accel_V, disp_V=disp_V, resends=resends)

    def acquire(self) -> DaqBlock:
        """Arm, trigger and read one block with the present configuration."""
        self.arm()
        self.trigger()
        return self.read_block()

    def acquire_periods(self, freq_Hz: float, n_periods: int,
                        min_rate_Hz: float = 25_600.0) -> DaqBlock:
        """One block of exactly ``n_periods`` periods of ``freq_Hz`` (see plan_block)."""
        rate_Hz, n = plan_block(freq_Hz, n_periods, min_rate_Hz)
        if (int(round(rate_Hz * 1000)), n) != (self._rate_mHz, self._n_samples):
            self.configure(rate_Hz, n)
        return self.acquire()

    def acquire_samples(self, sample_rate_Hz: float, n_samples: int) -> DaqBlock:
        """One block of ``n_samples`` at ``sample_rate_Hz`` (configured only when it changes)."""
        if (int(round(sample_rate_Hz * 1000)), n_samples) != (self._rate_mHz, self._n_samples):
            self.configure(sample_rate_Hz, n_samples)
        return self.acquire()

    def close(self) -> None:
        try:
            self._command(codec.Command.ABORT)
        except InstrumentError as exc:
            log.debug("DAQ close: ABORT not sent: %s", exc)
        self._bus.shutdown()
