"""Simulated CAN FD DAQ: answers the host's frames and samples the shared plant.

On TRIGGER it advances the plant's virtual clock by one block (``rig.run``, holding
``rig.lock``), quantises the three input voltages to 24-bit counts and sends header, data
frames and end-of-block. The last block is kept so RESEND can repeat it.

The plant is simulated, not real time: a block can take longer to compute than it lasts
(the first ``rig.run`` of a process pays the kernel's JIT compilation, seconds). While
it computes, the twin sends a STATUS frame in state ACQUIRING every
``BUSY_STATUS_INTERVAL_S`` so the host knows the DAQ is alive (see ``CanFdDaq``).

The twin's thread owns the bus: :meth:`DaqTwin.close` asks it to stop, and the thread
abandons any block in progress, sends nothing more and shuts the bus down itself, so no
frame is ever sent on a closed bus and no exception escapes the thread.

Fault injection for tests: :meth:`DaqTwin.inject_fault` queues a function that edits the
list of outgoing data frames of the next transmission (drop, duplicate, corrupt, ...).
"""

from __future__ import annotations

import collections
import logging
import threading
from collections.abc import Callable
from typing import Any

import can
import numpy as np

from . import _daq_codec as codec

log = logging.getLogger(__name__)

MIN_RATE_mHz = 1_000_000
MAX_RATE_mHz = 204_800_000
# the twin's block limit, the real DAQ's: a block of the three channels fits in 65535 data
# frames of 20 values (NFrames is 16 bits): 436900 samples, about 10 MB in flight
MAX_SAMPLES = codec.MAX_FRAMES * codec.SAMPLES_PER_FRAME // codec.N_CHANNELS
MAX_PENDING_FAULTS = 64
BUSY_STATUS_INTERVAL_S = 0.1

FrameFault = Callable[[list[bytes]], list[bytes]]


class _Stopping(Exception):
    """Raised inside the twin's thread when close() was asked for: abandon the work."""


