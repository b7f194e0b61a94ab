"""ADS1115 datasheet facts shared by the signal-level ADC model and the ``hw`` driver.

Source: TI ADS111x datasheet (SBAS444), section 9.6 "Register Map". The data-rate table
matches Adafruit ADS1x15's ``_ADS1115_CONFIG_DR`` (``101 = 250``, ``110 = 475``,
``111 = 860`` SPS); some other libraries' tables are wrong.
"""

from types import MappingProxyType

# Address pointer register values (datasheet table 6).
REG_CONVERSION = 0x00
REG_CONFIG = 0x01
REG_LO_THRESH = 0x02
REG_HI_THRESH = 0x03

#: Config register value after power-on reset.
CONFIG_POWER_ON = 0x8583

#: Default I2C address (ADDR pin to GND); 0x49 VDD, 0x4A SDA, 0x4B SCL.
I2C_ADDRESSES = (0x48, 0x49, 0x4A, 0x4B)

#: Data rate field (bits 7:5) -> samples per second.
DATA_RATE_SPS = MappingProxyType(
    {0b000: 8, 0b001: 16, 0b010: 32, 0b011: 64, 0b100: 128, 0b101: 250, 0b110: 475, 0b111: 860}
)

#: PGA field (bits 11:9) -> full-scale range in volts (110 and 111 both mean +-0.256 V).
PGA_FSR_V = MappingProxyType(
    {
        0b000: 6.144,
        0b001: 4.096,
        0b010: 2.048,
        0b011: 1.024,
        0b100: 0.512,
        0b101: 0.256,
        0b110: 0.256,
        0b111: 0.256,
    }
)

#: Valid data rates, ascending.
DATA_RATES_SPS = tuple(sorted(DATA_RATE_SPS.values()))
#: Valid full-scale ranges, descending (one per distinct PGA setting).
FULL_SCALE_RANGES_V = (6.144, 4.096, 2.048, 1.024, 0.512, 0.256)

#: Internal oscillator tolerance: conversions may run up to this fraction fast or slow.
OSCILLATOR_TOLERANCE = 0.10

#: Most positive and most negative output codes (16-bit two's complement).
CODE_MAX = 0x7FFF
CODE_MIN = -0x8000


def lsb_volts(fsr_v: float) -> float:
    """Size of one output code in volts: ``FSR / 32768``."""
    return fsr_v / 32768.0


def check_data_rate(data_rate_sps: float) -> int:
    """Return ``data_rate_sps`` as an int, or raise naming the valid rates."""
    if data_rate_sps not in DATA_RATES_SPS:
        raise ValueError(
            f"ADS1115 data rate {data_rate_sps!r} SPS does not exist; choose one of "
            f"{', '.join(map(str, DATA_RATES_SPS))} (there is no 200 SPS: sample at 200 Hz "
            "in single-shot mode with a faster rate)"
        )
    return int(data_rate_sps)


def check_fsr(fsr_v: float) -> float:
    """Return ``fsr_v`` as a float, or raise naming the valid full-scale ranges."""
    if not any(abs(fsr_v - r) < 1e-9 for r in FULL_SCALE_RANGES_V):
        raise ValueError(
            f"ADS1115 full-scale range {fsr_v!r} V does not exist; choose one of "
            f"{', '.join(map(str, FULL_SCALE_RANGES_V))}"
        )
    return float(fsr_v)
