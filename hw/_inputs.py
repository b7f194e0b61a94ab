"""Several ADS1115 inputs sampled round-robin: input names, data-rate choice, the scanner.

An input is named like the chip's pins: ``A0`` .. ``A3`` single-ended (against GND), or a
differential pair the multiplexer offers (``A0-A1``, ``A0-A3``, ``A1-A3``, ``A2-A3``),
optionally prefixed by the chip's I2C address for a second chip on the bus (``0x49:A0``).

In single-shot mode every conversion starts when the config register is written, after the
multiplexer has switched, and the delta-sigma converter's digital filter settles within that
one conversion: a result read after a mux change is a fresh, fully settled conversion of the
new input, so no conversion has to be thrown away. The cost of a mux change is therefore
one conversion plus its I2C traffic per sample, which bounds the rate of the scan:
``inputs × rate_hz ≤ 1 / (slowest 860 SPS conversion + I2C traffic)`` (see
:func:`max_scan_rate_hz`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from types import MappingProxyType

from whiskerid.io._ads1115_spec import DATA_RATES_SPS, OSCILLATOR_TOLERANCE

from ._ads1115 import ADS1115, Config
from ._emulator import EmulatedADS1115, EmulatedBus

#: Input name -> the MUX field's name for it (the differential pairs the chip offers).
INPUT_MUX = MappingProxyType(
    {
        "A0": "AIN0_GND",
        "A1": "AIN1_GND",
        "A2": "AIN2_GND",
        "A3": "AIN3_GND",
        "A0-A1": "AIN0_AIN1",
        "A0-A3": "AIN0_AIN3",
        "A1-A3": "AIN1_AIN3",
        "A2-A3": "AIN2_AIN3",
    }
)

#: I2C time budgeted per sample besides the conversion (s): the config write that starts
#: it, one or two OS-bit polls and the result's read, at the Pi's 400 kHz bus clock with
#: margin for the kernel's scheduling.
I2C_BUDGET_S = 0.6e-3

_INPUT_RE = re.compile(r"^(?:(0x[0-9a-fA-F]{2}|\d+):)?(A[0-3](?:-A[0-3])?)$")


@dataclasses.dataclass(frozen=True)
class Input:
    """One input of one chip.

    Attributes:
        name: Column name in a recording: the input (``A0``, ``A0-A1``), prefixed by the
            address when it is not the default chip's (``0x49:A0``).
        address: 7-bit I2C address of the chip.
        mux: The MUX field's name (a key of ``MUX_CODES``).
    """

    name: str
    address: int
    mux: str


def parse_inputs(text: str, *, default_address: int = 0x48) -> tuple[Input, ...]:
    """Parse ``"A0,A1"``, ``"A0-A1"`` or ``"A0,0x49:A0"`` into inputs.

    Raises:
        ValueError: An unknown input or pair, a repeated one, or none at all.
    """
    items = [s.strip() for s in text.split(",") if s.strip()]
    if not items:
        raise ValueError("no input given; name them like A0 or A0,A1 or A0-A1")
    out = []
    for item in items:
        m = _INPUT_RE.match(item)
        if m is None or m.group(2) not in INPUT_MUX:
            raise ValueError(
                f"input {item!r} is not an ADS1115 input; use A0..A3 (single-ended) or one of "
                f"the differential pairs {', '.join(k for k in INPUT_MUX if '-' in k)}, "
                "optionally as ADDRESS:INPUT (0x49:A0) for a second chip"
            )
        address = default_address if m.group(1) is None else int(m.group(1), 0)
        if not 0x03 <= address <= 0x77:
            raise ValueError(f"input {item!r}: I2C address {address:#x} is outside 0x03..0x77")
        name = m.group(2) if address == default_address else f"{address:#04x}:{m.group(2)}"
        out.append(Input(name, address, INPUT_MUX[m.group(2)]))
    names = [i.name for i in out]
    if len(set(names)) != len(names):
        raise ValueError(f"an input is named twice in {text!r}; name each once")
    return tuple(out)


def worst_conversion_s(data_rate_sps: int) -> float:
    """Longest conversion at this data rate (the oscillator slow by its full tolerance)."""
    return 1.0 / (data_rate_sps * (1.0 - OSCILLATOR_TOLERANCE))


def max_scan_rate_hz(n_inputs: int = 1) -> float:
    """Highest per-input rate of a single-shot scan of ``n_inputs`` inputs (Hz)."""
    return 1.0 / (n_inputs * (worst_conversion_s(DATA_RATES_SPS[-1]) + I2C_BUDGET_S))


def data_rate_for(slot_s: float) -> int:
    """The slowest data rate whose worst-case conversion plus I2C traffic fits in a slot.

    Slower conversions average over a longer window, so they are less noisy; a faster one
    than needed would only add noise.

    Raises:
        ValueError: If even 860 SPS does not fit (the slot is too short).
    """
    for dr in DATA_RATES_SPS:
        if worst_conversion_s(dr) + I2C_BUDGET_S <= slot_s:
            return dr
    raise ValueError(
        f"a sample every {slot_s * 1e3:.3g} ms is faster than single-shot conversions allow "
        f"(at most {max_scan_rate_hz():.0f} samples per second in all)"
    )


class InputScan:
    """Read several inputs in turn, one single-shot conversion each (for :class:`Sampler`).

    Every conversion writes its input's MUX with the start bit, so each result is a fresh,
    settled conversion of that input. Inputs on other addresses get their own driver on the
    same bus.

    Args:
        bus: smbus2-like bus shared by all the chips.
        inputs: The inputs, in scan order.
        config: Common configuration (PGA, data rate); its ``mux`` is replaced per input.
        **driver_options: Passed to every :class:`ADS1115` (``timeout_s``, ``clock``, ...).
    """

    def __init__(self, bus, inputs: Sequence[Input], *, config: Config, **driver_options) -> None:
        if not inputs:
            raise ValueError("an InputScan needs at least one input")
        self.inputs = tuple(inputs)
        self.config = config.replace(single_shot=True)
        self._chips: dict[int, ADS1115] = {}
        for inp in self.inputs:
            if inp.address not in self._chips:
                self._chips[inp.address] = ADS1115(
                    bus, inp.address, config=self.config, **driver_options
                )

    @property
    def n_inputs(self) -> int:
        """How many inputs one round reads."""
        return len(self.inputs)

    @property
    def names(self) -> tuple[str, ...]:
        """The inputs' names, in scan order."""
        return tuple(i.name for i in self.inputs)

    @property
    def chips(self) -> tuple[ADS1115, ...]:
        """The drivers, one per address."""
        return tuple(self._chips.values())

    def read_input(self, j: int) -> int:
        """Convert input ``j`` once; its code (raises like :meth:`ADS1115.read_single`)."""
        inp = self.inputs[j]
        return self._chips[inp.address].read_single(inp.mux)

    def read(self) -> int:
        """Convert the first input (so that a one-input scan is a plain ADC)."""
        return self.read_input(0)

    def to_volts(self, code: int) -> float:
        """A code in volts (every input shares the PGA range)."""
        return self.chips[0].to_volts(code)


