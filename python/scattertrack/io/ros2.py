"""A track as ROS 2 messages, in MCAP or in a ROS 2 bag (no ROS install needed).

Every channel is ROS 2: ``ros2msg`` schemas and CDR encoding, so ROS tools,
Foxglove and the ``mcap``/``rosbags`` readers all read the files. Per tag
(the EPC exactly as in ``track.csv``; ROS names cannot start with a digit,
hence the ``tag_`` prefix):

* ``/scattertrack/tags/tag_<EPC>/pose``: ``geometry_msgs/msg/PoseWithCovarianceStamped``;
* ``/scattertrack/tags/tag_<EPC>/odom``: ``nav_msgs/msg/Odometry`` (pose and
  velocity with covariance);

and once, at the first estimate's stamp, the antennas as
``visualization_msgs/msg/MarkerArray`` on ``/scattertrack/antennas``.
Exactly one pose and one odometry message per track row.

Covariances (row-major 6×6, x y z then rotations about x y z): the
tracker's full 3×3 position (and velocity) block when the track carries
it (``Track.covariance``), else the diagonal of its sigmas. The
orientation is the identity with a rotation variance of
:data:`UNKNOWN_ROTATION_VARIANCE` (rad², "unknown") unless the track
estimates orientation (Marvel), which is then given with
:data:`NOMINAL_ROTATION_VARIANCE`. Stamps are the estimates' times
(Unix epoch for live input). ``transform`` (x, y, z, qw, qx, qy, qz) maps
the scene frame into the robot's: p' = R p + t, Σ' = R Σ Rᵀ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

UNKNOWN_ROTATION_VARIANCE = 1e6
"""rad²: the ROS convention for "orientation not estimated"."""
NOMINAL_ROTATION_VARIANCE = 0.01
"""rad² (about 6°): for tracks with an orientation but no orientation covariance."""
DISTRO = "ROS2_HUMBLE"


@dataclass(frozen=True)
class Transform:
    """Scene frame -> robot frame: translation (m) and rotation (unit quaternion w, x, y, z)."""

    translation: np.ndarray
    rotation: np.ndarray

    @staticmethod
    def parse(text: str) -> "Transform":
        values = [float(v) for v in text.split(",")]
        if len(values) != 7 or not all(math.isfinite(v) for v in values):
            raise ValueError(f"expected x,y,z,qw,qx,qy,qz (seven finite numbers), got {text!r}")
        q = np.array(values[3:])
        norm = np.linalg.norm(q)
        if not 0.999 < norm < 1.001:
            raise ValueError(f"the quaternion {values[3:]} is not a unit quaternion (norm {norm:.4f})")
        return Transform(np.array(values[:3]), q / norm)

    def matrix(self) -> np.ndarray:
        w, x, y, z = self.rotation
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )


IDENTITY = Transform(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))


def topic(epc: str, kind: str) -> str:
    """``/scattertrack/tags/tag_<EPC>/<kind>``."""
    return f"/scattertrack/tags/tag_{epc}/{kind}"


ANTENNA_TOPIC = "/scattertrack/antennas"
POSE = "geometry_msgs/msg/PoseWithCovarianceStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
MARKERS = "visualization_msgs/msg/MarkerArray"


def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(getattr(Stores, DISTRO))


def _stamp(types, time_s: float):
    sec = math.floor(time_s)
    nanosec = min(int(round((time_s - sec) * 1e9)), 999_999_999)
    return types["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=nanosec)


def _covariances(track, i: int, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position 3×3, velocity 3×3) of row ``i`` in the output frame."""
    if getattr(track, "covariance", None) is not None:
        full = np.asarray(track.covariance[i], dtype=float).reshape(6, 6)
        position, velocity = full[:3, :3], full[3:, 3:]
    else:
        sigma = np.asarray(track.sigma[i], dtype=float) if track.sigma is not None else np.full(3, np.nan)
        position, velocity = np.diag(sigma**2), np.full((3, 3), np.nan)
    velocity = np.where(np.isfinite(velocity), velocity, 0.0) if np.isfinite(velocity).any() else np.diag([UNKNOWN_ROTATION_VARIANCE] * 3)
    return rotation @ position @ rotation.T, rotation @ velocity @ rotation.T


def _six(block: np.ndarray, rotation_variance: float) -> np.ndarray:
    six = np.zeros((6, 6))
    six[:3, :3] = block
    six[3:, 3:] = np.eye(3) * rotation_variance
    return six.reshape(36)


