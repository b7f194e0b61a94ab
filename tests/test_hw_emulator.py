"""The register-level ADS1115 emulator: timing, averaging, clipping, MUX, RDY and faults."""

import math

import numpy as np
import pytest
from whiskerid.hw import (
    Config,
    EmulatedADS1115,
    FakeClock,
    Recorder,
    decode_conversion,
    encode_config,
    source_from_recording,
    volts_to_code,
)

ADDR = 0x48


@pytest.fixture
def clock():
    return FakeClock()


def make(clock, source=None, **kw):
    return EmulatedADS1115(source, clock=clock.now_ns, sleep=clock.sleep, **kw)


def write_config(emu, cfg):
    word = encode_config(cfg)
    emu.write_i2c_block_data(ADDR, 1, [word >> 8, word & 0xFF])


def read_u16(emu, reg):
    msb, lsb = emu.read_i2c_block_data(ADDR, reg, 2)
    return msb << 8 | lsb


def convert_once(emu, clock, cfg):
    """Start a single-shot conversion, wait it out on the fake clock, return the code."""
    write_config(emu, cfg.replace(os=True, single_shot=True))
    clock.advance(2.0 / cfg.data_rate_sps)
    return decode_conversion(emu.read_i2c_block_data(ADDR, 0, 2))


def test_power_on_registers(clock):
    emu = make(clock)
    assert read_u16(emu, 1) == 0x8583
    assert read_u16(emu, 2) == 0x8000
    assert read_u16(emu, 3) == 0x7FFF
    assert read_u16(emu, 0) == 0


def test_pointer_register_and_byte_access(clock):
    emu = make(clock)
    emu.write_byte(ADDR, 1)  # pointer -> config
    assert emu.read_byte(ADDR) == 0x85
    assert emu.read_i2c_block_data(ADDR, 1, 2) == [0x85, 0x83]
    assert emu.pointer == 1
    # smbus2's word read is little-endian: the chip's big-endian bytes come back swapped.
    assert emu.read_word_data(ADDR, 1) == 0x8385
    emu.write_i2c_block_data(ADDR, 3, [0x12, 0x34])
    emu.write_i2c_block_data(ADDR, 2, [0xAB, 0xCD])
    assert (read_u16(emu, 3), read_u16(emu, 2)) == (0x1234, 0xABCD)
    emu.write_i2c_block_data(ADDR, 0, [0x55, 0x55])  # conversion register is read-only
    assert read_u16(emu, 0) == 0
    assert list(emu.writes) == [(1, b""), (3, b"\x12\x34"), (2, b"\xab\xcd"), (0, b"\x55\x55")]
    with pytest.raises(OSError, match="2 bytes"):
        emu.write_i2c_block_data(ADDR, 1, [1, 2, 3])


def test_os_bit_reads_0_while_converting_and_1_when_done(clock):
    emu = make(clock, lambda t: 0.3)
    write_config(emu, Config(os=True, data_rate_sps=128))
    assert read_u16(emu, 1) & 0x8000 == 0
    clock.advance(1 / 128 - 1e-6)
    assert read_u16(emu, 1) & 0x8000 == 0
    assert read_u16(emu, 0) == 0  # no result yet
    clock.advance(2e-6)
    assert read_u16(emu, 1) == 0x8583  # idle again, the rest of the word as written
    assert decode_conversion(emu.read_i2c_block_data(ADDR, 0, 2)) == volts_to_code(0.3, 2.048)
    assert emu.conversions == 1


def test_writing_os_during_a_conversion_has_no_effect(clock):
    emu = make(clock, lambda t: np.asarray(t) * 0 + 1.0)
    write_config(emu, Config(os=True, data_rate_sps=8))  # 125 ms
    clock.advance(0.1)
    write_config(emu, Config(os=True, data_rate_sps=8))
    clock.advance(0.03)  # 130 ms after the first start: done if it was not restarted
    assert read_u16(emu, 1) & 0x8000
    assert emu.conversions == 1


