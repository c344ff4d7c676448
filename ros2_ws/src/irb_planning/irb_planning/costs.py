"""Time weight of a free-duration plan in cost terms (no ROS).

Minimising E + w_T T with E in J is minimising cost = price_J E + rate_s T when
w_T = rate_s / price_J: with an energy price p [currency/kWh] (1 kWh = 3.6e6 J) and a
machine-hour cost c [currency/h] (the robot cell's cost per hour of use, 3600 s),

    w_T [J/s] = (c / 3600) / (p / 3.6e6) = 1000 c / p.
"""
from __future__ import annotations


def time_weight(energy_price_per_kwh: float, machine_hour_cost: float) -> float:
    """w_T [J/s] from the energy price [currency/kWh] and machine-hour cost [currency/h]."""
    if not energy_price_per_kwh > 0 or not machine_hour_cost >= 0:
        raise ValueError('energy price must be > 0 and machine-hour cost >= 0, got '
                         f'{energy_price_per_kwh}, {machine_hour_cost}')
    return 1000.0 * machine_hour_cost / energy_price_per_kwh


def cycle_cost(energy_j: float, duration_s: float, energy_price_per_kwh: float,
               machine_hour_cost: float) -> float:
    """Cost of one cycle [currency]: energy at the price plus the machine time."""
    return energy_j / 3.6e6 * energy_price_per_kwh + duration_s / 3600.0 * machine_hour_cost
