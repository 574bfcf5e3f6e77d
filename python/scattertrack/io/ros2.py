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

:class:`Builder` turns one row into its messages, for a whole track
(:func:`messages`) and for a live estimate
(:mod:`scattertrack.readers.outputs`) alike; :class:`McapFile` and
:class:`BagFile` take them one at a time, so a live run writes as it goes.
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


def _blocks(covariance, sigma) -> tuple[np.ndarray, np.ndarray]:
    """(position 3×3, velocity 3×3) in the scene frame, from a full 6×6
    covariance of [p, v] when there is one, else from the sigmas."""
    if covariance is not None:
        full = np.asarray(covariance, dtype=float).reshape(6, 6)
        position, velocity = full[:3, :3], full[3:, 3:]
    else:
        sigma = np.asarray(sigma, dtype=float) if sigma is not None else np.full(3, np.nan)
        position, velocity = np.diag(sigma**2), np.full((3, 3), np.nan)
    velocity = np.where(np.isfinite(velocity), velocity, 0.0) if np.isfinite(velocity).any() else np.diag([UNKNOWN_ROTATION_VARIANCE] * 3)
    return position, velocity


def _six(block: np.ndarray, rotation_variance: float) -> np.ndarray:
    six = np.zeros((6, 6))
    six[:3, :3] = block
    six[3, 3] = six[4, 4] = six[5, 5] = rotation_variance  # (not np.eye: this runs per live estimate)
    return six.reshape(36)


class Builder:
    """Builds the messages of one track row: the single place a row becomes
    ROS 2, for a whole track (:func:`messages`) and for a live estimate
    alike, so that files and live outputs cannot drift apart."""

    def __init__(self, frame_id: str = "scattertrack", transform: Transform = IDENTITY) -> None:
        self.store = _typestore()
        self.types = self.store.types
        self.frame_id = frame_id
        self.transform = transform
        self._rotation = transform.matrix()

    def antennas(self, scene, time_s: float):
        """``(topic, msgtype, stamp_ns, message)`` of the antennas' markers."""
        return ANTENNA_TOPIC, MARKERS, _nanoseconds(time_s), _antenna_markers(self.types, scene, time_s, self.frame_id, self.transform)

    def row(self, time_s: float, epc: str, position, velocity, covariance=None, sigma=None, orientation=None) -> list:
        """The pose and odometry ``(topic, msgtype, stamp_ns, message)`` of one
        row: ``covariance`` the 6×6 of [p, v] (or None: ``sigma``, 3 m),
        ``orientation`` (w, x, y, z) or None, all in the scene frame."""
        types, rotation, transform = self.types, self._rotation, self.transform
        position = rotation @ np.asarray(position, dtype=float) + transform.translation
        velocity = np.asarray(velocity, dtype=float)
        velocity = rotation @ np.where(np.isnan(velocity), 0.0, velocity)
        position_cov, velocity_cov = (rotation @ block @ rotation.T for block in _blocks(covariance, sigma))
        if orientation is not None and np.all(np.isfinite(orientation)):
            q, rotation_variance = _rotate_quaternion(transform.rotation, np.asarray(orientation, dtype=float)), NOMINAL_ROTATION_VARIANCE
        else:
            q, rotation_variance = np.array([1.0, 0.0, 0.0, 0.0]), UNKNOWN_ROTATION_VARIANCE
        header = types["std_msgs/msg/Header"](stamp=_stamp(types, time_s), frame_id=self.frame_id)
        pose = types["geometry_msgs/msg/PoseWithCovariance"](
            pose=types["geometry_msgs/msg/Pose"](
                position=types["geometry_msgs/msg/Point"](x=position[0], y=position[1], z=position[2]),
                orientation=types["geometry_msgs/msg/Quaternion"](x=q[1], y=q[2], z=q[3], w=q[0]),
            ),
            covariance=_six(position_cov, rotation_variance),
        )
        Vector3 = types["geometry_msgs/msg/Vector3"]
        twist = types["geometry_msgs/msg/TwistWithCovariance"](
            twist=types["geometry_msgs/msg/Twist"](linear=Vector3(x=velocity[0], y=velocity[1], z=velocity[2]), angular=Vector3(x=0.0, y=0.0, z=0.0)),
            covariance=_six(velocity_cov, UNKNOWN_ROTATION_VARIANCE),
        )
        stamp = _nanoseconds(time_s)
        return [
            (topic(epc, "pose"), POSE, stamp, types[POSE](header=header, pose=pose)),
            (topic(epc, "odom"), ODOMETRY, stamp, types[ODOMETRY](header=header, child_frame_id=f"tag_{epc}", pose=pose, twist=twist)),
        ]

    def schema(self, msgtype: str) -> str:
        """The ``ros2msg`` definition of ``msgtype`` (with its dependencies)."""
        text, _ = self.store.generate_msgdef(msgtype, ros_version=2)
        return text

    def cdr(self, message, msgtype: str) -> bytes:
        return bytes(self.store.serialize_cdr(message, msgtype))


