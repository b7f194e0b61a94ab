"""ADS1115 config codec, conversion decoding, PGA scaling and the driver (through the emulator)."""

import subprocess
import sys

import numpy as np
import pytest
import whiskerid.hw as hw
from whiskerid.hw import (
    ADS1115,
    Config,
    ConversionTimeout,
    EmulatedADS1115,
    FakeClock,
    I2CError,
    code_to_volts,
    decode_config,
    decode_conversion,
    encode_config,
    volts_to_code,
)

# Field masks typed in from the datasheet (table 8), independently of the implementation.
MASKS = {
    "os": 0x8000,
    "mux": 0x7000,
    "fsr_v": 0x0E00,
    "single_shot": 0x0100,
    "data_rate_sps": 0x00E0,
    "comp_mode": 0x0010,
    "comp_polarity": 0x0008,
    "comp_latching": 0x0004,
    "comp_queue": 0x0003,
}

# (field, human value, bits in place) from the datasheet.
FIELD_CASES = [
    ("os", True, 0x8000),
    ("os", False, 0x0000),
    ("mux", "AIN0_AIN1", 0b000 << 12),
    ("mux", "AIN0_AIN3", 0b001 << 12),
    ("mux", "AIN1_AIN3", 0b010 << 12),
    ("mux", "AIN2_AIN3", 0b011 << 12),
    ("mux", "AIN0_GND", 0b100 << 12),
    ("mux", "AIN1_GND", 0b101 << 12),
    ("mux", "AIN2_GND", 0b110 << 12),
    ("mux", "AIN3_GND", 0b111 << 12),
    ("fsr_v", 6.144, 0b000 << 9),
    ("fsr_v", 4.096, 0b001 << 9),
    ("fsr_v", 2.048, 0b010 << 9),
    ("fsr_v", 1.024, 0b011 << 9),
    ("fsr_v", 0.512, 0b100 << 9),
    ("fsr_v", 0.256, 0b101 << 9),
    ("single_shot", True, 0x0100),
    ("single_shot", False, 0x0000),
    ("data_rate_sps", 8, 0b000 << 5),
    ("data_rate_sps", 16, 0b001 << 5),
    ("data_rate_sps", 32, 0b010 << 5),
    ("data_rate_sps", 64, 0b011 << 5),
    ("data_rate_sps", 128, 0b100 << 5),
    ("data_rate_sps", 250, 0b101 << 5),
    ("data_rate_sps", 475, 0b110 << 5),
    ("data_rate_sps", 860, 0b111 << 5),
    ("comp_mode", "traditional", 0x00),
    ("comp_mode", "window", 0x10),
    ("comp_polarity", "active_low", 0x00),
    ("comp_polarity", "active_high", 0x08),
    ("comp_latching", False, 0x00),
    ("comp_latching", True, 0x04),
    ("comp_queue", 1, 0b00),
    ("comp_queue", 2, 0b01),
    ("comp_queue", 4, 0b10),
    ("comp_queue", None, 0b11),
]


@pytest.mark.parametrize(("field", "value", "bits"), FIELD_CASES)
def test_config_field_encodes_to_datasheet_bits(field, value, bits):
    word = encode_config(Config(**{field: value}))
    assert word & MASKS[field] == bits
    # Only that field moved away from the power-on word.
    assert word & ~MASKS[field] & 0xFFFF == 0x8583 & ~MASKS[field]
    decoded = decode_config((0x8583 & ~MASKS[field]) | bits)
    assert getattr(decoded, field) == value


def test_power_on_word_decodes_to_datasheet_defaults():
    cfg = decode_config(0x8583)
    assert cfg.os is True
    assert cfg.mux == "AIN0_AIN1"
    assert cfg.fsr_v == 2.048
    assert cfg.single_shot is True
    assert cfg.data_rate_sps == 128
    assert cfg.comp_mode == "traditional"
    assert cfg.comp_polarity == "active_low"
    assert cfg.comp_latching is False
    assert cfg.comp_queue is None
    assert cfg == Config() == hw.POWER_ON_CONFIG
    assert encode_config(cfg) == 0x8583


