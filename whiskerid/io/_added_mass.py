"""A known mass clipped to the whisker's tip, as written on the command line or in a recording.

The added-mass calibration (``whiskerid calibrate PLAIN.csv LOADED.csv --added-mass
LOADED.csv=0.52g±0.01g``) needs each recording's extra tip mass and its 1σ. Either comes
from the command line (:func:`parse_mass`) or from a recording's metadata lines
``# added_mass_kg: 0.00052`` and ``# added_mass_std_kg: 0.00001`` (which ``whiskerid record
--added-mass`` writes; :func:`mass_from_meta`).

A number without a unit is in kilograms (SI, as everywhere in whiskerid): ``0.00052`` is
0.52 g. A mass outside the plausible range of a clipped tip mass (0.1 mg to 50 g) is refused
with the value, so that ``520`` meant as milligrams does not become 520 kg.

A mass written without its uncertainty is taken as known to half a unit of its last written
digit (the rounding of the number as written: ``0.52g`` → ±0.005 g, ``0.00052`` kg →
±0.000005 kg); state the scale's real uncertainty when it is larger.

No JAX here: the Raspberry Pi side writes these lines.
"""

import math
import re

#: Metadata key of a recording's added tip mass (kg).
ADDED_MASS_KEY = "added_mass_kg"
#: Metadata key of its 1σ (kg).
ADDED_MASS_STD_KEY = "added_mass_std_kg"

_UNITS = {"kg": 1.0, "g": 1e-3, "mg": 1e-6, "": None}
#: The plausible range of a mass clipped to a whisker's tip (kg): 0.1 mg to 50 g.
PLAUSIBLE_KG = (1e-7, 0.05)
_NUMBER = r"([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)"
_MASS = re.compile(
    rf"^\s*{_NUMBER}\s*(kg|mg|g)?\s*(?:(?:±|\+/-|\+-)\s*{_NUMBER}\s*(kg|mg|g)?)?\s*$"
)


def rounding_std(number: str) -> float:
    """Half a unit of the last written digit of ``number`` (``"0.52"`` → 0.005)."""
    mantissa, _, exponent = number.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    power = -decimals + (int(exponent) if exponent else 0)
    return 0.5 * 10.0 ** max(min(power, 300), -300)  # beyond: refused as implausible anyway


def parse_mass(text: str, *, default_unit: str = "kg") -> tuple[float, float]:
    """A mass and its 1σ in kg from text such as ``0.52g±0.01g``, ``520mg+-10mg``, ``0.52g``,
    ``5.2e-4kg`` or ``0.00052`` (kg).

    Units ``kg``, ``g`` or ``mg`` (``default_unit``, kg, when none is written); the uncertainty
    takes the value's unit when it has none. Without an uncertainty, half a unit of the
    value's last written digit.

    Raises:
        ValueError: Text that is not a positive mass, or an uncertainty as large as the mass.
    """
    m = _MASS.match(text)
    if m is None:
        raise ValueError(
            f"mass {text!r} is not a mass: write e.g. 0.52g, 0.52g±0.01g or 520mg+-10mg"
        )
    value, unit, err, err_unit = m.groups()
    unit = unit or default_unit
    scale = _UNITS[unit]
    kg = float(value) * scale
    std = rounding_std(value) * scale if err is None else float(err) * _UNITS[err_unit or unit]
    _checked(kg, 0.0, text)  # a finite mass in the plausible range first
    if err is None and not std < 0.5 * kg:
        raise ValueError(
            f"mass {text!r} is written without its uncertainty, so it is known only to half a "
            f"unit of its last digit ({std * 1e3:.3g} g), half the mass or more: state the "
            f"scale's, e.g. {value}{m.group(2) or ''}±0.01g"
        )
    return _checked(kg, std, text)


def _checked(kg: float, std: float, where: str) -> tuple[float, float]:
    if not (math.isfinite(kg) and kg > 0):
        raise ValueError(f"mass {where!r} must be a positive, finite mass")
    lo, hi = PLAUSIBLE_KG
    if not lo <= kg <= hi:
        raise ValueError(
            f"mass {where!r} is {kg:.3g} kg, outside the plausible range of a tip mass "
            f"({lo * 1e6:g} mg to {hi * 1e3:g} g); a number without a unit is kg: write its "
            "unit, e.g. 0.52g or 520mg"
        )
    if not (math.isfinite(std) and 0 <= std < 0.5 * kg):
        raise ValueError(
            f"mass {where!r}: its uncertainty must be below half the mass (a mass known that "
            "poorly cannot calibrate anything); weigh it more precisely"
        )
    return kg, std


def mass_from_meta(meta: dict[str, str]) -> tuple[float, float] | None:
    """The added tip mass and its 1σ (kg) of a recording's metadata, or None if it has none
    (or 0).

    Raises:
        ValueError: A value that is not a positive number.
    """
    text = meta.get(ADDED_MASS_KEY)
    if text is None:
        return None
    text = str(text).strip()
    try:
        kg = float(text)
    except ValueError:
        raise ValueError(f"{ADDED_MASS_KEY}: {text!r} is not a number (kg)") from None
    if kg == 0:  # written for the plain whisker's plucks
        return None
    err = meta.get(ADDED_MASS_STD_KEY)
    if err is None:
        std = rounding_std(text) if re.fullmatch(_NUMBER, text) else 0.0
    else:
        try:
            std = float(str(err).strip())
        except ValueError:
            raise ValueError(f"{ADDED_MASS_STD_KEY}: {err!r} is not a number (kg)") from None
    return _checked(kg, std, f"{ADDED_MASS_KEY}: {text}")


def mass_text(kg: float, std_kg: float) -> str:
    """``kg ± std`` in grams, as ``parse_mass`` reads it back (e.g. ``0.52g±0.01g``)."""
    return f"{kg * 1e3:.6g}g±{std_kg * 1e3:.3g}g"