class DaqTwin:
    """The DAQ end of the CAN FD link (one bus, one thread)."""

    def __init__(self, rig: Any, bus: can.BusABC, *, full_scale_V: float = 10.0) -> None:
        self._rig = rig
        self._bus = bus
        self.full_scale_V = full_scale_V
        self.state = codec.State.IDLE
        self.sample_rate_mHz = 25_600_000
        self.n_samples = 0
        self.channel_mask = codec.ALL_CHANNELS_MASK
        self.block_id = 0
        self._last_block: tuple[codec.BlockHeader, list[bytes]] | None = None
        self._faults: collections.deque[FrameFault] = collections.deque()
        self.frames_sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="daq-twin", daemon=True)
        self._thread.start()

    def inject_fault(self, fault: FrameFault) -> None:
        """Apply ``fault`` to the data frames of the next block transmission only."""
        if len(self._faults) >= MAX_PENDING_FAULTS:
            raise ValueError(f"{MAX_PENDING_FAULTS} faults already queued")
        self._faults.append(fault)

    # ----------------------------------------------------------------- loop
    def _loop(self) -> None:
        try:
            while not self._stop.is_set():
                try:
                    msg = self._bus.recv(timeout=0.05)
                except can.CanError as exc:
                    log.warning("DAQ twin: bus receive failed: %s", exc)
                    self._stop.wait(0.05)
                    continue
                if msg is None or msg.is_error_frame:
                    continue
                try:
                    self._handle(msg)
                except _Stopping:
                    break
                except Exception:  # noqa: BLE001 - the twin keeps serving after bad input
                    log.exception("DAQ twin: failed to handle frame %s", msg)
                    self._report_failure()
        except Exception:  # noqa: BLE001 - never let an exception escape the thread
            log.exception("DAQ twin: serving loop failed")
        finally:
            try:
                self._bus.shutdown()
            except Exception as exc:  # noqa: BLE001
                log.warning("DAQ twin: bus shutdown failed: %s", exc)
            log.debug("DAQ twin: stopped")

    def _report_failure(self) -> None:
        try:
            self._status(0, codec.ErrorCode.UNKNOWN_COMMAND, codec.State.ERROR)
        except _Stopping:
            pass
        except Exception as exc:  # noqa: BLE001
            log.warning("DAQ twin: could not report the failure: %s", exc)

    def _handle(self, msg: can.Message) -> None:
        if msg.arbitration_id == codec.ID_CONFIG:
            self._configure(bytes(msg.data))
        elif msg.arbitration_id == codec.ID_COMMAND:
            fields = codec.decode(codec.ID_COMMAND, bytes(msg.data))
            self._command(int(fields["Command"]), int(fields["BlockId"]))

    def _send(self, frame_id: int, data: bytes) -> None:
        if self._stop.is_set():
            raise _Stopping
        self._bus.send(can.Message(arbitration_id=frame_id, data=data, is_fd=True,
                                   bitrate_switch=True, is_extended_id=False))
        self.frames_sent += 1

    def _status(self, command: int, error: codec.ErrorCode,
                state: codec.State | None = None) -> None:
        self._send(codec.ID_STATUS, codec.encode(
            codec.ID_STATUS, State=int(state if state is not None else self.state),
            LastCommand=command, BlockId=self.block_id, ErrorCode=int(error)))

    def _configure(self, data: bytes) -> None:
        if len(data) != 8:
            self._status(0, codec.ErrorCode.BAD_CONFIG)
            return
        f = codec.decode(codec.ID_CONFIG, data)
        rate, n, mask = int(f["SampleRate_mHz"]), int(f["NSamples"]), int(f["ChannelMask"])
        if not (MIN_RATE_mHz <= rate <= MAX_RATE_mHz) or not (1 <= n <= MAX_SAMPLES) \
                or mask != codec.ALL_CHANNELS_MASK:
            log.info("DAQ twin: rejected configuration rate=%d mHz n=%d mask=%#x", rate, n, mask)
            self._status(0, codec.ErrorCode.BAD_CONFIG)
            return
        self.sample_rate_mHz, self.n_samples, self.channel_mask = rate, n, mask
        self.state = codec.State.CONFIGURED
        self._send(codec.ID_CONFIG_ACK, codec.encode(codec.ID_CONFIG_ACK, SampleRate_mHz=rate,
                                                     NSamples=n, ChannelMask=mask))
        self._status(0, codec.ErrorCode.NONE)

    def _command(self, command: int, block_id: int) -> None:
        if command == codec.Command.ARM:
            if self.state == codec.State.IDLE:
                self._status(command, codec.ErrorCode.NOT_CONFIGURED)
                return
            self.state = codec.State.ARMED
            self._status(command, codec.ErrorCode.NONE)
        elif command == codec.Command.TRIGGER:
            if self.state != codec.State.ARMED:
                self._status(command, codec.ErrorCode.NOT_ARMED)
                return
            self._acquire_and_send()
        elif command == codec.Command.RESEND:
            if self._last_block is None or self._last_block[0].block_id != block_id:
                self._status(command, codec.ErrorCode.UNKNOWN_BLOCK)
                return
            self._transmit(*self._last_block)
        elif command == codec.Command.ABORT:
            self.state = codec.State.CONFIGURED if self.n_samples else codec.State.IDLE
            self._status(command, codec.ErrorCode.NONE)
        elif command == codec.Command.STATUS:
            self._status(command, codec.ErrorCode.NONE)
        else:
            self._status(command, codec.ErrorCode.UNKNOWN_COMMAND)

    def _acquire_and_send(self) -> None:
        self.state = codec.State.ACQUIRING
        block = self._run_plant(self.n_samples, self.sample_rate_mHz / 1000.0)
        volts = np.stack([block.force_V, block.accel_V, block.disp_V], axis=1)
        counts = codec.volts_to_counts(volts, self.full_scale_V)
        payload = codec.pack_samples(counts)
        self.block_id = (self.block_id + 1) & 0xFFFF
        n_values = self.n_samples * codec.N_CHANNELS
        frames = codec.build_data_frames(payload, self.block_id, n_values)
        header = codec.BlockHeader(
            block_id=self.block_id, n_samples=self.n_samples, channel_mask=self.channel_mask,
            bits_per_sample=codec.BITS_PER_SAMPLE, n_frames=len(frames),
            payload_crc32=codec.crc32(payload), sample_rate_mHz=self.sample_rate_mHz,
            t0_us=int(round(block.t0_s * 1e6)), full_scale_mV=int(round(self.full_scale_V * 1e3)))
        self._last_block = (header, frames)
        self.state = codec.State.SENDING
        self._transmit(header, frames)
        self.state = codec.State.CONFIGURED

    def _run_plant(self, n_samples: int, fs_Hz: float) -> Any:
        """``rig.run`` on a helper thread; a busy STATUS every BUSY_STATUS_INTERVAL_S
        until it returns. Raises _Stopping (block abandoned) if close() is asked for."""
        done = threading.Event()
        outcome: dict[str, Any] = {}

        def compute() -> None:
            try:
                with self._rig.lock:
                    outcome["block"] = self._rig.run(n_samples, fs_Hz)
            except BaseException as exc:  # noqa: BLE001 - handed to the serving thread
                outcome["error"] = exc
            finally:
                done.set()

        threading.Thread(target=compute, name="daq-twin-plant", daemon=True).start()
        while not done.wait(BUSY_STATUS_INTERVAL_S):
            self._status(codec.Command.TRIGGER, codec.ErrorCode.NONE, codec.State.ACQUIRING)
        if "error" in outcome:
            raise outcome["error"]
        return outcome["block"]

    def _transmit(self, header: codec.BlockHeader, frames: list[bytes]) -> None:
        if self._faults:
            frames = self._faults.popleft()(list(frames))
        self._send(codec.ID_BLOCK_HEADER, header.to_frame())
        for data in frames:
            self._send(codec.ID_BLOCK_DATA, data)
        self._send(codec.ID_BLOCK_END, codec.encode(
            codec.ID_BLOCK_END, BlockId=header.block_id, NFrames=header.n_frames,
            PayloadCrc32=header.payload_crc32))

    def close(self) -> None:
        """Stop serving; the thread abandons a block in progress and closes the bus."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        if self._thread.is_alive():
            log.warning("DAQ twin: thread still busy after close(); it will release the "
                        "bus when it returns")