def test_every_meaningful_word_round_trips():
    words = [w for w in range(0x10000) if (w >> 9) & 0b111 <= 0b101]
    assert len(words) == 0xC000
    assert all(encode_config(decode_config(w)) == w for w in words)


@pytest.mark.parametrize("pga", [0b110, 0b111])
def test_pga_aliases_decode_to_0256_and_reencode_canonically(pga):
    word = 0x8583 & ~0x0E00 | pga << 9
    cfg = decode_config(word)
    assert cfg.fsr_v == 0.256
    assert encode_config(cfg) == 0x8583 & ~0x0E00 | 0b101 << 9


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"mux": "AIN4_GND"}, "'AIN0_GND'"),
        ({"mux": "ain0_gnd"}, "Config.mux"),
        ({"fsr_v": 3.3}, "4.096"),
        ({"data_rate_sps": 200}, "250"),
        ({"data_rate_sps": 200}, "data_rate_sps"),
        ({"comp_mode": "hysteresis"}, "'window'"),
        ({"comp_polarity": "low"}, "'active_low'"),
        ({"comp_queue": 3}, "comp_queue"),
        ({"comp_queue": True}, "comp_queue"),
        ({"single_shot": 1}, "single_shot"),
        ({"os": None}, "Config.os"),
    ],
)
def test_bad_config_values_name_the_field_and_choices(kwargs, needle):
    with pytest.raises(ValueError, match=needle.replace("(", r"\(")):
        Config(**kwargs)


@pytest.mark.parametrize("word", [-1, 0x10000, 1.5, "0x8583", True])
def test_decode_config_rejects_non_16_bit_words(word):
    with pytest.raises(ValueError, match=r"0\.\.0xFFFF"):
        decode_config(word)


def test_config_normalises_fsr_to_table_value():
    cfg = Config(fsr_v=4.096 + 1e-12)
    assert cfg.fsr_v == 4.096
    assert cfg.lsb_v == 4.096 / 32768
    assert cfg.replace(data_rate_sps=860).conversion_time_s == 1 / 860


@pytest.mark.parametrize(
    ("data", "code"),
    [
        ([0x7F, 0xFF], 32767),
        ([0x80, 0x00], -32768),
        ([0xFF, 0xFF], -1),
        ([0x00, 0x01], 1),
        ([0x00, 0x00], 0),
        ([0x12, 0x34], 0x1234),
        ([0xFE, 0xDC], 0xFEDC - 0x10000),
    ],
)
def test_conversion_register_is_big_endian_twos_complement(data, code):
    assert decode_conversion(data) == code


def test_pga_scaling_is_exact():
    # FSR / 32768 per code, with no rounding: the products below are exact in binary.
    assert code_to_volts(32767, 4.096) == 32767 * 0.000125
    assert code_to_volts(-32768, 2.048) == -2.048
    assert code_to_volts(1, 0.256) == 7.8125e-6
    assert code_to_volts(-1, 6.144) == -0.0001875
    assert code_to_volts(16384, 1.024) == 0.512
    codes = np.arange(-32768, 32768)
    for fsr in (6.144, 4.096, 2.048, 1.024, 0.512, 0.256):
        volts = code_to_volts(codes, fsr)
        np.testing.assert_array_equal(volts, codes * (fsr / 32768))
        np.testing.assert_array_equal(volts_to_code(volts, fsr), codes)


def test_volts_to_code_rounds_and_clips():
    assert volts_to_code(1.0, 2.048) == 16000
    assert isinstance(volts_to_code(1.0, 2.048), int)
    assert volts_to_code(0.4 * 6.25e-5, 2.048) == 0
    assert volts_to_code(0.6 * 6.25e-5, 2.048) == 1
    assert volts_to_code(2.048, 2.048) == 0x7FFF
    assert volts_to_code(5.0, 2.048) == 0x7FFF
    assert volts_to_code(-2.048, 2.048) == -0x8000
    assert volts_to_code(-5.0, 2.048) == -0x8000
    with pytest.raises(ValueError, match="full-scale range"):
        volts_to_code(1.0, 3.3)


# --- driver ------------------------------------------------------------------------------------


@pytest.fixture
def clock():
    return FakeClock(start_ns=10**9)


