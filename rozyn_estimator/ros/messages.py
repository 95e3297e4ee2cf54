"""ROS message conversions shared by the nodes and the replay (no node, no DDS needed).

Conventions (documented in the README):
- ``inertia`` (geometry_msgs/InertiaStamped): ``m`` the sprung mass [kg], ``iyy`` the
  pitch moment of inertia [kg m^2]; ``com.x`` the centre of gravity along the body's x
  axis (REP 103: forward) in ``header.frame_id``, i.e. ``front_axle_x_m - lf`` (the CoG
  lies ``lf`` behind the front axle). A half car is symmetric about its centre plane, so
  ``com.y = ixy = iyz = 0``; what the half car cannot see is NaN: ``com.z``, ``ixx``,
  ``izz``, ``ixz``.
- The full car's ``inertia`` adds ``ixx``, the roll inertia [kg m^2], and ``com.y``, the
  lateral CoG (REP 103: positive left); its model takes x and y as the body's principal
  axes, so ``ixy = 0``; ``com.z``, ``izz``, ``ixz`` and ``iyz`` are NaN (not seen).
- ``inertia/covariance`` (std_msgs/Float64MultiArray): the 3x3 covariance, row-major, of
  (mass [kg], pitch inertia [kg m^2], CoG from the front axle [m]); ``layout.dim[0]`` is
  labelled ``"mass_kg,pitch_inertia_kgm2,cog_from_front_axle_m"`` and
  ``layout.dim[1].label`` carries the stamp of the matching ``inertia`` message as
  ``"stamp=<sec>.<nanosec>"``. It is published right after that message. The full car's
  is 5x5 in the order of ``FULL_PARAM_NAMES``, labelled
  ``"mass_kg,roll_inertia_kgm2,pitch_inertia_kgm2,cog_from_front_axle_m,cog_lateral_m"``.
"""

from __future__ import annotations

import math
from operator import attrgetter
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import InertiaStamped
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import PARAM_NAMES
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.online import NS, Health, Update

COVARIANCE_LABEL = ",".join(PARAM_NAMES)
FULL_COVARIANCE_LABEL = ",".join(FULL_PARAM_NAMES)


def stamp_ns(stamp: Any) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return stamp.sec * NS + stamp.nanosec


def to_time(ns: int) -> Time:
    return Time(sec=int(ns // NS), nanosec=int(ns % NS))


def field_getter(path: str, msg_type: Any = None) -> attrgetter:
    """Getter for a dotted numeric field of a message, e.g. ``linear_acceleration.z``.

    With ``msg_type`` the field is checked to exist and be numeric in that type.
    """
    if not path or any(not part.isidentifier() for part in path.split(".")):
        raise ConfigError(f"field: expected a dotted field name like linear_acceleration.z, got {path!r}")
    getter = attrgetter(path)
    if msg_type is not None:
        try:
            value = getter(msg_type())
        except AttributeError:
            raise ConfigError(f"field: {msg_type.__name__} has no field {path!r}") from None
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"field: {msg_type.__name__}.{path} is not a number ({type(value).__name__})")
    return getter


def inertia_msg(update: Update, frame_id: str, front_axle_x_m: float) -> InertiaStamped:
    """The published estimate (see the module docstring for the conventions)."""
    if update.params is None:
        raise ValueError("the update has no estimate to publish")
    params = [float(x) for x in update.params]
    msg = InertiaStamped()
    msg.header.stamp = to_time(update.stamp_ns)
    msg.header.frame_id = frame_id
    inertia = msg.inertia
    inertia.com.z = math.nan
    inertia.ixx = inertia.izz = inertia.ixz = math.nan
    inertia.ixy = inertia.iyz = 0.0
    if len(params) == len(FULL_PARAM_NAMES):
        inertia.m, inertia.ixx, inertia.iyy, lf, inertia.com.y = params
        inertia.iyz = math.nan
    else:
        inertia.m, inertia.iyy, lf = params
        inertia.com.y = 0.0
    inertia.com.x = front_axle_x_m - lf
    return msg


def covariance_msg(update: Update) -> Float64MultiArray:
    """The covariance (3x3, or the full car's 5x5) with its labelled layout and the matching stamp."""
    if update.covariance is None:
        raise ValueError("the update has no covariance to publish")
    k = update.covariance.shape[0]
    label = FULL_COVARIANCE_LABEL if k == len(FULL_PARAM_NAMES) else COVARIANCE_LABEL
    msg = Float64MultiArray()
    t = to_time(update.stamp_ns)
    msg.layout.dim = [
        MultiArrayDimension(label=label, size=k, stride=k * k),
        MultiArrayDimension(label=f"stamp={t.sec}.{t.nanosec:09d}", size=k, stride=k),
    ]
    msg.data = [float(x) for x in update.covariance.ravel()]
    return msg


def covariance_stamp_ns(msg: Float64MultiArray) -> int:
    """The stamp carried by a covariance message (to match it with its inertia message)."""
    sec, _, nanosec = msg.layout.dim[1].label.removeprefix("stamp=").partition(".")
    return int(sec) * NS + int(nanosec)


def diagnostic_array(health: Health, name: str, hardware_id: str, stamp: int) -> DiagnosticArray:
    """One DiagnosticStatus wrapped in a DiagnosticArray."""
    status = DiagnosticStatus(
        level=bytes([health.level]),
        name=name,
        message=health.message,
        hardware_id=hardware_id,
        values=[KeyValue(key=k, value=v) for k, v in health.values.items()],
    )
    array = DiagnosticArray(status=[status])
    array.header.stamp = to_time(stamp)
    return array
