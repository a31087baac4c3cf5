"""Units, defined once for server and car: US ACC set speeds and INRIX move in mph, CAN speaks
km/h, the warehouse and every model speak SI."""

from __future__ import annotations

# Exact by definition: 1 mile = 1609.344 m, so 1 mph = 0.44704 m/s and 1.609344 km/h.
METRES_PER_MILE = 1609.344
MPS_PER_MPH = 0.44704
MPH_PER_MPS = 1.0 / MPS_PER_MPH
KPH_PER_MPH = 1.609344
MPS_PER_KPH = 1.0 / 3.6
KPH_PER_MPS = 3.6
# I-24 MOTION measures in feet along the interstate's mileposts.
METRES_PER_FOOT = 0.3048
FEET_PER_MILE = 5280.0

# Congestion waves travel upstream at about 15 km/h (paper, the Speed Planner's INRIX
# prediction): the speed a plan is made with (planner), aged with (car) and simulated with (sim),
# here as a magnitude; upstream is the sign each use gives it.
WAVE_SPEED_MPS = 15.0 * MPS_PER_KPH


def mps_to_mph(speed_mps: float) -> float:
    """Metres per second to miles per hour."""
    return speed_mps / MPS_PER_MPH


def kph_to_mps(speed_kph: float) -> float:
    """Kilometres per hour to metres per second."""
    return speed_kph * MPS_PER_KPH
