"""DAQ wire format: numpy packing agrees with the shipped DBC (decoded by cantools)."""

import zlib

import cantools
import numpy as np
import pytest

from drivers import FrameError, dbc_path
from drivers import _daq_codec as codec

pytestmark = pytest.mark.timeout(60)


def test_shipped_dbc_describes_can_fd_frames_of_the_documented_sizes():
    db = cantools.database.load_file(dbc_path())
    sizes = {m.name: (m.frame_id, m.length, m.is_fd) for m in db.messages}
    assert sizes["DAQ_BlockData"] == (0x300, 64, True)
    assert sizes["DAQ_BlockHeader"][1:] == (32, True)
    assert sizes["DAQ_Config"][1:] == (8, True)


def test_int24_packing_matches_twos_complement_little_endian():
    counts = np.array([[1, -1, 0x7FFFFF], [-0x7FFFFF, 256, -256]], dtype=np.int32)
    payload = codec.pack_samples(counts)
    assert payload[:6] == b"\x01\x00\x00\xff\xff\xff"
    assert payload[6:9] == b"\xff\xff\x7f"
    assert np.array_equal(codec.unpack_samples(payload, 2), counts)


def test_cantools_decodes_data_frames_to_the_voltages_the_twin_sampled():
    rng = np.random.default_rng(3)
    volts = rng.uniform(-9.9, 9.9, size=(50, 3))
    counts = codec.volts_to_counts(volts)
    frames = codec.build_data_frames(codec.pack_samples(counts), block_id=7, n_values=150)
    db = cantools.database.load_file(dbc_path())
    decoded = []
    for seq, frame in enumerate(frames):
        fields = db.decode_message(0x300, frame)
        assert fields["Seq"] == seq and fields["BlockIdLsb"] == 7
        decoded += [fields[f"Sample{i:02d}"] for i in range(fields["NValid"])]
    assert np.allclose(np.reshape(decoded, (50, 3)), volts, atol=10.0 / 2**23)


def test_quantisation_saturates_at_full_scale():
    counts = codec.volts_to_counts(np.array([12.0, -12.0, 0.0]))
    assert counts.tolist() == [codec.FULL_SCALE_COUNTS, -codec.FULL_SCALE_COUNTS, 0]


def _block(n_samples=41, block_id=5):
    counts = np.arange(n_samples * 3, dtype=np.int32).reshape(n_samples, 3) - 60
    payload = codec.pack_samples(counts)
    frames = codec.build_data_frames(payload, block_id, n_samples * 3)
    header = codec.BlockHeader(block_id, n_samples, 7, 24, len(frames),
                               zlib.crc32(payload), 25_600_000, 0, 10_000)
    return header, frames, payload


def test_assemble_returns_the_exact_payload_of_a_clean_block():
    header, frames, payload = _block()
    assert codec.assemble_payload(header, frames) == payload


@pytest.mark.parametrize("fault, message", [
    (lambda f: f[:2] + f[3:], "data frames"),                 # lost
    (lambda f: f[:3] + [f[2]] + f[3:], "data frames"),       # duplicated
    (lambda f: [f[1], f[0]] + f[2:], "sequence"),            # reordered
    (lambda f: f[:1] + [f[1][:48]] + f[2:], "bytes"),        # wrong length
    (lambda f: f[:1] + [f[1][:10] + bytes([f[1][10] ^ 1]) + f[1][11:]] + f[2:], "CRC"),
    (lambda f: f[:1] + [f[1][:2] + b"\x09" + f[1][3:]] + f[2:], "belongs to block"),
])
def test_assemble_detects_bad_frames(fault, message):
    header, frames, _ = _block()
    with pytest.raises(FrameError, match=message):
        codec.assemble_payload(header, fault(frames))
