"""DES 70/10 protocol layer: CRC, frames, words, flags and the incremental decoder (pure bytes)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from skidsteer_power.des.errors import DesCrcError, DesFrameError, DesLinkError
from skidsteer_power.des.kinematics import side_speeds, twist_to_motor_rpm, unwrap_counter
from skidsteer_power.des.protocol import (
    MAX_WORDS,
    REPLY_OPCODE,
    DesConfig,
    DesErrorFlags,
    Frame,
    FrameDecoder,
    FrameStart,
    OpCode,
    Status,
    command_bytes,
    crc16_xmodem,
    encode_body,
    frame_crc,
    join_lword,
    split_lword,
    to_int16,
    to_word,
)
from skidsteer_power.errors import ConfigError

words_strategy = st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=MAX_WORDS).map(tuple)


def maxon_wordwise_crc(words: list[int]) -> int:
    """maxon's CRC routine (EPOS2/DES communication guides), transcribed: word-wise, MSB first,
    augmented by the caller with one 0x0000 word."""
    crc = 0
    for word in words:
        shifter = 0x8000
        while shifter:
            carry = crc & 0x8000
            crc = (crc << 1) & 0xFFFF
            if word & shifter:
                crc += 1
            if carry:
                crc ^= 0x1021
            shifter >>= 1
    return crc


def test_crc_standard_check_value() -> None:
    # CRC-16/XMODEM catalogue check value: 0x31C3 for ASCII "123456789" (des-protocol.md, CRC section).
    assert crc16_xmodem(b'123456789') == 0x31C3


def test_crc_worked_example_read_sys_status() -> None:
    # des-protocol.md worked example: ReadSysStatus = 01 | 00 00 00, CRC 0x76B4 sent as B4 76.
    assert frame_crc(OpCode.READ_SYS_STATUS, (0,)) == 0x76B4
    assert encode_body(OpCode.READ_SYS_STATUS, (0,)) == bytes.fromhex('000000B476')


@given(st.integers(0, 0xFF), words_strategy)
def test_direct_crc_equals_maxon_wordwise_routine(opcode: int, words: tuple[int, ...]) -> None:
    augmented = [(opcode << 8) | (len(words) - 1), *words, 0x0000]
    assert frame_crc(opcode, words) == maxon_wordwise_crc(augmented)


def test_body_layout_little_endian_words_and_crc() -> None:
    body = encode_body(OpCode.SET_VELOCITY, (to_word(-1000),))
    # len-1 = 0; -1000 = 0xFC18 sent low byte first; CRC over 21 00 FC 18 (words high byte first).
    crc = crc16_xmodem(bytes.fromhex('2100FC18'))
    assert body == bytes((0x00, 0x18, 0xFC, crc & 0xFF, crc >> 8))


def test_empty_and_oversized_frames_are_refused() -> None:
    with pytest.raises(ValueError, match=r'1\.\.8 words'):
        encode_body(OpCode.READ_ERROR, ())
    with pytest.raises(ValueError, match=r'1\.\.8 words'):
        encode_body(OpCode.READ_ERROR, (0,) * (MAX_WORDS + 1))


@pytest.mark.parametrize(('value', 'word'), [(0, 0), (1, 1), (-1, 0xFFFF), (-32768, 0x8000), (65535, 0xFFFF)])
def test_word_conversion(value: int, word: int) -> None:
    assert to_word(value) == word


@pytest.mark.parametrize('value', [-32769, 65536])
def test_word_out_of_range(value: int) -> None:
    with pytest.raises(ValueError, match='16-bit'):
        to_word(value)


@given(st.integers(-0x8000, 0x7FFF))
def test_int16_round_trip(value: int) -> None:
    assert to_int16(to_word(value)) == value


@pytest.mark.parametrize('low_first', [True, False])
@given(value=st.integers(-0x8000_0000, 0x7FFF_FFFF))
def test_lword_round_trip_in_both_orders(low_first: bool, value: int) -> None:
    config = DesConfig(lword_low_word_first=low_first)
    words = split_lword(value, config)
    assert join_lword(words, config, signed=True) == value


def test_lword_order_is_the_configured_one() -> None:
    assert split_lword(0x12345678, DesConfig(lword_low_word_first=True)) == (0x5678, 0x1234)
    assert split_lword(0x12345678, DesConfig(lword_low_word_first=False)) == (0x1234, 0x5678)


def test_config_rejects_unknown_baud_and_current_source() -> None:
    # A configuration error is the project's ConfigError (one line at the CLI), not a bare ValueError.
    with pytest.raises(ConfigError, match='baud rate'):
        DesConfig(baudrate=12345)
    with pytest.raises(ConfigError, match='current_source'):
        DesConfig(current_source='guess')


def test_status_word_flags_and_power_stage() -> None:
    # Bits 9 (error), 10 (enabled), 15 (power stage '10' = on): des-protocol.md, status word bits.
    status = Status((1 << 9) | (1 << 10) | (1 << 15))
    assert Status.ERROR in status and Status.ENABLED in status
    assert status.power_stage == 'on'
    assert Status(1 << 14).power_stage == 'refresh'
    assert Status(0).power_stage == 'off'
    assert 'ENABLED' in status.describe()


def test_error_word_flags_describe_unknown_bits() -> None:
    errors = DesErrorFlags((1 << 4) | (1 << 15) | (1 << 9))  # bit 9 has no label in any source
    assert DesErrorFlags.OVER_CURRENT in errors
    assert errors.describe() == 'OVER_CURRENT, ANY, 0x0200'
    assert DesErrorFlags(0).describe() == 'none'


def test_command_bytes_of_a_poll() -> None:
    # ReadVelocityIsMust: opcode, 'O', [len-1, 1 word, CRC] = 5 bytes, 'O';
    # then 0x00, 'O', [len-1, 2 words, CRC] = 7 bytes, 'O'.
    assert command_bytes(OpCode.READ_VELOCITY_IS_MUST, 1, 2) == 1 + 1 + 5 + 1 + 1 + 1 + 7 + 1
    assert command_bytes(OpCode.SET_VELOCITY, 1, 0) == 8


# -- decoder ------------------------------------------------------------------------------------


def reply(words: tuple[int, ...]) -> bytes:
    return bytes((REPLY_OPCODE,)) + encode_body(REPLY_OPCODE, words)


def decode_all(decoder: FrameDecoder) -> tuple[list[object], list[DesLinkError]]:
    events: list[object] = []
    errors: list[DesLinkError] = []
    while True:
        try:
            event = decoder.next_event()
        except DesLinkError as err:
            errors.append(err)
            continue
        if event is None:
            return events, errors
        events.append(event)


@pytest.mark.parametrize('op', list(OpCode))
def test_decoder_round_trip_every_command(op: OpCode) -> None:
    decoder = FrameDecoder(frozenset(int(o) for o in OpCode))
    decoder.feed(bytes((op,)) + encode_body(op, (1, 0xBEEF)))
    events, errors = decode_all(decoder)
    assert errors == []
    assert events == [FrameStart(op), Frame(op, (1, 0xBEEF))]


def test_decoder_waits_for_a_split_frame() -> None:
    data = reply((0x1234, 0x5678))
    decoder = FrameDecoder()
    decoder.feed(data[:4])
    assert decoder.next_event() == FrameStart(0)
    assert decoder.next_event() is None
    assert decoder.needed == len(data) - 4
    decoder.feed(data[4:])
    assert decoder.next_event() == Frame(0, (0x1234, 0x5678))


def test_decoder_skips_garbage_before_a_reply() -> None:
    decoder = FrameDecoder()
    decoder.feed(b'\xff\x4f\x13' + reply((7,)))
    events, errors = decode_all(decoder)
    assert errors == []
    assert events == [FrameStart(0), Frame(0, (7,))]
    assert decoder.discarded == 3


def test_decoder_reports_crc_error_then_resynchronizes() -> None:
    bad = bytearray(reply((42,)))
    bad[-1] ^= 0x55
    decoder = FrameDecoder()
    decoder.feed(bytes(bad) + reply((43,)))
    events, errors = decode_all(decoder)
    assert [type(e) for e in errors] == [DesCrcError]
    assert events[-1] == Frame(0, (43,))


def test_decoder_rejects_impossible_length_then_resynchronizes() -> None:
    decoder = FrameDecoder()
    decoder.feed(b'\x00\xc8' + reply((9,)))  # len-1 = 200: no DES frame is that long
    events, errors = decode_all(decoder)
    assert [type(e) for e in errors] == [DesFrameError]
    assert Frame(0, (9,)) in events


@settings(max_examples=300)
@given(st.binary(max_size=300), st.lists(st.integers(1, 40), max_size=20))
def test_decoder_fuzz_only_protocol_errors_and_always_ends(data: bytes, chunk_sizes: list[int]) -> None:
    decoder = FrameDecoder(frozenset(int(o) for o in OpCode) | {REPLY_OPCODE})
    position, calls = 0, 0
    chunks = [*chunk_sizes, len(data)]
    for size in chunks:
        decoder.feed(data[position : position + size])
        position += size
        while True:
            calls += 1
            assert calls <= 2 * len(data) + len(chunks) + 1, 'decoder did not consume input'
            try:
                if decoder.next_event() is None:
                    break
            except (DesCrcError, DesFrameError):
                continue
    assert decoder.pending <= 1 + 2 * MAX_WORDS + 2


garbage = st.binary(max_size=20).map(lambda b: bytes(x for x in b if x != REPLY_OPCODE))


@given(st.lists(st.tuples(garbage, words_strategy), min_size=1, max_size=6), garbage)
def test_decoder_recovers_every_frame_between_garbage(
    parts: list[tuple[bytes, tuple[int, ...]]], tail: bytes
) -> None:
    stream = b''.join(g + reply(w) for g, w in parts) + tail
    decoder = FrameDecoder()
    decoder.feed(stream)
    events, errors = decode_all(decoder)
    assert errors == []
    assert [e.words for e in events if isinstance(e, Frame)] == [w for _, w in parts]


# -- kinematics ---------------------------------------------------------------------------------


def test_side_speeds_rep103() -> None:
    # v = 1 m/s, yaw rate +0.5 rad/s (left turn), tread 0.4 m: v_l = 1 - 0.1, v_r = 1 + 0.1.
    assert side_speeds(1.0, 0.5, 0.4) == pytest.approx((0.9, 1.1))


def test_twist_to_motor_rpm_hand_calculation() -> None:
    # 0.2 m/s straight, r = 0.1 m, G = 12: axle 2 rad/s, motor 24 rad/s = 229.18 rpm (24 * 60 / 2 pi).
    left, right = twist_to_motor_rpm(0.2, 0.0, tread_m=0.4, drive_radius_m=0.1, gear_ratio=12, max_rpm=4000)
    assert left == pytest.approx(229.183, abs=1e-3)
    assert right == pytest.approx(left)


def test_twist_to_motor_rpm_saturation_keeps_the_ratio() -> None:
    left, right = twist_to_motor_rpm(3.0, 5.0, tread_m=0.4, drive_radius_m=0.1, gear_ratio=12, max_rpm=1000)
    # unsaturated sides 2.0 and 4.0 m/s: right hits the limit, left keeps half of it.
    assert right == pytest.approx(1000.0)
    assert left == pytest.approx(500.0)


@pytest.mark.parametrize(
    ('previous', 'current', 'expected', 'delta'),
    [
        (100, 300, 200.0, 200),
        (65000, 500, 1000.0, 1036),  # forward through the wrap: 65536 - 65000 + 500
        (500, 65000, -1000.0, -1036),  # backward through the wrap
        (0, 30000, 95536.0, 95536),  # more than a whole wrap between readings: 30000 + 65536
    ],
)
def test_unwrap_counter(previous: int, current: int, expected: float, delta: int) -> None:
    assert unwrap_counter(previous, current, expected) == delta
