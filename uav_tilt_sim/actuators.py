"""Actuator dynamics: rotors with first-order thrust lag, servos with bandwidth and rate limit."""
import math

import numpy as np


class RotorBank:
    """Four rotors: thrust follows the command with time constant tau, bounded to [0, F_max]."""

    def __init__(self, tau_s, f_max_n, dt_s, initial_n=0.0):
        self.f_max_n = f_max_n
        self._gain = 1.0 if tau_s <= 0.0 else 1.0 - math.exp(-dt_s / tau_s)
        self.thrusts_n = np.full(4, float(initial_n))

    def step(self, command_n):
        """Advance one physics step towards ``command_n``; returns the thrusts [N]."""
        # plain floats: called at the physics rate, where numpy's per-call cost dominates
        gain, f_max = self._gain, self.f_max_n
        self.thrusts_n[:] = [f + gain * (min(max(c, 0.0), f_max) - f) for f, c in
                             zip(self.thrusts_n.tolist(), np.asarray(command_n).tolist())]
        return self.thrusts_n


class Servo:
    """Position servo: first-order response of bandwidth f_bw, rate limit, angle range."""

    def __init__(self, bandwidth_hz, rate_limit_rad_s, limit_rad, dt_s, initial_rad=0.0):
        self._omega = 2.0 * math.pi * bandwidth_hz
        self.rate_limit = rate_limit_rad_s
        self.limit = limit_rad
        self.dt = dt_s
        self.angle_rad = float(initial_rad)
        self.rate_rad_s = 0.0

    def step(self, command_rad):
        """Advance one physics step; returns (angle, rate) of the servo's reference motion."""
        target = min(max(command_rad, -self.limit), self.limit)
        rate = self._omega * (target - self.angle_rad)
        # Never overshoot the target within one step (stable for any bandwidth and dt).
        rate = min(max(rate, -self.rate_limit), self.rate_limit)
        step = rate * self.dt
        if abs(step) > abs(target - self.angle_rad):
            step = target - self.angle_rad
        self.angle_rad += step
        self.rate_rad_s = step / self.dt
        return self.angle_rad, self.rate_rad_s