def messages(track, scene=None, frame_id: str = "scattertrack", transform: Transform = IDENTITY):
    """Yield ``(topic, msgtype, stamp_ns, message)`` in time order: the
    antennas first (if ``scene``), then per track row its pose and odometry."""
    ts = _typestore()
    types = ts.types
    rotation = transform.matrix()
    order = np.argsort(np.asarray(track.time_s), kind="stable")
    if scene is not None and len(order):
        yield ANTENNA_TOPIC, MARKERS, int(round(float(track.time_s[order[0]]) * 1e9)), _antenna_markers(types, scene, float(track.time_s[order[0]]), frame_id, transform)
    Header, Point, Quaternion, Pose, Vector3 = (types[t] for t in ("std_msgs/msg/Header", "geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion", "geometry_msgs/msg/Pose", "geometry_msgs/msg/Vector3"))
    PoseWithCovariance, Twist, TwistWithCovariance = (types[t] for t in ("geometry_msgs/msg/PoseWithCovariance", "geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistWithCovariance"))
    orientation = getattr(track, "orientation", None)
    for i in order:
        time_s = float(track.time_s[i])
        epc = str(track.epc[i])
        position = rotation @ np.asarray(track.position[i], dtype=float) + transform.translation
        velocity = rotation @ np.nan_to_num(np.asarray(track.velocity[i], dtype=float))
        position_cov, velocity_cov = _covariances(track, i, rotation)
        if orientation is not None and np.all(np.isfinite(orientation[i])):
            q, rotation_variance = _rotate_quaternion(transform.rotation, np.asarray(orientation[i], dtype=float)), NOMINAL_ROTATION_VARIANCE
        else:
            q, rotation_variance = np.array([1.0, 0.0, 0.0, 0.0]), UNKNOWN_ROTATION_VARIANCE
        header = Header(stamp=_stamp(types, time_s), frame_id=frame_id)
        pose = PoseWithCovariance(
            pose=Pose(position=Point(x=position[0], y=position[1], z=position[2]), orientation=Quaternion(x=q[1], y=q[2], z=q[3], w=q[0])),
            covariance=_six(position_cov, rotation_variance),
        )
        stamp = int(round(time_s * 1e9))
        yield topic(epc, "pose"), POSE, stamp, types[POSE](header=header, pose=pose)
        twist = TwistWithCovariance(
            twist=Twist(linear=Vector3(x=velocity[0], y=velocity[1], z=velocity[2]), angular=Vector3(x=0.0, y=0.0, z=0.0)),
            covariance=_six(velocity_cov, UNKNOWN_ROTATION_VARIANCE),
        )
        yield topic(epc, "odom"), ODOMETRY, stamp, types[ODOMETRY](header=header, child_frame_id=f"tag_{epc}", pose=pose, twist=twist)


def _rotate_quaternion(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b (w, x, y, z)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _antenna_markers(types, scene, time_s: float, frame_id: str, transform: Transform):
    """One sphere (5 cm) and one text label per antenna."""
    rotation = transform.matrix()
    markers = []
    empty = np.zeros(0, dtype=np.uint8)
    for k, antenna in enumerate(scene.antennas):
        p = rotation @ np.asarray(antenna.position, dtype=float) + transform.translation
        for j, (kind, text) in enumerate(((2, ""), (9, f"antenna {antenna.id}"))):  # SPHERE, TEXT_VIEW_FACING
            markers.append(
                types["visualization_msgs/msg/Marker"](
                    header=types["std_msgs/msg/Header"](stamp=_stamp(types, time_s), frame_id=frame_id),
                    ns="scattertrack/antennas",
                    id=2 * k + j,
                    type=kind,
                    action=0,
                    pose=types["geometry_msgs/msg/Pose"](
                        position=types["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2] + (0.06 if j else 0.0)),
                        orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                    ),
                    scale=types["geometry_msgs/msg/Vector3"](x=0.05, y=0.05, z=0.05),
                    color=types["std_msgs/msg/ColorRGBA"](r=0.9, g=0.5, b=0.1, a=1.0),
                    lifetime=types["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
                    frame_locked=False,
                    points=[],
                    colors=[],
                    texture_resource="",
                    texture=types["sensor_msgs/msg/CompressedImage"](header=types["std_msgs/msg/Header"](stamp=_stamp(types, time_s), frame_id=frame_id), format="", data=empty),
                    uv_coordinates=[],
                    text=text,
                    mesh_resource="",
                    mesh_file=types["visualization_msgs/msg/MeshFile"](filename="", data=empty),
                    mesh_use_embedded_materials=False,
                )
            )
    return types[MARKERS](markers=markers)


def write_mcap(path, track, scene=None, frame_id: str = "scattertrack", transform: Transform = IDENTITY) -> dict:
    """Write the track as MCAP (ros2msg + CDR); returns messages per topic."""
    from mcap.writer import Writer

    ts = _typestore()
    counts: dict[str, int] = {}
    schemas: dict[str, int] = {}
    channels: dict[str, int] = {}
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="scattertrack")
        for name, msgtype, stamp, message in messages(track, scene, frame_id, transform):
            if msgtype not in schemas:
                text, _ = ts.generate_msgdef(msgtype, ros_version=2)
                schemas[msgtype] = writer.register_schema(name=msgtype, encoding="ros2msg", data=text.encode())
            if name not in channels:
                channels[name] = writer.register_channel(topic=name, message_encoding="cdr", schema_id=schemas[msgtype])
            data = ts.serialize_cdr(message, msgtype)
            writer.add_message(channel_id=channels[name], log_time=stamp, data=bytes(data), publish_time=stamp, sequence=counts.get(name, 0))
            counts[name] = counts.get(name, 0) + 1
        writer.finish()
    return counts


def write_ros2_bag(directory, track, scene=None, frame_id: str = "scattertrack", transform: Transform = IDENTITY) -> dict:
    """Write the track as a ROS 2 bag (rosbag2, sqlite3 storage); returns messages per topic.
    ``directory`` must not exist yet (rosbag2's rule)."""
    from rosbags.rosbag2 import Writer

    ts = _typestore()
    counts: dict[str, int] = {}
    connections = {}
    with Writer(directory, version=8) as writer:
        for name, msgtype, stamp, message in messages(track, scene, frame_id, transform):
            if name not in connections:
                connections[name] = writer.add_connection(name, msgtype, typestore=ts)
            writer.write(connections[name], stamp, ts.serialize_cdr(message, msgtype))
            counts[name] = counts.get(name, 0) + 1
    return counts