class Rounds:
    """Group round-robin samples (``Sample.channel``) into rows, one per complete round.

    A round missing an input (a lost slot) is dropped whole and counted, so that every row
    of a recording holds one sample of each input.

    Args:
        n_inputs: Inputs per round.
    """

    def __init__(self, n_inputs: int) -> None:
        self.n_inputs = int(n_inputs)
        self.incomplete = 0
        self._round: int | None = None
        self._times: list[float | None] = [None] * self.n_inputs
        self._codes: list[int] = [0] * self.n_inputs

    def push(self, sample) -> tuple[list[float], list[int]] | None:
        """Add a sample; return ``(times, codes)`` when it completes a round."""
        if sample.round != self._round:
            if self._round is not None and any(t is not None for t in self._times):
                self.incomplete += 1  # the previous round never completed
            self._round = sample.round
            self._times = [None] * self.n_inputs
        j = sample.channel
        self._times[j], self._codes[j] = sample.t_s, sample.code
        if any(t is None for t in self._times):
            return None
        times, self._times = self._times, [None] * self.n_inputs
        return list(times), list(self._codes)


def converter(bus, inputs: Sequence[Input], *, config: Config, **timing) -> ADS1115 | InputScan:
    """What a :class:`~whiskerid.hw.Sampler` reads: the chip of a single input, or an
    :class:`InputScan` of several.

    Args:
        bus: The I2C bus (or an emulated one).
        inputs: The inputs; the configuration's multiplexer is set per input by a scan.
        config: The chip's configuration.
        **timing: ``clock`` and ``sleep`` (a virtual clock).
    """
    if len(inputs) == 1:
        return ADS1115(bus, inputs[0].address, config=config, **timing)
    return InputScan(bus, inputs, config=config, **timing)


def emulated_bus(inputs: Sequence[Input], sources: Sequence, *, seed: int = 0,
                 noise_v: float = 0.0, **timing) -> EmulatedADS1115 | EmulatedBus:  # fmt: skip
    """Emulated chip(s) answering on the inputs' addresses, each input's positive pin fed by
    its source (a differential input's negative pin is grounded).

    Args:
        inputs: The inputs.
        sources: One ``source(t_s) -> volts`` per input.
        seed: Seed of the first chip's noise (the next chips get ``seed + 1``, ...).
        noise_v: Input noise per conversion, volts RMS.
        **timing: ``clock`` and ``sleep`` for every chip.
    """
    per_chip: dict[int, list] = {}
    for inp, source in zip(inputs, sources, strict=True):
        pins = per_chip.setdefault(inp.address, [None] * 4)
        pins[int(inp.mux[3])] = source  # AINp_...: the positive pin's number
    chips = [
        EmulatedADS1115(pins, address=a, seed=seed + i, noise_v=noise_v, **timing)
        for i, (a, pins) in enumerate(per_chip.items())
    ]
    return chips[0] if len(chips) == 1 else EmulatedBus(chips)
