"""Wire format of the CAN FD DAQ: control frames via cantools, data frames via numpy.

The frames are described in ``drivers/daq.dbc`` (the single source of the layout; see
docs/decisions/0005). Control frames are few and are encoded/decoded with cantools. Data
frames are thousands per block, so their 24-bit samples are packed and unpacked with
vectorised numpy; tests check that layout against the DBC with cantools.

Data frame (id 0x300, 64 bytes, little-endian)::

    bytes 0-1  Seq         0 .. NFrames-1
    byte  2    BlockIdLsb  low byte of the block id
    byte  3    NValid      samples in this frame (20, fewer in the last one)
    bytes 4-63 20 x int24  channel-interleaved ADC counts (ch0, ch1, ch2, ch0, ...)
"""

from __future__ import annotations

import enum
import functools
import logging
import zlib
from dataclasses import dataclass
from pathlib import Path

import cantools
import numpy as np

from ._errors import FrameError

log = logging.getLogger(__name__)

ID_CONFIG = 0x100
ID_COMMAND = 0x101
ID_CONFIG_ACK = 0x180
ID_STATUS = 0x181
ID_BLOCK_HEADER = 0x200
ID_BLOCK_DATA = 0x300
ID_BLOCK_END = 0x400

DATA_FRAME_BYTES = 64
DATA_HEADER_BYTES = 4
SAMPLES_PER_FRAME = 20
MAX_FRAMES = 65535          # NFrames of DAQ_BlockHeader / DAQ_BlockEnd is 16 bits (daq.dbc)
BYTES_PER_SAMPLE = 3
BITS_PER_SAMPLE = 24
FULL_SCALE_COUNTS = 2**23 - 1
DEFAULT_FULL_SCALE_V = 10.0
N_CHANNELS = 3
ALL_CHANNELS_MASK = 0b111


class Command(enum.IntEnum):
    ARM = 1
    TRIGGER = 2
    RESEND = 3
    ABORT = 4
    STATUS = 5


class State(enum.IntEnum):
    IDLE = 0
    CONFIGURED = 1
    ARMED = 2
    ACQUIRING = 3
    SENDING = 4
    ERROR = 5


class ErrorCode(enum.IntEnum):
    NONE = 0
    BAD_CONFIG = 1
    NOT_CONFIGURED = 2
    NOT_ARMED = 3
    UNKNOWN_BLOCK = 4
    UNKNOWN_COMMAND = 5


def dbc_path() -> str:
    return str(Path(__file__).with_name("daq.dbc"))


@functools.cache
def database() -> cantools.database.can.Database:
    """The shipped DBC, loaded once."""
    db = cantools.database.load_file(dbc_path())
    assert isinstance(db, cantools.database.can.Database)     # a .dbc is a CAN database
    return db


def encode(frame_id: int, **signals: float) -> bytes:
    return bytes(database().get_message_by_frame_id(frame_id).encode(signals))


def decode(frame_id: int, data: bytes) -> dict:
    return dict(database().get_message_by_frame_id(frame_id).decode(bytes(data),
                                                                     decode_choices=False))


