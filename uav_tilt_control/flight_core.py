"""One tick of the PX4-side flight control: impedance -> attitude -> allocation.

The impedance force in map is split by :func:`attitude_setpoint`: yaw and pitch come from the
setpoint and roll removes the y_FLU part; the x_FLU part is made by tilting the arms (the
article's decoupling), so moving along x_FLU needs no pitching.
"""
import dataclasses

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from uav_tilt_common.config import nested
from uav_tilt_common.geometry import cross3
from uav_tilt_common.state import ActuatorCommand, VehicleState
from uav_tilt_common.vehicle import VehicleParams
from uav_tilt_control import frames
from uav_tilt_control.allocation import AllocationConfig, Allocator
from uav_tilt_control.attitude import AttitudeConfig, AttitudePid, attitude_setpoint
from uav_tilt_control.disturbance import DisturbanceConfig, DisturbanceObserver
from uav_tilt_control.impedance import ImpedanceConfig, ImpedanceController
from uav_tilt_control.types import ImpedanceSetpoint


@dataclasses.dataclass
class FlightCoreConfig:
    """The impedance, disturbance, attitude and allocation configs of the flight core."""

    impedance: ImpedanceConfig = nested(ImpedanceConfig)
    disturbance: DisturbanceConfig = nested(DisturbanceConfig)
    attitude: AttitudeConfig = nested(AttitudeConfig)
    allocation: AllocationConfig = nested(AllocationConfig)


class FlightCore:
    """Pure control core: its only state is the filters and integrators of its parts."""

    def __init__(self, vehicle: VehicleParams, config: FlightCoreConfig | None = None
                 ) -> None:
        self.vehicle = vehicle
        self.config = config or FlightCoreConfig()
        self.impedance = ImpedanceController(vehicle.mass_kg, self.config.impedance)
        self.disturbance = DisturbanceObserver(vehicle.mass_kg, vehicle.thrust_tau_s,
                                               self.config.disturbance)
        self.attitude = AttitudePid(vehicle.inertia_kgm2, self.config.attitude)
        self.allocator = Allocator(vehicle, self.config.allocation)
        self._tip_flu = np.array([vehicle.tool_tip_x_m, 0.0, 0.0])
        self._airborne = False

    def reset(self) -> None:
        """Clear filter and integrator state (e.g. on arming)."""
        self.impedance.reset()
        self.disturbance.reset()
        self.attitude.reset()
        self._airborne = False

    def safe_command(self) -> ActuatorCommand:
        """Hover thrust at zero tilt: what is sent when the inputs cannot be trusted."""
        return ActuatorCommand(np.full(4, self.vehicle.hover_thrust_n), 0.0, 0.0)

    def step(self, state: VehicleState, setpoint: ImpedanceSetpoint, f_contact_map: ArrayLike,
             dt_s: float, specific_force_base: ArrayLike | None = None
             ) -> tuple[ActuatorCommand, dict[str, Any]]:
        """One control tick; returns (ActuatorCommand, diagnostics dict).

        ``specific_force_base``: the IMU's accelerometer (body, m/s^2) for the disturbance
        observer; without it the observer holds its estimate.
        """
        if not _inputs_finite(state, setpoint, f_contact_map, dt_s):
            return self.safe_command(), {'input_fault': True, 'saturated': False}

        R_map_base = frames.quat_matrix(state.q_map_base)
        if setpoint.airborne and not self._airborne:
            self._hand_weight_to_observer()
        self._airborne = setpoint.airborne
        if specific_force_base is not None and np.all(np.isfinite(specific_force_base)):
            self.disturbance.update(R_map_base, specific_force_base, f_contact_map, dt_s,
                                    setpoint.airborne)
        f_p_map = self.impedance.update(state.p_map, state.v_map, setpoint, f_contact_map, dt_s,
                                        self.disturbance.f_ext_map)
        R_map_base_d, _, _ = attitude_setpoint(f_p_map, setpoint.yaw_rad, setpoint.pitch_rad,
                                               self.config.attitude.roll_limit_rad)
        # Split the force on the attitude actually flown, so the tilt makes the x_FLU part
        # right away while the attitude loop is still converging.
        f_body = R_map_base.T @ f_p_map
        torque_flu = self.attitude.update(R_map_base_d, state, dt_s)
        if setpoint.tangential_feedforward:
            # The friction acts at the tool tip: its pitch moment is cancelled too, else the
            # attitude gives way and the tip leaves the line. Not its yaw moment: the rotors'
            # drag torque (about 0.25 N m) cannot make it, and cancelling it would also take
            # away the damping that friction gives a sideways slip of the tip.
            moment = cross3(self._tip_flu, R_map_base.T @ self.impedance.f_tangential_map)
            torque_flu = torque_flu - np.array([0.0, moment[1], 0.0])
        result = self.allocator.allocate((f_body[0], f_body[2]), torque_flu)
        given_up_x, given_up_z = result.force_given_up_n
        made_x, made_z = f_body[0] - given_up_x, f_body[2] - given_up_z
        self.disturbance.commanded(R_map_base @ np.array([made_x, 0.0, made_z]))
        command = ActuatorCommand(result.thrusts_n, result.alpha_rad, result.beta_rad)
        diagnostics = {
            'input_fault': False,
            'saturated': result.saturated,
            'f_p_map': f_p_map,
            'f_contact_map_filtered': self.impedance.f_contact_map.copy(),
            'f_ext_map': self.disturbance.f_ext_map.copy(),
            'R_map_base_d': R_map_base_d,
            'torque_flu': torque_flu,
            'force_given_up_n': result.force_given_up_n,
            'torque_given_up_nm': result.torque_given_up_nm,
        }
        return command, diagnostics

    def _hand_weight_to_observer(self) -> None:
        """Leaving the ground: the observer's vertical axis starts learning, and it learns a
        weight error too (the IMU scales the thrust by the true mass), so what the hover-thrust
        estimator learnt of it on the climb becomes the observer's starting estimate instead
        of being counted twice (that climbed the vehicle by the error over K_z). What the
        observer's bound leaves over stays with the estimator: a vehicle 40% heavier than its
        model sagged 0.17 m once handed over, one twice as heavy fell to the ground."""
        if self.disturbance.vertical_active:
            self.impedance.f_hover_n = -self.disturbance.take_vertical(
                -self.impedance.f_hover_n)


def _inputs_finite(state: VehicleState, setpoint: ImpedanceSetpoint, f_contact_map: ArrayLike,
                   dt_s: float) -> bool:
    try:
        # one concatenate with the cast, not one array per input (this runs every tick)
        flat = np.concatenate(
            (state.p_map, state.q_map_base, state.v_map, state.w_base, f_contact_map,
             np.ravel(setpoint.R_map_t), setpoint.origin_map, setpoint.lambda_d_t,
             setpoint.dlambda_d_t, setpoint.ddlambda_d_t,
             (setpoint.yaw_rad, setpoint.pitch_rad, dt_s)), dtype=float)
        q = np.asarray(state.q_map_base, dtype=float)
    except (TypeError, ValueError):
        return False
    return bool(np.isfinite(flat).all()) and dt_s > 0.0 and math.sqrt(q @ q) > 0.5
