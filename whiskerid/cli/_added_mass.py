"""``--added-mass FILE=MASS``: which recordings carry a known tip mass (calibrate, posterior).

A recording's mass comes from the flag, else from its ``added_mass_kg`` metadata (which
``whiskerid record --added-mass`` writes); recordings with neither are plucks of the plain
whisker. Nothing here imports JAX until the masses are turned into the fit's objects.
"""

from pathlib import Path

ADDED_MASS_HELP = (
    "a known mass clipped to the whisker's tip for recording FILE (FILE=MASS, e.g. "
    "loaded.csv=0.52g±0.01g or =520mg+-10mg; repeat for several files). Without a stated "
    "1-sigma, half a unit of the last digit written; a number without a unit is kg. A "
    "recording's added_mass_kg (and "
    "added_mass_std_kg) metadata does the same. Plucks with and without the mass determine "
    "EI and rho a (so C) separately: the added-mass method"
)


def add_added_mass_option(p) -> None:
    """Register ``--added-mass`` on a parser."""
    p.add_argument("--added-mass", action="append", metavar="FILE=MASS", help=ADDED_MASS_HELP)


def _match(file: str, paths: list[Path]) -> int | None:
    """The index of the recording ``file`` names: the same path, else the same file name
    when only one recording has it."""
    from ..io import same_file

    for i, p in enumerate(paths):
        if str(p) == file or (Path(file).exists() and p.exists() and same_file(p, file)):
            return i
    by_name = [i for i, p in enumerate(paths) if p.name == Path(file).name]
    return by_name[0] if len(by_name) == 1 else None


def stated_masses(specs, paths: list[Path], command_error) -> list[tuple[float, float] | None]:
    """Per recording file, its ``(kg, 1σ kg)`` from ``--added-mass`` or its metadata, or None.

    Raises:
        command_error: A spec that is not ``FILE=MASS``, names no recording, or a mass that
            cannot be read.
    """
    from ..io import RecordingError, mass_from_meta, parse_mass, read_recording

    out: list[tuple[float, float] | None] = [None] * len(paths)
    named = set()
    for spec in specs or []:
        file, sep, mass = str(spec).rpartition("=")
        if not sep or not file.strip() or not mass.strip():
            raise command_error(
                f"--added-mass {spec!r}: write FILE=MASS, e.g. loaded.csv=0.52g±0.01g"
            )
        i = _match(file.strip(), paths)
        if i is None:
            raise command_error(
                f"--added-mass {spec!r}: {file} is not one of the recordings given; name one "
                "of them"
            )
        if i in named:
            raise command_error(
                f"--added-mass {spec!r}: {paths[i]} has a mass already (the flag names it "
                "twice); give each recording one mass"
            )
        try:
            out[i] = parse_mass(mass)
        except ValueError as err:
            raise command_error(f"--added-mass {spec!r}: {err}") from None
        named.add(i)
    for i, p in enumerate(paths):
        if i in named:
            continue
        try:
            out[i] = mass_from_meta(read_recording(p).meta)
        except (ValueError, RecordingError, OSError) as err:
            raise command_error(f"{p}: {err}") from None
    return out


def added_masses(specs, paths: list[Path], obs_lists: list[list], command_error):
    """One :class:`whiskerid.fit.AddedMass` or None per observation (the observations of
    each path in ``obs_lists``), or None when no recording carries a mass."""
    stated = stated_masses(specs, paths, command_error)
    if all(m is None for m in stated):
        return None
    from ..fit import AddedMass

    out = []
    for m, obs in zip(stated, obs_lists, strict=True):
        out += [None if m is None else AddedMass(*m)] * len(obs)
    return out
