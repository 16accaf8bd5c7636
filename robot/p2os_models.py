"""The Pioneer models' conversion factors, chosen by the subclass the SYNC2 reply names.

A Pioneer reports its position, heading, wheel speeds and sonar ranges in units of its own: a
Pioneer 3-DX with the "SH" controller counts 1 mm, a classic ``p3dx`` 0.485 mm, a Pioneer 1
0.05066 mm. ARIA (``ArRobotTypes.cpp`` and ``params/<subclass>.p``) and Player's p2os driver
(``robot_params.cpp``, generated from the Saphira parameter files) both pick the factors by the
robot's class and subclass and multiply the SIP's fields by them; commands (VEL in mm/s, DHEAD in
degrees) go out unconverted. The table below holds their values (p2os's, which agree with ARIA's
for these fields). It is data, so it lives here as a table rather than behind a library.
"""

from __future__ import annotations

import logging

from robot.p2os_protocol import ConversionFactors

log = logging.getLogger(__name__)

# DistConvFactor (mm per count), AngleConvFactor (rad per angle unit), VelConvFactor
# (mm/s per velocity unit), RangeConvFactor (mm per sonar unit), per subclass.
MODEL_FACTORS: dict[str, ConversionFactors] = {
    "amigo": ConversionFactors(0.5083, 0.001534, 0.6154, 1.0),
    "amigo-sh": ConversionFactors(1.0, 0.001534, 1.3746, 1.0),
    "p2at": ConversionFactors(1.32, 0.001534, 1.0, 0.268),
    "p2at8": ConversionFactors(1.32, 0.001534, 1.0, 1.0),
    "p2at8+": ConversionFactors(0.465, 0.001534, 1.0, 1.0),
    "p2ce": ConversionFactors(0.826, 0.001534, 1.0, 0.268),
    "p2d8": ConversionFactors(0.485, 0.001534, 1.0, 1.0),
    "p2d8+": ConversionFactors(0.485, 0.001534, 1.0, 1.0),
    "p2de": ConversionFactors(0.969, 0.001534, 1.0, 0.268),
    "p2df": ConversionFactors(0.485, 0.001534, 1.0, 0.268),
    "p2dx": ConversionFactors(0.84, 0.001534, 1.0, 0.268),
    "p2it": ConversionFactors(1.136, 0.001534, 1.0, 0.268),
    "p2pb": ConversionFactors(0.424, 0.001534, 1.0, 0.268),
    "p2pp": ConversionFactors(0.485, 0.001534, 1.0, 0.268),
    "p3at": ConversionFactors(0.465, 0.001534, 1.0, 1.0),
    "p3at-sh": ConversionFactors(1.0, 0.001534, 1.0, 1.0),
    "p3dx": ConversionFactors(0.485, 0.001534, 1.0, 1.0),
    "p3dx-sh": ConversionFactors(1.0, 0.001534, 1.0, 1.0),
    "p3dx-sh-lms1xx": ConversionFactors(1.0, 0.001534, 1.0, 1.0),
    "peoplebot-sh": ConversionFactors(1.0, 0.001534, 1.0, 1.0),
    "perfpb": ConversionFactors(0.485, 0.001534, 1.0, 1.0),
    "perfpb+": ConversionFactors(0.485, 0.001534, 1.0, 1.0),
    "pion1m": ConversionFactors(0.05066, 0.0061359, 2.5332, 0.1734),
    "pion1x": ConversionFactors(0.05066, 0.0061359, 2.5332, 0.1734),
    "pionat": ConversionFactors(0.07, 0.0061359, 2.5332, 0.1734),
    "powerbot": ConversionFactors(0.5813, 0.001534, 1.0, 1.0),
    "powerbot-sh": ConversionFactors(1.0, 0.001534, 1.0, 1.0),
    "psos1m": ConversionFactors(0.05066, 0.0061359, 2.5332, 0.1734),
    "psos1x": ConversionFactors(0.05066, 0.0061359, 2.5332, 0.1734),
}
DEFAULT_MODEL = "p3dx-sh"
"""What an unknown subclass is read as: 1 mm and 1 mm/s units, as every current Pioneer."""


def factors_for_model(subclass: str) -> ConversionFactors:
    """The conversion factors of ``subclass`` (case-insensitive, e.g. ``"p3dx"``);
    ``ValueError`` naming the known models for another."""
    try:
        return MODEL_FACTORS[subclass.strip().lower()]
    except KeyError:
        known = ", ".join(sorted(MODEL_FACTORS))
        raise ValueError(f"unknown Pioneer model {subclass!r}; known: {known}") from None


def factors_from_sync(robot_strings: tuple[str, ...], port: str) -> ConversionFactors:
    """The factors for the SYNC2 reply's (name, class, subclass); an unknown or missing subclass
    is read as :data:`DEFAULT_MODEL`, with a warning naming ``port``, as ARIA and p2os do."""
    subclass = robot_strings[2] if len(robot_strings) > 2 else ""
    try:
        return factors_for_model(subclass)
    except ValueError:
        log.warning(
            "%s: unknown Pioneer model %r (SYNC2 said %s); reading its SIPs as a %s's "
            "(1 mm units); name the model to override",
            port,
            subclass,
            robot_strings,
            DEFAULT_MODEL,
        )
        return MODEL_FACTORS[DEFAULT_MODEL]
