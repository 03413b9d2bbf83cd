"""The flight battery of a ``motors`` profile: its voltage sags under load and caps the rotors' top speed.

In:  a profile's ``[battery]`` table (cells, capacity mAh, cell volts full and empty, internal resistance
     ohm per cell, motor and ESC efficiency), then per physics step the rotor speeds (rad/s), the rotors'
     drag-torque factor (N m s^2) and the step (s); the pack's charge at the start (% of capacity; 100 by default)
Out: the terminal voltage (V), the current (A), the charge used (mAh) and left (0..1), the rotors' speed cap (rad/s);
     the voltage and the charge left as measured (a battery event may make them read empty: plant.events)

The model (docs/weather.md "Battery"): the open-circuit voltage follows a LiPo cell's rest voltage by the charge
left (:data:`LIPO_SHAPE`: flat through the middle, steep at both ends), E = n (v_empty + (v_full − v_empty) s(charge
left)); the shaft power the rotors draw is
P = Σ Q_i ω_i = κ Σ ω_i³ (Q = κ ω², the rotor's drag torque), the pack delivers P / η, and its terminal
voltage V = E − I R with I = P / (η V) is the larger root of V² − E V + P R / η = 0 (exact, no iteration).
A DC motor's no-load speed is proportional to its voltage (K_v · V), so the rotors' top speed is
ω_max · V / (n v_full): the profile's ω_max on a full pack at rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from params import Table

# A LiPo cell's rest voltage by its charge left, every 5 % from empty (0) to full (20), as a share of the way from
# its empty to its full voltage: the hobby trade's usual table (3.27 V empty, 3.61 at 5 %, 3.69 at 10 %, 3.84 at
# 50 %, 4.20 V full), assumed, not measured. Before it the voltage was linear in the charge, and the x500 could not
# climb below about 23 %, before any of PX4's battery levels (docs/weather.md).
LIPO_SHAPE = (0.0, 0.3656, 0.4516, 0.4731, 0.4946, 0.5161, 0.5376, 0.5591, 0.5699, 0.5914, 0.6129, 0.6237, 0.6452,
              0.6882, 0.7312, 0.7634, 0.8065, 0.871, 0.9032, 0.9462, 1.0)


def open_circuit_v(cells: float, capacity_mah: float, full_v: float, empty_v: float, used_mah: float) -> float:
    """The pack's open-circuit voltage (V) with ``used_mah`` of its ``capacity_mah`` drawn: ``cells`` cells, each
    at its rest voltage by the charge left (:data:`LIPO_SHAPE`, linear between its points) between ``empty_v`` and
    ``full_v`` (V). Plain floats: the batch engine compiles it with :func:`pack_step`."""
    x = 20.0 * (1.0 - min(used_mah / capacity_mah, 1.0))  # the charge left, in 5 % steps
    i = min(int(x), 19)
    s = LIPO_SHAPE[i] + (LIPO_SHAPE[i + 1] - LIPO_SHAPE[i]) * (x - i)
    return cells * (empty_v + (full_v - empty_v) * s)


@dataclass(frozen=True, slots=True)
class BatteryConfig:
    cells: int
    capacity_mah: float
    cell_full_v: float
    cell_empty_v: float
    cell_resistance_ohm: float
    efficiency: float

    @property
    def full_v(self) -> float:
        return self.cells * self.cell_full_v


def battery_from_table(t: Table) -> BatteryConfig:
    """Validate a profile's ``[battery]`` table (errors name the file and key)."""
    cfg = BatteryConfig(
        cells=t.integer("cells", lo=1, hi=24),
        capacity_mah=t.number("capacity_mah", lo=1.0, hi=1e6),
        cell_full_v=t.number("cell_full_v", 4.2, lo=1.0, hi=5.0),
        cell_empty_v=t.number("cell_empty_v", 3.3, lo=1.0, hi=5.0),
        cell_resistance_ohm=t.number("cell_resistance_ohm", lo=0.0, hi=1.0),
        efficiency=t.number("efficiency", lo=0.05, hi=1.0),
    )
    if cfg.cell_empty_v >= cfg.cell_full_v:
        raise t.error("cell_empty_v", f"must be below cell_full_v ({cfg.cell_full_v:g} V)")
    t.done()
    return cfg