def _nanoseconds(time_s: float) -> int:
    return int(round(float(time_s) * 1e9))


def messages(track, scene=None, frame_id: str = "scattertrack", transform: Transform = IDENTITY):
    """Yield ``(topic, msgtype, stamp_ns, message)`` in time order: the
    antennas first (if ``scene``), then per track row its pose and odometry."""
    builder = Builder(frame_id, transform)
    order = np.argsort(np.asarray(track.time_s), kind="stable")
    if scene is not None and len(order):
        yield builder.antennas(scene, float(track.time_s[order[0]]))
    covariance = getattr(track, "covariance", None)
    orientation = getattr(track, "orientation", None)
    for i in order:
        yield from builder.row(
            float(track.time_s[i]),
            str(track.epc[i]),
            track.position[i],
            track.velocity[i],
            covariance=None if covariance is None else covariance[i],
            sigma=None if track.sigma is None else track.sigma[i],
            orientation=None if orientation is None else orientation[i],
        )


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


class McapFile:
    """An MCAP file written message by message (ros2msg schemas, CDR), so a
    live run can write it as it goes; :meth:`close` writes the index."""

    def __init__(self, path, builder: Builder) -> None:
        from mcap.writer import Writer

        self.builder = builder
        self.counts: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._stream = open(path, "wb")
        self._writer = Writer(self._stream)
        self._writer.start(profile="ros2", library="scattertrack")

    def write(self, name: str, msgtype: str, stamp: int, data: bytes) -> None:
        """One message, already CDR (:meth:`Builder.cdr`: serialized once for every output)."""
        if msgtype not in self._schemas:
            self._schemas[msgtype] = self._writer.register_schema(name=msgtype, encoding="ros2msg", data=self.builder.schema(msgtype).encode())
        if name not in self._channels:
            self._channels[name] = self._writer.register_channel(topic=name, message_encoding="cdr", schema_id=self._schemas[msgtype])
        sequence = self.counts.get(name, 0)
        self._writer.add_message(channel_id=self._channels[name], log_time=stamp, data=data, publish_time=stamp, sequence=sequence)
        self.counts[name] = sequence + 1

    def close(self) -> None:
        if not self._stream.closed:
            self._writer.finish()
            self._stream.close()


class BagFile:
    """A ROS 2 bag (rosbag2, sqlite3 storage) written message by message.
    ``directory`` must not exist yet (rosbag2's rule)."""

    def __init__(self, directory, builder: Builder) -> None:
        from rosbags.rosbag2 import Writer

        self.builder = builder
        self.counts: dict[str, int] = {}
        self._connections: dict = {}
        self._writer = Writer(directory, version=8)
        self._writer.open()
        self._open = True

    def write(self, name: str, msgtype: str, stamp: int, data: bytes) -> None:
        """One message, already CDR."""
        if name not in self._connections:
            self._connections[name] = self._writer.add_connection(name, msgtype, typestore=self.builder.store)
        self._writer.write(self._connections[name], stamp, data)
        self.counts[name] = self.counts.get(name, 0) + 1

    def close(self) -> None:
        if self._open:
            self._writer.close()
            self._open = False


def _write(sink, track, scene, frame_id, transform) -> dict:
    try:
        for name, msgtype, stamp, message in messages(track, scene, frame_id, transform):
            sink.write(name, msgtype, stamp, sink.builder.cdr(message, msgtype))
    finally:
        sink.close()
    return sink.counts


def write_mcap(path, track, scene=None, frame_id: str = "scattertrack", transform: Transform = IDENTITY) -> dict:
    """Write the track as MCAP (ros2msg + CDR); returns messages per topic."""
    return _write(McapFile(path, Builder(frame_id, transform)), track, scene, frame_id, transform)


def write_ros2_bag(directory, track, scene=None, frame_id: str = "scattertrack", transform: Transform = IDENTITY) -> dict:
    """Write the track as a ROS 2 bag (rosbag2, sqlite3 storage); returns messages per topic.
    ``directory`` must not exist yet (rosbag2's rule)."""
    return _write(BagFile(directory, Builder(frame_id, transform)), track, scene, frame_id, transform)