def make_emulator(clock, source=lambda t: 1.0, **kw):
    return EmulatedADS1115(source, clock=clock.now_ns, sleep=clock.sleep, **kw)


def make_driver(clock, emu, **kw):
    return ADS1115(emu, clock=clock.now_ns, sleep=clock.sleep, **kw)


def test_single_shot_read_writes_exact_config_bytes(clock):
    emu = make_emulator(clock)
    drv = make_driver(clock, emu)
    t_start = clock.now_ns()
    assert drv.read_single() == 8000  # 1.0 V / (4.096 V / 32768)
    # OS=1 MUX=100 (AIN0_GND) PGA=001 (4.096) MODE=1 DR=110 (475) COMP 0 0 0 11 -> 0xC3C3.
    assert list(emu.writes) == [(1, b"\xc3\xc3")]
    # Polled the OS bit, then read the conversion register; every read a 2-byte block.
    regs = [r for r, _ in emu.reads]
    assert regs[-1] == 0 and set(regs[:-1]) == {1}
    assert all(len(data) == 2 for _, data in emu.reads)
    # It did not return before the conversion could have finished (1/475 s).
    assert clock.now_ns() - t_start >= 1e9 / 475
    assert drv.stats.reads == 1 and drv.stats.retries == 0
    assert drv.read_volts() == 1.0


def test_read_with_mux_override_and_custom_config(clock):
    emu = make_emulator(clock, [lambda t: 0.5, lambda t: 0.25, None, lambda t: -0.125])
    cfg = Config(mux="AIN0_GND", fsr_v=1.024, data_rate_sps=860)
    drv = make_driver(clock, emu, address=0x48, config=cfg)
    assert drv.read_single() == volts_to_code(0.5, 1.024)
    assert drv.read_single(mux="AIN1_AIN3") == volts_to_code(0.375, 1.024)
    # OS=1 MUX=010 PGA=011 MODE=1 DR=111 COMP=00011 -> 0xA7E3.
    assert emu.writes[-1] == (1, b"\xa7\xe3")


def test_ready_pin_mode_programs_thresholds_and_does_not_poll_config(clock):
    emu = make_emulator(clock, lambda t: -0.5)
    drv = make_driver(clock, emu, ready_pin=emu.rdy)
    assert drv.read_single() == -4000
    assert drv.read_single() == -4000
    # Hi_thresh = 0x8000, Lo_thresh = 0x0000 once; config with COMP_QUE = 00 (not 11).
    assert list(emu.writes) == [
        (3, b"\x80\x00"),
        (2, b"\x00\x00"),
        (1, b"\xc3\xc0"),
        (1, b"\xc3\xc0"),
    ]
    assert [r for r, _ in emu.reads] == [0, 0]


@pytest.mark.parametrize("use_pin", [False, True])
def test_never_ready_raises_conversion_timeout_within_timeout(clock, use_pin):
    emu = make_emulator(clock)
    emu.never_ready = True
    drv = make_driver(clock, emu, timeout_s=0.01, ready_pin=emu.rdy if use_pin else None)
    t0 = clock.now_ns()
    with pytest.raises(ConversionTimeout, match="conversion-ready") as info:
        drv.read_single()
    assert isinstance(info.value, TimeoutError)
    elapsed = (clock.now_ns() - t0) * 1e-9
    assert 0.01 <= elapsed <= 0.01 + 1e-6
    assert drv.stats.timeouts == 1 and drv.stats.reads == 0


def test_default_timeout_scales_with_data_rate(clock):
    drv = make_driver(clock, make_emulator(clock), config=Config(data_rate_sps=8))
    assert drv.timeout_s == pytest.approx(2 / 8 + 5e-3)
    drv.config = Config(data_rate_sps=860)
    assert drv.timeout_s == pytest.approx(2 / 860 + 5e-3)


def test_transient_i2c_errors_are_retried(clock):
    emu = make_emulator(clock)
    drv = make_driver(clock, emu, retry_delay_s=1e-3)
    emu.fail_next(2)
    t0 = clock.now_ns()
    assert drv.read_single() == 8000
    assert drv.stats.retries == 2 and drv.stats.i2c_errors == 2 and drv.stats.reads == 1
    assert list(emu.writes) == [(1, b"\xc3\xc3")]  # the failed attempts never reached the chip
    assert clock.now_ns() - t0 >= 2e6 + 1e9 / 475  # two retry delays, then the conversion