@pytest.mark.parametrize("clock_error", [-0.10, 0.0, 0.05, 0.10])
def test_oscillator_error_changes_conversion_time(clock, clock_error):
    emu = make(clock, clock_error=clock_error)
    expected = 1 / (128 * (1 + clock_error))
    assert emu.conversion_time_s(128) == pytest.approx(expected, rel=1e-12)
    write_config(emu, Config(os=True, data_rate_sps=128))
    clock.advance(expected - 2e-6)
    assert not read_u16(emu, 1) & 0x8000
    clock.advance(4e-6)
    assert read_u16(emu, 1) & 0x8000
    # Continuous mode: conversions per second follow the oscillator too.
    write_config(emu, Config(single_shot=False, data_rate_sps=128))
    before = emu.conversions
    clock.advance(1.0 + 1e-6)
    read_u16(emu, 0)
    assert emu.conversions - before == math.floor(128 * (1 + clock_error) * (1 + 1e-6))


@pytest.mark.parametrize(
    ("freq_hz", "clock_error"),
    [(5.0, 0.0), (30.0, 0.0), (70.0, 0.0), (100.0, 0.0), (155.0, 0.0), (100.0, 0.1)],
)
def test_conversion_averages_input_first_order_sinc(clock, freq_hz, clock_error):
    amp = 1.0

    def sine(t):
        return amp * np.sin(2 * np.pi * freq_hz * np.asarray(t) + 0.3)

    emu = make(clock, sine, clock_error=clock_error)
    write_config(emu, Config(mux="AIN0_GND", single_shot=False, data_rate_sps=128))
    period = emu.conversion_time_s()
    n = 300
    codes = np.empty(n)
    for j in range(n):
        clock.advance_to_ns(math.ceil((j + 1) * period * 1e9) + 1)  # just after window j
        codes[j] = decode_conversion(emu.read_i2c_block_data(ADDR, 0, 2))
    t_mid = (np.arange(n) + 0.5) * period
    w = 2 * np.pi * freq_hz * t_mid
    design = np.column_stack([np.sin(w), np.cos(w), np.ones(n)])
    coef, *_ = np.linalg.lstsq(design, codes * (2.048 / 32768), rcond=None)
    ratio = math.hypot(coef[0], coef[1]) / amp
    expected = abs(np.sinc(freq_hz * period))  # np.sinc(x) = sin(pi x) / (pi x)
    assert ratio == pytest.approx(expected, rel=0.02)
    # The response really is attenuated where sinc says so (not a trivially passing check).
    if freq_hz * period > 0.5:
        assert ratio < 0.7


@pytest.mark.parametrize(
    ("volts", "raw"),
    [
        (3.0, b"\x7f\xff"),
        (2.048, b"\x7f\xff"),
        (-3.0, b"\x80\x00"),
        (-2.048, b"\x80\x00"),
        (-6.25e-5, b"\xff\xff"),
        (6.25e-5, b"\x00\x01"),
        (0.0, b"\x00\x00"),
        (1.0, b"\x3e\x80"),
    ],
)
def test_pga_clipping_and_twos_complement_storage(clock, volts, raw):
    emu = make(clock, lambda t: volts)
    convert_once(emu, clock, Config(mux="AIN0_GND", fsr_v=2.048))
    assert emu.reads[-1] == (0, raw)


@pytest.mark.parametrize(
    ("mux", "volts"),
    [
        ("AIN0_AIN1", -0.1),
        ("AIN0_AIN3", -0.3),
        ("AIN1_AIN3", -0.2),
        ("AIN2_AIN3", -0.1),
        ("AIN0_GND", 0.1),
        ("AIN1_GND", 0.2),
        ("AIN2_GND", 0.3),
        ("AIN3_GND", 0.4),
    ],
)
def test_mux_selects_inputs(clock, mux, volts):
    emu = make(clock, [lambda t: 0.1, lambda t: 0.2, lambda t: 0.3, lambda t: 0.4])
    code = convert_once(emu, clock, Config(mux=mux, fsr_v=0.512))
    assert code == volts_to_code(volts, 0.512)


