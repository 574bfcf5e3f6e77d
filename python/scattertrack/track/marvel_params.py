"""The parameters of Marvel's pose sensing from a LoRa recording, and the
table of the ``marvel`` and ``ulocate`` methods (fusion + sensing).

Declared like :class:`scattertrack.fusion.params.MarvelParams` (one field
per parameter, :func:`scattertrack.parameter_rows.parameter`) and checked
by the core's checker; the module docstring of
:mod:`scattertrack.track.marvel` says what each step does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import cache

from scattertrack.parameter_rows import parameter, rows_of


@dataclass(frozen=True)
class SensingParams:
    """Tuning of the pose sensing of a recording (used with ``--sigmf`` only); SI units."""

    # 16 dB after the 36 dB dechirp gain is the SX1276's SF12 limit
    # (docs/marvel.md section 9); pure noise reads about -27 dB (the largest of 4096 bins).
    min_snr_db: float = parameter(-20.0, "any", "dB", "an epoch whose per-sample SNR (mean over its dechirped peaks) is below this is not decoded")
    # Floors added in quadrature to the DSP's thermal sigmas (module docstring, step 6).
    range_sigma_floor_m: float = parameter(0.1, ">= 0", "m", "floor added in quadrature to the DSP's range sigma")
    angle_sigma_floor_rad: float = parameter(0.01, ">= 0", "rad", "floor added in quadrature to the angle sigma, per tangent axis")
    yaw_sigma_floor_rad: float = parameter(0.05, ">= 0", "rad", "floor added in quadrature to the DSP's yaw sigma")
    doppler_direction: str = parameter(
        "epoch", choices=("epoch", "previous", "predicted"),
        description="the translational Doppler's direction: this epoch's MUSIC angle, the previous epoch's, or the IMU-predicted one",
    )
    clock_flight_epochs: int = parameter(20, ">= 1", "epochs", "epochs used for the tags' clock error when the recording has no rest epoch")
    # The timing range picks the phase range's fringe (5.8 m apart), and the
    # first row places the controller (module docstring, step 2).
    clock_settle_m: float = parameter(
        0.5, ">= 0", "m", "at rest, an epoch is fused once the clock error's uncertainty moves the timing range by less than this"
    )
    # A drone flies at most ~3 m/s here (paper sec. V); a diverging velocity
    # would otherwise feed a wrong Doppler back into the sensing.
    max_doppler_speed_m_s: float = parameter(5.0, "> 0", "m/s", "a predicted velocity above this is scaled down to it for the Doppler correction")
    # Off by default: at 4 it helped behind three reflecting walls (0.96 ->
    # 0.73 m) and hurt behind a ground reflection at 20 m, where the timing
    # range is the one that is fringes off (one seed 5.6 -> 19.6 m snapshots).
    fringe_consistency_sigmas: float = parameter(
        math.inf, "(0, inf]", "sigma", "in flight, the fringe is picked by the timing range alone when it and the predicted range differ by more; inf: off"
    )
    # In a reflecting room (docs/marvel.md section 11) the angle is 7-10
    # degrees off where its thermal sigma is a tenth of a degree.
    consistency_sigmas: bool = parameter(True, description="add the DSP's consistency spreads (tags' directions, phase ranges) to the row's sigmas")


SENSING_DEFAULTS = {f.name: f.default for f in fields(SensingParams)}
"""Parameters of the pose sensing from a recording, name -> default (SI units)."""


@cache
def sensing_table():
    """The table of :class:`SensingParams` alone."""
    from scattertrack import _core

    return _core.ParameterTable("marvel", rows_of(SensingParams))


@cache
def table(method: str = "marvel"):
    """The table of a drone method: the fusion's rows, then the pose sensing's."""
    from scattertrack import _core
    from scattertrack.fusion.params import MarvelParams

    return _core.ParameterTable(method, rows_of(MarvelParams) + rows_of(SensingParams))
