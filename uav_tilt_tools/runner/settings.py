"""What a user sets for an in-process flight (``uav-tilt fly --set``, ``uav-tilt campaign
--set``): the controller's parameters and the vehicle's, by the node parameters' names.

``vehicle.*`` are the names that plant_node and controller_node both take
(:class:`uav_tilt_common.vehicle.VehicleParams`): the plant's is the vehicle flown (its
truth, times the scenario's ``mismatch``), the controller's its model of it. One process
flies both, so a ``vehicle.*`` setting changes the vehicle: the plant's body and the
controller's model alike (``launch.sh`` needs ``--param plant.vehicle.NAME`` and
``--param controller.vehicle.NAME`` for the same). A model that differs from the truth is
the scenario's ``mismatch``.
"""
import dataclasses
from typing import Any, Mapping

import yaml

from uav_tilt_common.config import ConfigError, from_dict, nested
from uav_tilt_common.vehicle import VehicleParams, check_vehicle
from uav_tilt_control.controller_core import ControllerConfig


@dataclasses.dataclass
class FlySettings(ControllerConfig):
    """The controller's parameters and ``vehicle.*``, the vehicle flown (module docstring)."""

    vehicle: VehicleParams = nested(VehicleParams)


def parse_pairs(option: str, pairs: list[str] | None, owned: Mapping[str, str]
                ) -> dict[str, Any]:
    """``KEY=VALUE`` words of ``option`` (``--set``) as a dict of YAML values; a key that
    one of the command's own options sets (``owned``: key -> that option) is refused."""
    out = {}
    for pair in pairs or ():
        key, sep, text = pair.partition('=')
        if not sep:
            raise ConfigError(f"{option} {pair!r}: expected KEY=VALUE")
        if key in owned:
            raise ConfigError(f"{option} {pair!r}: that is {owned[key]}")
        try:
            out[key] = yaml.safe_load(text)
        except yaml.YAMLError as err:
            raise ConfigError(f"{option} {pair!r}: {' '.join(str(err).split())}") from None
    return out


def split_settings(values: Mapping[str, Any] | None
                   ) -> tuple[ControllerConfig, VehicleParams]:
    """(the controller's config, the vehicle) of ``values`` (dotted or nested names of
    :class:`FlySettings`), validated: ConfigError for a bad value, an unknown name or a
    vehicle that cannot fly (:func:`uav_tilt_common.vehicle.check_vehicle`)."""
    settings = from_dict(FlySettings, values)
    controller = ControllerConfig(**{f.name: getattr(settings, f.name)
                                     for f in dataclasses.fields(ControllerConfig)})
    check_vehicle(settings.vehicle)
    return controller, settings.vehicle