def test_unconnected_inputs_read_zero(clock):
    emu = make(clock, [None, lambda t: 0.2])
    assert convert_once(emu, clock, Config(mux="AIN0_GND")) == 0
    assert convert_once(emu, clock, Config(mux="AIN2_GND")) == 0
    assert convert_once(emu, clock, Config(mux="AIN1_GND")) == volts_to_code(0.2, 2.048)
    with pytest.raises(ValueError, match="4 inputs"):
        make(clock, [None] * 5)


def test_noise_rms_and_seed(clock):
    cfg = Config(mux="AIN0_GND", fsr_v=0.256, data_rate_sps=860)

    def run(seed):
        emu = make(clock, lambda t: 0.0, noise_v=1e-3, seed=seed)
        return np.array([convert_once(emu, clock, cfg) for _ in range(2000)]) * (0.256 / 32768)

    a, b, c = run(1), run(1), run(2)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.std(a) == pytest.approx(1e-3, rel=0.06)
    assert abs(np.mean(a)) < 1e-4


def rdy_setup(emu, comp_queue=1):
    emu.write_i2c_block_data(ADDR, 3, [0x80, 0x00])
    emu.write_i2c_block_data(ADDR, 2, [0x00, 0x00])
    return Config(comp_queue=comp_queue, data_rate_sps=128)


def test_rdy_single_shot_asserts_at_end_until_next_start(clock):
    emu = make(clock, lambda t: 0.1)
    cfg = rdy_setup(emu)
    write_config(emu, cfg.replace(os=True))
    assert not emu.rdy() and emu.alert_level()  # active low: idle high
    clock.advance(1 / 128 + 1e-6)
    assert emu.rdy() and not emu.alert_level()
    clock.advance(0.1)
    assert emu.rdy()  # stays asserted in single-shot mode
    write_config(emu, cfg.replace(os=True))
    assert not emu.rdy()
    write_config(emu, cfg.replace(comp_polarity="active_high"))
    clock.advance(0.01)
    assert emu.rdy() and emu.alert_level()


def test_rdy_continuous_pulses_8us_per_conversion(clock):
    emu = make(clock, lambda t: 0.1)
    write_config(emu, rdy_setup(emu).replace(single_shot=False))
    period_ns = 1e9 / 128
    pulses = 0
    for j in range(1, 6):
        clock.advance_to_ns(round(j * period_ns) + 2000)  # 2 us after conversion j ended
        pulses += emu.rdy()
        clock.advance(10e-6)  # 12 us after: the ~8 us pulse is over
        assert not emu.rdy()
    assert pulses == 5


@pytest.mark.parametrize(
    ("hi", "lo", "queue"), [(0x7FFF, 0x8000, 1), (0x8000, 0x0000, None), (0x8000, 0x8000, 1)]
)
def test_rdy_needs_thresholds_and_comparator_enabled(clock, hi, lo, queue):
    emu = make(clock)
    emu.write_i2c_block_data(ADDR, 3, [hi >> 8, hi & 0xFF])
    emu.write_i2c_block_data(ADDR, 2, [lo >> 8, lo & 0xFF])
    convert_once(emu, clock, Config(comp_queue=queue))
    assert not emu.rdy()


def test_fail_next_nacks_then_recovers(clock):
    emu = make(clock)
    emu.fail_next(2)
    for _ in range(2):
        with pytest.raises(OSError) as info:
            emu.read_i2c_block_data(ADDR, 1, 2)
        assert info.value.errno == 121
    assert emu.read_i2c_block_data(ADDR, 1, 2) == [0x85, 0x83]
    emu.fail_next(1, exc=OSError(110, "Connection timed out"))
    with pytest.raises(OSError, match="timed out"):
        emu.write_i2c_block_data(ADDR, 1, [0x85, 0x83])
    assert list(emu.writes) == []