class Battery:
    """The pack's state: charge used (mAh), terminal voltage (V), current (A); their extremes over the flight."""

    def __init__(self, config: BatteryConfig, start_pct: float = 100.0) -> None:
        self.config = config
        self.used_mah = config.capacity_mah * (1.0 - start_pct / 100.0)  # (a pack not full at the start)
        self.voltage = open_circuit_v(config.cells, config.capacity_mah, config.cell_full_v, config.cell_empty_v,
                                      self.used_mah)  # at rest
        self.current = 0.0
        self.min_voltage = self.voltage
        self.max_current = 0.0
        self._charge_as = self.used_mah * 3.6  # A s drawn (pack_step: used mAh = A s / 3.6)
        self.reads_empty = False  # a battery event: it reads empty (its measured voltage and charge), drawn as it is

    def step(self, omega: tuple[float, ...], torque_factor: float, h: float) -> float:
        """Draw the rotors' power over h (s); returns the rotors' speed cap (rad/s) as a fraction of ω_max."""
        c = self.config
        v, i, self._charge_as, self.used_mah = pack_step(pack_constants(c), self.used_mah, self._charge_as, omega,
                                                         torque_factor, h)
        self.voltage, self.current = v, i
        self.min_voltage = min(self.min_voltage, v)
        self.max_current = max(self.max_current, i)
        return v / c.full_v

    @property
    def remaining(self) -> float:
        """The charge left as measured, a fraction of the capacity (0..1): what SYS_STATUS reports and the vehicle
        watches; 0 while it :attr:`reads_empty`."""
        if self.reads_empty:
            return 0.0
        return min(max(1.0 - self.used_mah / self.config.capacity_mah, 0.0), 1.0)

    @property
    def measured_v(self) -> float:
        """The terminal voltage as measured (V): what SYS_STATUS and BATTERY_STATUS report; the pack's empty voltage
        at rest while it :attr:`reads_empty`, as PX4's simulated battery reads on an injected failure
        (BatterySimulator.cpp: its empty cell voltage)."""
        return self.config.cells * self.config.cell_empty_v if self.reads_empty else self.voltage

    def summary(self) -> dict:
        return {"voltage_v": self.voltage, "min_voltage_v": self.min_voltage, "current_a": self.current,
                "max_current_a": self.max_current, "used_mah": self.used_mah,
                "capacity_mah": self.config.capacity_mah, "cells": self.config.cells}


def pack_constants(c: BatteryConfig) -> tuple[float, float, float, float, float, float]:
    """The numbers :func:`pack_step` takes: (cells, capacity mAh, cell V full, cell V empty, ohm a cell, efficiency)."""
    return (float(c.cells), c.capacity_mah, c.cell_full_v, c.cell_empty_v, c.cell_resistance_ohm, c.efficiency)


def pack_step(c: tuple[float, float, float, float, float, float], used_mah: float, charge_as: float,
              omega: tuple[float, ...], torque_factor: float, h: float) -> tuple[float, float, float, float]:
    """One physics step of h (s) of the pack (:func:`pack_constants`) at ``used_mah`` (mAh) and ``charge_as`` (A s
    drawn) feeding rotors at ``omega`` (4 speeds rad/s; ``torque_factor`` N m s^2): (terminal voltage V, current A,
    charge drawn A s and used mAh after it). Plain floats: the batch engine compiles this function."""
    cells, capacity, full, empty, resistance, efficiency = c
    cubes = omega[0] * omega[0] * omega[0] + omega[1] * omega[1] * omega[1] + omega[2] * omega[2] * omega[2]
    power = torque_factor * (cubes + omega[3] * omega[3] * omega[3]) / efficiency  # W from the pack
    e = open_circuit_v(cells, capacity, full, empty, used_mah)
    r = cells * resistance
    disc = e * e - 4.0 * power * r
    v = 0.5 * (e + math.sqrt(disc)) if disc > 0.0 else 0.5 * e  # beyond the pack's peak power: it gives half
    i = power / v if v > 0.0 else 0.0
    charge_as += i * h
    return v, i, charge_as, charge_as / 3.6