def test_exhausted_retries_raise_i2c_error(clock):
    emu = make_emulator(clock)
    drv = make_driver(clock, emu, retries=3)
    emu.fail_next(10)
    with pytest.raises(I2CError, match="4 attempt") as info:
        drv.read_single()
    assert isinstance(info.value, OSError)
    assert isinstance(info.value.__cause__, OSError) and info.value.__cause__.errno == 121
    assert drv.stats.i2c_errors == 4 and drv.stats.retries == 3 and drv.stats.reads == 0


def test_wrong_address_is_an_i2c_error(clock):
    drv = make_driver(clock, make_emulator(clock), address=0x49, retries=0)
    with pytest.raises(I2CError, match="0x49"):
        drv.read_single()


def test_continuous_mode_reads_latest_back_to_back_conversion(clock):
    emu = make_emulator(clock, lambda t: 2.0 * np.asarray(t))  # a 2 V/s ramp
    cfg = hw.DEFAULT_CONFIG.replace(single_shot=False, fsr_v=6.144)
    drv = make_driver(clock, emu, config=cfg)
    t_start = emu.time_s()  # conversions run back to back from the config write
    drv.read()
    # OS=0 MUX=100 PGA=000 MODE=0 DR=110 COMP=00011 -> 0x40C3.
    assert list(emu.writes) == [(1, b"\x40\xc3")]
    for dt in (0.0123, 0.5, 1.0):
        clock.advance(dt)
        code = drv.read()
        period = 1 / 475
        j = int((emu.time_s() - t_start) / period) - 1  # latest finished conversion
        mid = t_start + (j + 0.5) * period
        assert abs(code - volts_to_code(2.0 * mid, 6.144)) <= 1
    assert len(emu.writes) == 1  # no more config writes while running
    drv.stop()
    assert emu.writes[-1] == (1, b"\x41\xc3")


def test_driver_rejects_bad_arguments(clock):
    emu = make_emulator(clock)
    with pytest.raises(ValueError, match="address"):
        ADS1115(emu, 0x80)
    with pytest.raises(ValueError, match="retries"):
        ADS1115(emu, retries=-1)
    with pytest.raises(ValueError, match=r"0\.\.0xFFFF"):
        ADS1115(emu).write_register(1, 0x10000)


def test_open_bus_without_smbus2_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "smbus2", None)  # makes "import smbus2" fail
    with pytest.raises(ImportError, match=r'pip install "whiskerid\[pi\]"'):
        hw.open_bus(1)


def test_open_bus_opens_the_numbered_bus(monkeypatch):
    import smbus2

    opened = []
    monkeypatch.setattr(smbus2, "SMBus", lambda n: opened.append(n) or f"bus{n}")
    assert hw.open_bus(1) == "bus1"
    assert opened == [1]


_DRIVER_SIDE = """
import sys, time
t0 = time.perf_counter()
import whiskerid.hw
from whiskerid.hw import (ADS1115, EmulatedADS1115, FakeClock, Recorder, Sampler,
                          read_recording_csv, source_from_recording)
elapsed = time.perf_counter() - t0
heavy = sorted({m.split(".")[0] for m in sys.modules} & {"jax", "jaxlib", "equinox", "scipy"})
print(heavy, elapsed, "run_stream" in dir(whiskerid.hw))
"""


def test_driver_side_imports_without_jax():
    # A fresh interpreter: in this one the test suite has imported JAX long ago.
    out = subprocess.run([sys.executable, "-c", _DRIVER_SIDE], capture_output=True, text=True,
                         check=True).stdout.split()  # fmt: skip
    heavy, seconds, listed = " ".join(out[:-2]), out[-2], out[-1]
    assert heavy == "[]", f"importing the driver side loaded {heavy}"
    assert listed == "True"  # the stream loop's names are there, loaded on first use
    print(f"import whiskerid.hw and the driver classes: {float(seconds):.3f} s")