def test_wrong_address_nacks(clock):
    emu = make(clock, address=0x49)
    with pytest.raises(OSError, match="0x48") as info:
        emu.read_i2c_block_data(0x48, 1, 2)
    assert info.value.errno == 121
    assert emu.read_i2c_block_data(0x49, 1, 2) == [0x85, 0x83]


def test_read_delay_stuck_output_and_never_ready(clock):
    emu = make(clock, lambda t: 0.5)
    emu.read_delay_s = 3e-3
    t0 = clock.now_ns()
    emu.read_i2c_block_data(ADDR, 1, 2)
    assert clock.now_ns() - t0 == 3_000_000
    emu.read_delay_s = 0.0
    emu.stuck_code = -2
    assert convert_once(emu, clock, Config()) == -2
    emu.stuck_code = None
    assert convert_once(emu, clock, Config()) == volts_to_code(0.5, 2.048)
    emu.never_ready = True
    write_config(emu, Config(os=True))
    clock.advance(10.0)
    assert not read_u16(emu, 1) & 0x8000


def test_close_and_context_manager(clock):
    with make(clock) as emu:
        assert emu.read_byte(ADDR) == 0
    assert emu.closed
    with pytest.raises(OSError, match="closed"):
        emu.read_byte(ADDR)


def test_source_from_recording_interpolates(clock):
    src = source_from_recording([0.0, 1.0, 2.0], [0.0, 10.0, 0.0])
    assert src(0.5) == 5.0
    np.testing.assert_allclose(src(np.array([0.25, 1.5, 3.0])), [2.5, 5.0, 0.0])
    loop = source_from_recording([0.0, 1.0, 2.0], [0.0, 10.0, 0.0], periodic=True)
    assert loop(2.5) == pytest.approx(5.0)
    assert loop(4.25) == pytest.approx(2.5)
    with pytest.raises(ValueError, match="increasing"):
        source_from_recording([0.0, 0.0, 1.0], [1.0, 2.0, 3.0])
    # Through the emulator: a slow ramp recording reads back as its window average.
    emu = make(clock, source_from_recording([0.0, 10.0], [0.0, 1.0]))
    clock.advance(5.0)
    code = convert_once(emu, clock, Config(mux="AIN0_GND", data_rate_sps=860))
    assert code == volts_to_code(0.1 * (5.0 + 0.5 / 860), 2.048)


def test_source_from_a_recording_file_in_volts_not_codes(tmp_path):
    with Recorder(tmp_path / "v.csv", columns=("a", "b")) as rec:
        for t in (0.0, 1.0, 2.0):
            rec.write(t, 1.0 + t, 10.0 * t)
    assert source_from_recording(tmp_path / "v.csv")(0.5) == 1.5
    assert source_from_recording(tmp_path / "v.csv", column="b")(1.5) == 15.0
    with Recorder(tmp_path / "c.csv", columns=("adc",), units="code") as rec:
        rec.write(0.0, 100)
        rec.write(1.0, 200)
    with pytest.raises(ValueError, match=r"c\.csv: units are 'code'"):
        source_from_recording(tmp_path / "c.csv")


def test_transfer_log_is_bounded(clock):
    emu = make(clock, log_limit=5)
    for _ in range(20):
        emu.read_i2c_block_data(ADDR, 1, 2)
    assert len(emu.reads) == 5


def test_fake_clock():
    c = FakeClock(start_ns=5)
    c.sleep(1e-3)
    c.sleep(-1.0)
    assert c.now_ns() == 1_000_005 and c.sleeps == 2
    c.advance_to_ns(10)
    assert c.now_ns() == 1_000_005
    with pytest.raises(ValueError):
        c.advance(-1.0)