def n_data_frames(n_samples: int, n_channels: int = N_CHANNELS) -> int:
    return -(-n_samples * n_channels // SAMPLES_PER_FRAME)


# ---------------------------------------------------------------------- samples
def volts_to_counts(volts: np.ndarray, full_scale_V: float = DEFAULT_FULL_SCALE_V) -> np.ndarray:
    """ADC quantisation with saturation at full scale."""
    counts = np.rint(np.asarray(volts, dtype=np.float64) * (FULL_SCALE_COUNTS / full_scale_V))
    return np.clip(counts, -FULL_SCALE_COUNTS, FULL_SCALE_COUNTS).astype(np.int32)


def counts_to_volts(counts: np.ndarray, full_scale_V: float = DEFAULT_FULL_SCALE_V) -> np.ndarray:
    return counts.astype(np.float64) * (full_scale_V / FULL_SCALE_COUNTS)


def pack_samples(counts: np.ndarray) -> bytes:
    """(n_samples, n_channels) int32 counts -> interleaved little-endian int24 bytes."""
    flat = np.ascontiguousarray(counts, dtype="<i4").reshape(-1)
    return flat.view(np.uint8).reshape(-1, 4)[:, :BYTES_PER_SAMPLE].tobytes()


def unpack_samples(payload: bytes | np.ndarray, n_samples: int,
                   n_channels: int = N_CHANNELS) -> np.ndarray:
    """Interleaved little-endian int24 bytes -> (n_samples, n_channels) int32 counts."""
    raw = np.frombuffer(payload, dtype=np.uint8) if isinstance(payload, (bytes, bytearray)) \
        else payload
    raw = raw[: n_samples * n_channels * BYTES_PER_SAMPLE].reshape(-1, BYTES_PER_SAMPLE)
    values = (raw[:, 0].astype(np.int32) | (raw[:, 1].astype(np.int32) << 8)
              | (raw[:, 2].astype(np.int32) << 16))
    values = (values ^ 0x800000) - 0x800000
    return values.reshape(n_samples, n_channels)


def crc32(payload: bytes) -> int:
    return zlib.crc32(payload) & 0xFFFFFFFF


def build_data_frames(payload: bytes, block_id: int, n_values: int) -> list[bytes]:
    """Split the sample payload into 64-byte data frames with sequence numbers."""
    n_frames = -(-n_values // SAMPLES_PER_FRAME)
    body_len = SAMPLES_PER_FRAME * BYTES_PER_SAMPLE
    frames = np.zeros((n_frames, DATA_FRAME_BYTES), dtype=np.uint8)
    body = np.zeros(n_frames * body_len, dtype=np.uint8)
    body[: len(payload)] = np.frombuffer(payload, dtype=np.uint8)
    frames[:, DATA_HEADER_BYTES:] = body.reshape(n_frames, body_len)
    seq = np.arange(n_frames, dtype=np.uint16)
    frames[:, 0] = seq & 0xFF
    frames[:, 1] = seq >> 8
    frames[:, 2] = block_id & 0xFF
    frames[:, 3] = SAMPLES_PER_FRAME
    frames[-1, 3] = n_values - (n_frames - 1) * SAMPLES_PER_FRAME
    return [row.tobytes() for row in frames]


@dataclass(frozen=True)
class BlockHeader:
    block_id: int
    n_samples: int
    channel_mask: int
    bits_per_sample: int
    n_frames: int
    payload_crc32: int
    sample_rate_mHz: int
    t0_us: int
    full_scale_mV: int

    @classmethod
    def from_frame(cls, data: bytes) -> BlockHeader:
        s = decode(ID_BLOCK_HEADER, data)
        return cls(int(s["BlockId"]), int(s["NSamples"]), int(s["ChannelMask"]),
                   int(s["BitsPerSample"]), int(s["NFrames"]), int(s["PayloadCrc32"]),
                   int(s["SampleRate_mHz"]), int(s["T0_us"]), int(s["FullScale_mV"]))

    def to_frame(self) -> bytes:
        return encode(ID_BLOCK_HEADER, BlockId=self.block_id, NSamples=self.n_samples,
                      ChannelMask=self.channel_mask, BitsPerSample=self.bits_per_sample,
                      NFrames=self.n_frames, PayloadCrc32=self.payload_crc32,
                      SampleRate_mHz=self.sample_rate_mHz, T0_us=self.t0_us,
                      FullScale_mV=self.full_scale_mV)


def assemble_payload(header: BlockHeader, frames: list[bytes]) -> bytes:
    """Check the data frames of one block and return the sample payload.

    Raises FrameError naming the first problem: a frame of the wrong length, a lost,
    duplicated or reordered frame (sequence), a frame of another block, a wrong sample
    count, or a CRC mismatch. Never returns a payload that fails any of these checks.
    """
    n_values = header.n_samples * N_CHANNELS
    expected_frames = -(-n_values // SAMPLES_PER_FRAME)
    if header.n_frames != expected_frames:
        raise FrameError(f"block {header.block_id}: header announces {header.n_frames} frames, "
                         f"{header.n_samples} samples need {expected_frames}")
    bad_lengths = [i for i, f in enumerate(frames) if len(f) != DATA_FRAME_BYTES]
    if bad_lengths:
        i = bad_lengths[0]
        raise FrameError(f"block {header.block_id}: data frame #{i} has {len(frames[i])} bytes, "
                         f"expected {DATA_FRAME_BYTES}")
    if len(frames) != expected_frames:
        raise FrameError(f"block {header.block_id}: received {len(frames)} data frames, "
                         f"expected {expected_frames} (lost or duplicated frames)")
    table = np.frombuffer(b"".join(frames), dtype=np.uint8).reshape(-1, DATA_FRAME_BYTES)
    seq = table[:, 0].astype(np.int64) | (table[:, 1].astype(np.int64) << 8)
    wrong_seq = np.flatnonzero(seq != np.arange(expected_frames))
    if wrong_seq.size:
        i = int(wrong_seq[0])
        raise FrameError(f"block {header.block_id}: frame #{i} has sequence {int(seq[i])}, "
                         f"expected {i} (lost, duplicated or reordered frame)")
    wrong_block = np.flatnonzero(table[:, 2] != (header.block_id & 0xFF))
    if wrong_block.size:
        i = int(wrong_block[0])
        raise FrameError(f"block {header.block_id}: frame #{i} belongs to block "
                         f"low byte {int(table[i, 2])}")
    n_valid = int(table[:, 3].astype(np.int64).sum())
    if n_valid != n_values:
        raise FrameError(f"block {header.block_id}: frames carry {n_valid} samples, "
                         f"expected {n_values}")
    payload = table[:, DATA_HEADER_BYTES:].reshape(-1)[: n_values * BYTES_PER_SAMPLE].tobytes()
    crc = crc32(payload)
    if crc != header.payload_crc32:
        raise FrameError(f"block {header.block_id}: payload CRC32 {crc:#010x} does not match "
                         f"the header's {header.payload_crc32:#010x} (corrupt frame)")
    return payload
